"""
Per-wheel velocity PID controller and stall detector (pure Python, no ROS).

Units: wheel speeds in rad/s (positive rolls the robot forward), time in s, effort
is a signed PWM duty in [-1, 1]. One ``PidController`` and one ``StallDetector`` per
wheel (FL, FR, RL, RR), updated at the control rate with the measured time step.

Output of ``PidController.update``::

    effort = kf * target + sign(target) * static_effort     (feedforward)
           + kp * (target - measured)                       (proportional)
           + integral                                        (integral, clamped)
           - kd * d(measured)/dt                             (derivative on measurement)

clipped to +-max_effort. A zero target is a commanded stop: the output is exactly 0.0
and the integrator is reset, so motors do not hum at rest.
"""

from dataclasses import dataclass
import math
from typing import Optional


def _check_finite_non_negative(owner: str, name: str, value: float) -> None:
    """Raise ValueError naming the field unless value is finite and >= 0."""
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
        raise ValueError(f'{owner}.{name} must be a finite number >= 0, got {value!r}')


@dataclass(frozen=True)
class PidGains:
    """
    Gains of one wheel's velocity PID; efforts are PWM duty fractions.

    kp: effort per rad/s of error. ki: effort per (rad/s * s) of integrated error.
    kd: effort per rad/s^2, applied to the measurement only (no derivative kick).
    kf: feedforward, effort per rad/s of target (1 / no-load speed at full duty).
    static_effort: sign(target) * static_effort added for a nonzero target (Coulomb
    friction). max_effort: output limit, 0 < max_effort <= 1.
    derivative_filter_tau_s: time constant (s) of a first-order low-pass on the
    derivative term, 0 for none.
    """

    kp: float
    ki: float
    kd: float
    kf: float = 0.0
    static_effort: float = 0.0
    max_effort: float = 1.0
    derivative_filter_tau_s: float = 0.0

    def __post_init__(self) -> None:
        """Validate: all finite, gains >= 0, 0 < max_effort <= 1, tau >= 0."""
        for name in ('kp', 'ki', 'kd', 'kf', 'static_effort', 'derivative_filter_tau_s'):
            _check_finite_non_negative('PidGains', name, getattr(self, name))
        max_effort = self.max_effort
        if not (isinstance(max_effort, (int, float)) and math.isfinite(max_effort)
                and 0.0 < max_effort <= 1.0):
            raise ValueError(
                f'PidGains.max_effort must be in (0, 1] (PWM duty), got {max_effort!r}')


def _clamp(value: float, limit: float) -> float:
    """Clip value to [-limit, limit]."""
    return max(-limit, min(limit, value))


def _valid_dt(dt_s: float) -> bool:
    """Return True if dt_s is a usable time step (finite and > 0)."""
    return isinstance(dt_s, (int, float)) and math.isfinite(dt_s) and dt_s > 0.0


class PidController:
    """
    Velocity PID of one wheel: target and measured in rad/s, output effort (duty).

    Anti-windup is conditional integration (clamping): the integrator is not advanced
    on a step where the output would be saturated in the direction of the error, and
    the integral contribution itself is kept within +-max_effort.
    """

    def __init__(self, gains: PidGains) -> None:
        """Create a controller at rest with the given gains."""
        self._gains = gains
        self._integral = 0.0
        self._derivative = 0.0
        self._prev_measured: Optional[float] = None

    @property
    def gains(self) -> PidGains:
        """Return the gains in use."""
        return self._gains

    @property
    def integral_effort(self) -> float:
        """Return the current integral contribution to the effort (duty)."""
        return self._integral

    @property
    def derivative_effort(self) -> float:
        """Return the last (filtered) derivative contribution to the effort (duty)."""
        return self._derivative

    def reset(self) -> None:
        """Clear the integrator and the derivative history."""
        self._integral = 0.0
        self._derivative = 0.0
        self._prev_measured = None

    def update(self, target: float, measured: float, dt_s: float) -> float:
        """
        Advance one control step and return the effort in [-max_effort, max_effort].

        target and measured are wheel speeds in rad/s, dt_s the real time (s) since
        the previous update. A non-finite target or measured raises ValueError. If
        dt_s is <= 0 or not finite, nothing is integrated or differentiated on this
        step: the output is feedforward + P + the held integral term (no D term). target == 0.0
        resets the controller and returns exactly 0.0 (a commanded stop; the board
        brakes).
        """
        if not (math.isfinite(target) and math.isfinite(measured)):
            raise ValueError(
                f'PID target and measured must be finite, got target={target!r}, '
                f'measured={measured!r}')
        if target == 0.0:
            self.reset()
            return 0.0
        g = self._gains
        error = target - measured
        base = (g.kf * target + math.copysign(g.static_effort, target) + g.kp * error)

        if _valid_dt(dt_s):
            if self._prev_measured is not None:
                raw = -g.kd * (measured - self._prev_measured) / dt_s
                alpha = dt_s / (g.derivative_filter_tau_s + dt_s)
                self._derivative += alpha * (raw - self._derivative)
            candidate = _clamp(self._integral + g.ki * error * dt_s, g.max_effort)
            unclipped = base + candidate + self._derivative
            # Clamping: refuse to integrate further into a saturation the error drives.
            if not (abs(unclipped) > g.max_effort and error * unclipped > 0.0):
                self._integral = candidate
            derivative = self._derivative
        else:
            derivative = 0.0  # no rate estimate without a time step
        # The next dt is measured from this call, so this is the previous measurement.
        self._prev_measured = measured
        return _clamp(base + self._integral + derivative, g.max_effort)


@dataclass(frozen=True)
class StallConfig:
    """
    When a wheel counts as stalled.

    |effort| >= effort_threshold (duty) while |measured| < velocity_threshold_rad_s,
    continuously for time_s seconds.
    """

    effort_threshold: float = 0.6
    velocity_threshold_rad_s: float = 0.5
    time_s: float = 0.5

    def __post_init__(self) -> None:
        """Validate: thresholds finite and > 0, time_s finite and > 0."""
        for name in ('effort_threshold', 'velocity_threshold_rad_s', 'time_s'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ValueError(f'StallConfig.{name} must be a finite number > 0, got {value!r}')


class StallDetector:
    """
    Latching stall detector of one wheel.

    The stall condition must hold continuously for config.time_s (summing the real
    dt of each step; any step without it restarts the count). Once stalled, the
    latch holds whatever the wheel does until the target becomes exactly 0.0 (an
    operator stop); then the wheel may be retried and the count starts afresh.
    """

    # Tolerance on the accumulated time, so 25 steps of 0.02 s count as 0.5 s.
    _TIME_EPS_S = 1e-9

    def __init__(self, config: StallConfig) -> None:
        """Create a detector, not stalled."""
        self._config = config
        self._condition_s = 0.0
        self._stalled = False

    @property
    def config(self) -> StallConfig:
        """Return the configuration in use."""
        return self._config

    @property
    def stalled(self) -> bool:
        """Return True while the stall latch is set."""
        return self._stalled

    @property
    def condition_time_s(self) -> float:
        """Return how long (s) the stall condition has held, frozen once latched."""
        return self._condition_s

    def reset(self) -> None:
        """Clear the latch and the timer."""
        self._condition_s = 0.0
        self._stalled = False

    def update(self, effort: float, measured: float, target: float, dt_s: float) -> bool:
        """
        Advance one step and return True while latched stalled.

        effort is the commanded duty, measured and target wheel speeds in rad/s,
        dt_s the real step (s); a step with dt_s <= 0 or non-finite adds no time.
        Non-finite effort, measured or target raise ValueError.
        """
        if not (math.isfinite(effort) and math.isfinite(measured) and math.isfinite(target)):
            raise ValueError(
                f'stall detector inputs must be finite, got effort={effort!r}, '
                f'measured={measured!r}, target={target!r}')
        if target == 0.0:
            self.reset()
            return False
        if self._stalled:
            return True
        cfg = self._config
        if abs(effort) >= cfg.effort_threshold and abs(measured) < cfg.velocity_threshold_rad_s:
            if _valid_dt(dt_s):
                self._condition_s += dt_s
            if self._condition_s >= cfg.time_s - self._TIME_EPS_S:
                self._stalled = True
        else:
            self._condition_s = 0.0
        return self._stalled
