"""
Velocity smoother (pure core, no ROS): Nav2 velocity_smoother's job for a mecanum base.

Commands (body twists in base_link, REP-103: vx m/s, vy m/s, wz rad/s) arrive with
on_command(); update() runs at smoothing_frequency and returns the twist to publish.
Semantics are Nav2's (nav2_velocity_smoother), per axis in the order (vx, vy, wz):

- The target is clamped to [min_velocity, max_velocity].
- Each step (dt = 1 / smoothing_frequency, fixed, as Nav2) an axis changes by at most
  max_accel * dt while accelerating (|target| >= |current| and no sign change) and
  by at most -max_decel * dt otherwise (max_decel is NEGATIVE, as in Nav2).
- scale_velocities: when an axis is limited, the whole change (target - current) is
  scaled by the most limiting axis' factor, so the axes stay in proportion and the
  direction of motion is kept (a diagonal strafe stays diagonal); each axis is then
  clamped to its own bound all the same.
- feedback 'OPEN_LOOP' ramps from the last output; 'CLOSED_LOOP' from the measured
  twist passed to update() (odometry).
- deadband_velocity: an output component smaller in magnitude is published as 0 (the
  internal state keeps the true value, as Nav2).
- velocity_timeout: no command for longer than this -> the target becomes zero and the
  output ramps down; once it is zero, publish is False (Nav2 stops publishing, so other
  sources of cmd_vel are not overridden) until a new command arrives.
- Non-finite commands (NaN / inf) are rejected: the target becomes zero and
  on_command() returns the reason (for a throttled warning).
"""

from dataclasses import dataclass
import math
from typing import Optional, Sequence, Tuple

Twist2D = Tuple[float, float, float]

ZERO: Twist2D = (0.0, 0.0, 0.0)
FEEDBACK_MODES = ('OPEN_LOOP', 'CLOSED_LOOP')
AXIS_NAMES = ('linear.x', 'linear.y', 'angular.z')

STATUS_WAITING = 'waiting'
STATUS_OK = 'ok'
STATUS_TIMEOUT = 'timeout'
STATUS_STOPPED = 'stopped'


def _triple(name: str, values, sign: int) -> Twist2D:
    """Return 3 finite floats, each >= 0 (sign 1), <= 0 (sign -1) or > 0 / < 0 (sign 2 / -2)."""
    try:
        items = [float(v) for v in values]
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be 3 numbers [vx, vy, wz], got {values!r}') from None
    if len(items) != 3 or any(isinstance(v, bool) for v in values):
        raise ValueError(f'{name} must be 3 numbers [vx, vy, wz], got {values!r}')
    for axis, value in zip(AXIS_NAMES, items):
        bad = (not math.isfinite(value) or (sign == 1 and value < 0.0)
               or (sign == -1 and value > 0.0) or (sign == 2 and value <= 0.0)
               or (sign == -2 and value >= 0.0))
        if bad:
            wanted = {1: '>= 0', -1: '<= 0', 2: '> 0', -2: '< 0'}[sign]
            raise ValueError(f'{name} {axis} must be finite and {wanted}, got {value!r}')
    return items[0], items[1], items[2]


@dataclass(frozen=True)
class SmootherParams:
    """
    Parameters with Nav2's names; arrays are [vx, vy, wz] (m/s or rad/s, per s for accel).

    min_velocity defaults to -max_velocity; max_decel must be negative (Nav2's sign).
    scale_velocities defaults to True here (Nav2: False): a mecanum base should keep
    the direction of its motion while ramping.
    """

    smoothing_frequency: float = 20.0
    scale_velocities: bool = True
    feedback: str = 'OPEN_LOOP'
    max_velocity: Tuple[float, float, float] = (0.8, 0.6, 2.5)
    min_velocity: Optional[Tuple[float, float, float]] = None
    max_accel: Tuple[float, float, float] = (1.5, 1.5, 5.0)
    max_decel: Tuple[float, float, float] = (-1.5, -1.5, -5.0)
    deadband_velocity: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity_timeout: float = 1.0

    def __post_init__(self) -> None:
        """Validate every field (ValueError naming it) and fill min_velocity."""
        for name in ('smoothing_frequency', 'velocity_timeout'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value) or value <= 0.0:
                raise ValueError(f'{name} must be a finite number > 0, got {value!r}')
        for name in ('scale_velocities',):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f'{name} must be a bool, got {getattr(self, name)!r}')
        if self.feedback not in FEEDBACK_MODES:
            raise ValueError(f'feedback must be one of {FEEDBACK_MODES}, got {self.feedback!r}')
        set_ = object.__setattr__
        set_(self, 'max_velocity', _triple('max_velocity', self.max_velocity, 1))
        if self.min_velocity is None:
            set_(self, 'min_velocity', tuple(-v for v in self.max_velocity))
        set_(self, 'min_velocity', _triple('min_velocity', self.min_velocity, -1))
        set_(self, 'max_accel', _triple('max_accel', self.max_accel, 2))
        set_(self, 'max_decel', _triple('max_decel', self.max_decel, -2))
        set_(self, 'deadband_velocity', _triple('deadband_velocity', self.deadband_velocity, 1))

    @classmethod
    def from_robot_config(cls, config, **overrides) -> 'SmootherParams':
        """Return parameters with a mecanum_control RobotConfig's limits, then overrides."""
        accel = (config.max_acceleration_x_m_s2, config.max_acceleration_y_m_s2,
                 config.max_angular_acceleration_rad_s2)
        values = {'max_velocity': (config.max_velocity_x_m_s, config.max_velocity_y_m_s,
                                   config.max_angular_velocity_rad_s),
                  'max_accel': accel, 'max_decel': tuple(-a for a in accel)}
        values.update(overrides)
        return cls(**values)


@dataclass(frozen=True)
class SmootherOutput:
    """
    Result of one update: the twist to publish and whether to publish it.

    status: 'waiting' (no command yet: nothing to publish), 'ok', 'timeout' (ramping
    down after velocity_timeout), 'stopped' (timed out and at zero: nothing to publish).
    warning: '' or why the measured twist was not used (CLOSED_LOOP).
    """

    twist: Twist2D
    status: str
    publish: bool
    warning: str = ''


def _axis_bounds(current: float, target: float, accel: float, decel: float,
                 dt: float) -> Tuple[float, float]:
    """Return the (low, high) change allowed on one axis in one step (Nav2's rule)."""
    if abs(target) >= abs(current) and current * target >= 0.0:
        step = accel * dt          # speeding up, same direction
    else:
        step = -decel * dt         # slowing down or reversing (decel < 0)
    return -step, step


class VelocitySmoother:
    """Nav2's velocity smoother as a plain class (see the module docstring)."""

    def __init__(self, params: Optional[SmootherParams] = None):
        """Create a smoother at rest, waiting for a first command."""
        params = SmootherParams() if params is None else params
        if not isinstance(params, SmootherParams):
            raise ValueError(f'params must be SmootherParams, not {type(params).__name__}')
        self.params = params
        self._target: Twist2D = ZERO
        self._last_command_s: Optional[float] = None
        self._last_output: Twist2D = ZERO
        self._stopped = False

    @property
    def last_output(self) -> Twist2D:
        """Return the last output before the deadband (the OPEN_LOOP state)."""
        return self._last_output

    def reset(self) -> None:
        """Forget commands and state: waiting, at rest."""
        self.__init__(self.params)

    def on_command(self, twist: Sequence[float], now_s: float) -> Optional[str]:
        """
        Take a cmd_vel (vx, vy, wz) received at now_s; return None, or why it was rejected.

        A rejected (non-finite) command counts as a zero command received now.
        """
        if not math.isfinite(now_s):
            raise ValueError(f'now_s must be finite, got {now_s!r}')
        reason = None
        try:
            values = tuple(float(v) for v in twist)
        except (TypeError, ValueError):
            values = ()
        if len(values) != 3:
            reason = f'cmd_vel must be 3 numbers (vx, vy, wz), got {twist!r}'
        else:
            bad = [f'{axis} is {value}' for axis, value in zip(AXIS_NAMES, values)
                   if not math.isfinite(value)]
            if bad:
                reason = 'cmd_vel rejected, treated as zero: ' + ', '.join(bad)
        self._target = ZERO if reason else (values[0], values[1], values[2])
        self._last_command_s = float(now_s)
        self._stopped = False
        return reason

    def update(self, now_s: float, measured: Optional[Sequence[float]] = None) -> SmootherOutput:
        """Run one smoothing step at now_s (measured twist needed for CLOSED_LOOP)."""
        p = self.params
        if not math.isfinite(now_s):
            raise ValueError(f'now_s must be finite, got {now_s!r}')
        if self._last_command_s is None:
            return SmootherOutput(ZERO, STATUS_WAITING, False)
        status = STATUS_OK
        if now_s - self._last_command_s > p.velocity_timeout:
            if self._stopped or self._last_output == ZERO:
                self._stopped = True
                return SmootherOutput(ZERO, STATUS_STOPPED, False)
            self._target = ZERO
            status = STATUS_TIMEOUT
        current, warning = self._last_output, ''
        if p.feedback == 'CLOSED_LOOP':
            try:
                values = tuple(float(v) for v in measured)
            except (TypeError, ValueError):
                values = ()
            if len(values) == 3 and all(math.isfinite(v) for v in values):
                current = values
            else:
                warning = (f'CLOSED_LOOP needs a finite measured twist, got {measured!r}; '
                           'used the last output')
        output = self._step(current, self._target)
        self._last_output = output
        published = tuple(0.0 if abs(v) < band else v
                          for v, band in zip(output, p.deadband_velocity))
        return SmootherOutput((published[0], published[1], published[2]), status, True,
                              warning)

    def _step(self, current: Twist2D, target: Twist2D) -> Twist2D:
        """Return one step from current toward target within the velocity and accel limits."""
        p = self.params
        dt = 1.0 / p.smoothing_frequency
        command = [min(max(t, low), high)
                   for t, low, high in zip(target, p.min_velocity, p.max_velocity)]
        bounds = [_axis_bounds(c, t, a, d, dt)
                  for c, t, a, d in zip(current, command, p.max_accel, p.max_decel)]
        deltas = [t - c for t, c in zip(command, current)]
        eta = 1.0
        if p.scale_velocities:
            for delta, (low, high) in zip(deltas, bounds):
                if delta > high:
                    eta = min(eta, high / delta)
                elif delta < low:
                    eta = min(eta, low / delta)
        vx, vy, wz = (c + min(max(eta * delta, low), high)
                      for c, delta, (low, high) in zip(current, deltas, bounds))
        return vx, vy, wz
