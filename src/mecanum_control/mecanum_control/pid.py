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

The controller never holds a non-finite state and never outputs NaN: a measurement jump
too large for a finite rate is not differentiated, an integrator step that would not be
finite is skipped, and an output that is NaN anyway (e.g. inf - inf from absurd inputs)
becomes 0.0, never full duty.
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
    integral_freeze_rate_rad_s2: while the target changes faster than this (a ramp),
    the integrator holds: the error then is mostly the measurement's delay, and
    integrating it would overshoot once the ramp ends (inf: always integrate).
    """

    kp: float
    ki: float
    kd: float
    kf: float = 0.0
    static_effort: float = 0.0
    max_effort: float = 1.0
    derivative_filter_tau_s: float = 0.0
    integral_freeze_rate_rad_s2: float = math.inf

    def __post_init__(self) -> None:
        """Validate: all finite, gains >= 0, 0 < max_effort <= 1, tau >= 0."""
        rate = self.integral_freeze_rate_rad_s2
        if not (isinstance(rate, (int, float)) and not math.isnan(rate) and rate > 0.0):
            raise ValueError(
                f'PidGains.integral_freeze_rate_rad_s2 must be > 0 (inf: never), got {rate!r}')
        for name in ('kp', 'ki', 'kd', 'kf', 'static_effort', 'derivative_filter_tau_s'):
            _check_finite_non_negative('PidGains', name, getattr(self, name))
        max_effort = self.max_effort
        if not (isinstance(max_effort, (int, float)) and math.isfinite(max_effort)
                and 0.0 < max_effort <= 1.0):
            raise ValueError(
                f'PidGains.max_effort must be in (0, 1] (PWM duty), got {max_effort!r}')


def _clamp(value: float, limit: float) -> float:
    """
    Clip value to [-limit, limit]; NaN gives 0.0.

    A NaN effort means the computation went wrong: it must stop the motor, not become
    full duty (max/min with a NaN return whichever operand comes first).
    """
    if math.isnan(value):
        return 0.0
    return max(-limit, min(limit, value))


def _scaled(gain: float, value: float) -> float:
    """Return gain * value, with a zero gain giving 0.0 even for an infinite value."""
    return 0.0 if gain == 0.0 else gain * value


def _valid_dt(dt_s: float) -> bool:
    """Return True if dt_s is a usable time step (finite and > 0)."""
    return isinstance(dt_s, (int, float)) and math.isfinite(dt_s) and dt_s > 0.0


class PidController:
    """
    Velocity PID of one wheel: target and measured in rad/s, output effort (duty).

    Anti-windup is conditional integration (clamping): the integrator is not advanced
    on a step where the output would be saturated in the direction of the error, and
    the integral contribution itself is kept within +-max_effort.

    The derivative contribution is capped at +-2 x max_effort (the whole output span)
    before filtering: with feedforward + P + I inside the output range a larger D term
    could not change the clipped output, but a measurement glitch would otherwise leave
    a huge filter state that holds the output saturated for many steps.
    """

    def __init__(self, gains: PidGains) -> None:
        """Create a controller at rest with the given gains."""
        self._gains = gains
        self._integral = 0.0
        self._derivative = 0.0
        self._prev_measured: Optional[float] = None
        self._prev_target = 0.0  # at rest: the first target is a step from 0

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
        self._prev_target = 0.0

    def update(self, target: float, measured: float, dt_s: float) -> float:
        """
        Advance one control step and return the effort in [-max_effort, max_effort].

        target and measured are wheel speeds in rad/s, dt_s the real time (s) since
        the previous update. A non-finite target or measured raises ValueError. If
        dt_s is <= 0 or not finite, nothing is integrated or differentiated on this
        step: the output is feedforward + P + the held integral term (no D term). target == 0.0
        resets the controller and returns exactly 0.0 (a commanded stop; the board
        brakes). Finite but absurd inputs (e.g. a measurement jump of 1e308 rad/s) never
        make the state non-finite; a step whose output would be NaN returns 0.0.
        """
        if not (math.isfinite(target) and math.isfinite(measured)):
            raise ValueError(
                f'PID target and measured must be finite, got target={target!r}, '
                f'measured={measured!r}')
        if target == 0.0:
            self.reset()
            return 0.0
        g = self._gains
        error = target - measured  # may overflow to +-inf for absurd finite inputs
        base = (_scaled(g.kf, target) + math.copysign(g.static_effort, target)
                + _scaled(g.kp, error))

        if _valid_dt(dt_s):
            if self._prev_measured is not None:
                rate = (measured - self._prev_measured) / dt_s
                if math.isfinite(rate):   # else: no usable rate, hold the D state
                    raw = _clamp(-_scaled(g.kd, rate), 2.0 * g.max_effort)
                    alpha = dt_s / (g.derivative_filter_tau_s + dt_s)
                    self._derivative += alpha * (raw - self._derivative)
            increment = _scaled(g.ki, error) * dt_s
            ramping = abs(target - self._prev_target) > g.integral_freeze_rate_rad_s2 * dt_s
            if math.isfinite(increment) and not ramping:
                candidate = _clamp(self._integral + increment, g.max_effort)
                unclipped = base + candidate + self._derivative
                # Clamping: refuse to integrate further into a saturation the error drives.
                if not (abs(unclipped) > g.max_effort and error * unclipped > 0.0):
                    self._integral = candidate
            derivative = self._derivative
        else:
            derivative = 0.0  # no rate estimate without a time step
        # The next dt is measured from this call, so this is the previous measurement.
        self._prev_measured = measured
        self._prev_target = target
        return _clamp(base + self._integral + derivative, g.max_effort)


@dataclass(frozen=True)
class StallConfig:
    """
    When a wheel counts as not following its effort (stalled or running against it).

    |effort| >= effort_threshold (duty) while the wheel does not turn in the effort's
    direction at velocity_threshold_rad_s or more, continuously for time_s seconds:
    either |measured| < velocity_threshold_rad_s (stalled, encoder disconnected) or
    the measured speed is opposite to the effort with |measured| >=
    velocity_threshold_rad_s (wrong direction: encoder or motor wired reversed). Also
    stalled: |target| >= target_threshold_rad_s while |measured| <
    velocity_threshold_rad_s, whatever the effort (a dead encoder on a wheel driven
    gently, where the effort stays below its threshold; the motor's lag is tens of ms).
    """

    effort_threshold: float = 0.6
    velocity_threshold_rad_s: float = 0.5
    time_s: float = 0.5
    target_threshold_rad_s: float = 3.0

    def __post_init__(self) -> None:
        """Validate: thresholds finite and > 0, time_s finite and > 0."""
        for name in ('effort_threshold', 'velocity_threshold_rad_s', 'time_s',
                     'target_threshold_rad_s'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ValueError(f'StallConfig.{name} must be a finite number > 0, got {value!r}')


FAULT_STALLED = 'stalled'
FAULT_WRONG_DIRECTION = 'wrong direction'


class StallDetector:
    """
    Latching detector of a wheel that does not follow its effort.

    The fault condition (see :class:`StallConfig`) must hold continuously for
    config.time_s (summing the real dt of each step; any step without it restarts the
    count). It covers two faults, timed together because a reversed encoder passes
    through the first on its way into the second:

    * ``'stalled'``: high effort, wheel (nearly) still: a blocked wheel or a
      disconnected encoder.
    * ``'wrong direction'``: high effort, wheel turning against it: an encoder (or
      motor) wired reversed. The loop then has positive feedback and would run the
      wheel at full speed forever; nothing else stops it.

    The reported :attr:`fault` is the one that held for most of the counted time.
    Normal braking (a target reversal, deceleration) also drives against the motion
    at high effort, but only for the tens of ms the wheel takes to reach zero, and a
    brief external push is equally shorter than time_s. A target of exactly 0.0 restarts
    the count. Once latched, the latch holds whatever the wheel does and whatever the
    target, until :meth:`reset` (an operator's clear, once the wheel is seen to): a
    retry on the next command would drive a robot with a dead encoder again, at full
    effort, for time_s more each time (the fault sweep saw 0.56 m/s lurches).
    """

    # Tolerance on the accumulated time, so 25 steps of 0.02 s count as 0.5 s.
    _TIME_EPS_S = 1e-9

    def __init__(self, config: StallConfig) -> None:
        """Create a detector, not stalled."""
        self._config = config
        self._condition_s = 0.0
        self._wrong_direction_s = 0.0
        self._fault: Optional[str] = None

    @property
    def config(self) -> StallConfig:
        """Return the configuration in use."""
        return self._config

    @property
    def stalled(self) -> bool:
        """Return True while the latch is set (for either fault: the wheel is stopped)."""
        return self._fault is not None

    @property
    def fault(self) -> Optional[str]:
        """Return None, or while latched FAULT_STALLED or FAULT_WRONG_DIRECTION."""
        return self._fault

    @property
    def condition_time_s(self) -> float:
        """Return how long (s) the fault condition has held, frozen once latched."""
        return self._condition_s

    def reset(self) -> None:
        """Clear the latch and the timer."""
        self._condition_s = 0.0
        self._wrong_direction_s = 0.0
        self._fault = None

    def update(self, effort: float, measured: float, target: float, dt_s: float) -> bool:
        """
        Advance one step and return True while latched (stalled or wrong direction).

        effort is the commanded duty, measured and target wheel speeds in rad/s,
        dt_s the real step (s); a step with dt_s <= 0 or non-finite adds no time.
        Non-finite effort, measured or target raise ValueError.
        """
        if not (math.isfinite(effort) and math.isfinite(measured) and math.isfinite(target)):
            raise ValueError(
                f'stall detector inputs must be finite, got effort={effort!r}, '
                f'measured={measured!r}, target={target!r}')
        if self._fault is not None:
            return True
        if target == 0.0:
            self.reset()
            return False
        cfg = self._config
        # Speed in the direction the effort pushes (effort != 0 past the threshold).
        following = math.copysign(1.0, effort) * measured
        pushed = abs(effort) >= cfg.effort_threshold and following < cfg.velocity_threshold_rad_s
        asked = (abs(target) >= cfg.target_threshold_rad_s
                 and abs(measured) < cfg.velocity_threshold_rad_s)
        if pushed or asked:
            if _valid_dt(dt_s):
                self._condition_s += dt_s
                if following <= -cfg.velocity_threshold_rad_s:
                    self._wrong_direction_s += dt_s
            if self._condition_s >= cfg.time_s - self._TIME_EPS_S:
                wrong = self._wrong_direction_s > 0.5 * self._condition_s
                self._fault = FAULT_WRONG_DIRECTION if wrong else FAULT_STALLED
        else:
            self._condition_s = 0.0
            self._wrong_direction_s = 0.0
        return self._fault is not None
