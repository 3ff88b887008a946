"""
Pure core of the motor_controller node: cmd_vel to wheel speeds (no ROS).

Twists are body-frame REP-103 (vx m/s forward, vy m/s left, wz rad/s CCW); wheel
speeds are rad/s in the order FL, FR, RL, RR; times are seconds on any clock that
the caller uses consistently.

Pipeline of ``MotorCommandCore``:

1. ``limit_twist``: non-finite or absurd components reject the whole command (and
   zero the target, see ``validate_twist``); otherwise the twist is scaled down as a
   whole (direction kept) until each axis is within its max_velocity and no wheel
   exceeds max_wheel_speed_rad_s. Doing this *before* rate limiting keeps the rate
   limiter's state equal to what the wheels really do, so acceleration limits hold on
   the real output: the set of reachable twists is convex and the rate limiter moves
   on the straight line from its current twist toward the target.
2. ``RateLimiter``: per-axis acceleration limits.
3. ``inverse_kinematics`` then ``desaturate`` (a safety net; a no-op up to rounding).

``limit_twist`` is the robot's one velocity limit: twist_mux, the first stage of the
command chain (mecanum_safety), applies it to every twist it forwards, so that the
collision monitor and the zone guard judge the twist the wheels will run, and
motor_controller's own limiting is a no-op on the chain's output (it is idempotent).
Clamping each axis on its own would turn the direction of motion instead (an
over-limit diagonal would run at another angle than the one the chain judged).

E-stop zeroes the output at once; a command timeout only zeroes the target, so the
robot decelerates with the acceleration limits (smooth, like diff_drive_controller).
"""

from dataclasses import dataclass
import math
from typing import Optional, Tuple

from mecanum_control.kinematics import desaturate, inverse_kinematics, MecanumGeometry

Twist2D = Tuple[float, float, float]
WheelSpeeds = Tuple[float, float, float, float]

ZERO_TWIST: Twist2D = (0.0, 0.0, 0.0)
AXIS_NAMES = ('cmd_vel linear.x', 'cmd_vel linear.y', 'cmd_vel angular.z')
AXIS_UNITS = ('m/s', 'm/s', 'rad/s')


@dataclass(frozen=True)
class AxisLimits:
    """
    Limits of one twist axis, in m/s and m/s^2 (linear) or rad/s and rad/s^2 (yaw).

    max_velocity: finite and > 0. max_acceleration: > 0, math.inf for no limit.
    """

    max_velocity: float
    max_acceleration: float

    def __post_init__(self) -> None:
        """Validate both limits."""
        if not (math.isfinite(self.max_velocity) and self.max_velocity > 0.0):
            raise ValueError(
                f'AxisLimits.max_velocity must be finite and > 0, got {self.max_velocity!r}')
        if not self.max_acceleration > 0.0:  # also rejects nan; inf is allowed
            raise ValueError(
                f'AxisLimits.max_acceleration must be > 0 (inf for none), '
                f'got {self.max_acceleration!r}')


@dataclass(frozen=True)
class TwistLimits:
    """
    Limits of the three body-twist axes.

    A component beyond absurd_factor * max_velocity is rejected as garbage, not
    clamped (absurd_factor finite and >= 1).
    """

    x: AxisLimits
    y: AxisLimits
    wz: AxisLimits
    absurd_factor: float = 10.0

    def __post_init__(self) -> None:
        """Validate absurd_factor."""
        if not (math.isfinite(self.absurd_factor) and self.absurd_factor >= 1.0):
            raise ValueError(
                f'TwistLimits.absurd_factor must be finite and >= 1, got {self.absurd_factor!r}')

    @property
    def axes(self) -> Tuple[AxisLimits, AxisLimits, AxisLimits]:
        """Return the axis limits in the order (x, y, wz)."""
        return self.x, self.y, self.wz

    @classmethod
    def from_config(cls, config, absurd_factor: float = 10.0) -> 'TwistLimits':
        """Return the limits of a robot_config.RobotConfig (motor_params.yaml)."""
        return cls(x=AxisLimits(config.max_velocity_x_m_s, config.max_acceleration_x_m_s2),
                   y=AxisLimits(config.max_velocity_y_m_s, config.max_acceleration_y_m_s2),
                   wz=AxisLimits(config.max_angular_velocity_rad_s,
                                 config.max_angular_acceleration_rad_s2),
                   absurd_factor=absurd_factor)


class CommandRejected(ValueError):
    """A velocity command that must not be executed (non-finite or absurd)."""


def validate_twist(vx: float, vy: float, wz: float, limits: TwistLimits) -> Twist2D:
    """
    Check a commanded twist (m/s, m/s, rad/s); return it unchanged, as floats.

    Raises CommandRejected naming the axis for a nan/inf component, or for one whose
    magnitude exceeds absurd_factor * max_velocity (garbage, not a command to scale
    down). Limiting is limit_twist's job: it keeps the direction, per-axis clamping
    would not.
    """
    result = []
    for value, axis, name, unit in zip((vx, vy, wz), limits.axes, AXIS_NAMES, AXIS_UNITS):
        value = float(value)
        if not math.isfinite(value):
            raise CommandRejected(f'{name} is {value}')
        bound = limits.absurd_factor * axis.max_velocity
        if abs(value) > bound:
            raise CommandRejected(
                f'{name} = {value:g} {unit} is absurd: beyond {limits.absurd_factor:g} x '
                f'max_velocity {axis.max_velocity:g} {unit} = {bound:g} {unit}')
        result.append(value)
    return result[0], result[1], result[2]


#: A twist at most this much (relative) over a limit counts as within it, so that
#: limiting a twist that was already limited (rounding included) changes nothing.
LIMIT_TOLERANCE = 1e-9


def limit_scale(twist: Twist2D, limits: TwistLimits, geometry: MecanumGeometry,
                max_wheel_speed_rad_s: float) -> float:
    """
    Return the factor s in (0, 1] that brings twist (m/s, m/s, rad/s) within the limits.

    s * twist has each axis within its max_velocity and no wheel beyond
    max_wheel_speed_rad_s: the most limiting of those ratios, 1 when none limits.
    Raises CommandRejected as validate_twist (non-finite or absurd twist) and
    ValueError for a max_wheel_speed_rad_s that is not finite and > 0.
    """
    if not (math.isfinite(max_wheel_speed_rad_s) and max_wheel_speed_rad_s > 0.0):
        raise ValueError(
            f'max_wheel_speed_rad_s must be finite and > 0, got {max_wheel_speed_rad_s!r}')
    vx, vy, wz = validate_twist(*twist, limits)
    ratios = [axis.max_velocity / abs(value)
              for value, axis in zip((vx, vy, wz), limits.axes) if value != 0.0]
    peak = max(abs(w) for w in inverse_kinematics(geometry, vx, vy, wz))
    if peak > 0.0:
        ratios.append(max_wheel_speed_rad_s / peak)
    scale = min(ratios, default=1.0)
    return 1.0 if scale >= 1.0 - LIMIT_TOLERANCE else scale


def limit_twist(twist: Twist2D, limits: TwistLimits, geometry: MecanumGeometry,
                max_wheel_speed_rad_s: float) -> Twist2D:
    """
    Return twist (m/s, m/s, rad/s) scaled down as a whole to the robot's limits.

    The direction of motion (and the ratio of translation to rotation) is kept: the
    result is limit_scale(...) * twist, unchanged (as floats) when within the limits,
    so limiting twice changes nothing. Raises as limit_scale.
    """
    scale = limit_scale(twist, limits, geometry, max_wheel_speed_rad_s)
    vx, vy, wz = (float(v) for v in twist)
    if scale == 1.0:
        return vx, vy, wz
    return scale * vx, scale * vy, scale * wz


class RateLimiter:
    """
    Acceleration limiting of a twist toward a target, per axis.

    Each step moves the current twist toward the target by at most
    max_acceleration * dt on every axis. When an axis is limited, the WHOLE change
    vector (target - current) is scaled by the most limiting axis' ratio, so the
    twist moves on the straight line toward the target and the direction of motion
    is kept (e.g. a diagonal strafe stays diagonal while the slower axis ramps);
    the other axes then accelerate less than they could.
    """

    def __init__(self, limits: TwistLimits) -> None:
        """Create a limiter at rest."""
        self._limits = limits
        self._current: Twist2D = ZERO_TWIST

    @property
    def current(self) -> Twist2D:
        """Return the twist now commanded, after limiting (m/s, m/s, rad/s)."""
        return self._current

    def reset(self, twist: Twist2D = ZERO_TWIST) -> None:
        """Set the current twist, with no limiting."""
        vx, vy, wz = (float(v) for v in twist)
        self._current = (vx, vy, wz)

    def step(self, target: Twist2D, dt_s: float) -> Twist2D:
        """
        Move toward target (m/s, m/s, rad/s) for dt_s seconds and return the new twist.

        dt_s <= 0 or non-finite leaves the twist unchanged. A non-finite target
        raises ValueError.
        """
        if not all(math.isfinite(v) for v in target):
            raise ValueError(f'rate limiter target must be finite, got {target!r}')
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            return self._current
        deltas = [t - c for t, c in zip(target, self._current)]
        scale = 1.0
        for delta, axis in zip(deltas, self._limits.axes):
            allowed = axis.max_acceleration * dt_s
            if abs(delta) > allowed:
                scale = min(scale, allowed / abs(delta))
        if scale >= 1.0:
            vx, vy, wz = (float(t) for t in target)  # land exactly on the target
        else:
            vx, vy, wz = (c + scale * d for c, d in zip(self._current, deltas))
        self._current = (vx, vy, wz)
        return self._current


class EmergencyStop:
    """
    Latching emergency stop: stays engaged until release() is called.

    Its input (the e-stop button, the emergency_stop topic) engages it when pressed;
    letting go of the button does not release it, and release() is refused while the
    button is still pressed (a reset needs the button let go first, as ISO 13850).
    """

    def __init__(self) -> None:
        """Create a released e-stop."""
        self._engaged = False
        self._pressed = False
        self._reason = ''

    @property
    def engaged(self) -> bool:
        """Return True while engaged."""
        return self._engaged

    @property
    def pressed(self) -> bool:
        """Return True while the input's last value was true."""
        return self._pressed

    def set_pressed(self, pressed: bool, reason: str) -> None:
        """Take the input's value: true engages (with reason); false only lets go."""
        self._pressed = bool(pressed)
        if self._pressed:
            self.engage(reason)

    @property
    def reason(self) -> str:
        """Return the reason given when first engaged ('' when released)."""
        return self._reason

    def engage(self, reason: str) -> None:
        """Engage; while already engaged the first reason is kept."""
        if not self._engaged:
            self._engaged = True
            self._reason = str(reason)

    def release(self) -> bool:
        """Release the latch and return True; refused (False) while the input is pressed."""
        if self._pressed:
            return False
        self._engaged = False
        self._reason = ''
        return True


class CommandWatchdog:
    """
    Command timeout: expired unless fed within the last timeout_s seconds.

    expired() is True before the first feed and when now - last_feed > timeout_s.
    A clock that jumps back by more than timeout_s (e.g. a simulation restart)
    also counts as expired; smaller backward differences are tolerated as jitter.
    """

    def __init__(self, timeout_s: float) -> None:
        """Create an expired (never fed) watchdog; timeout_s must be finite and > 0."""
        if not (math.isfinite(timeout_s) and timeout_s > 0.0):
            raise ValueError(f'timeout_s must be finite and > 0, got {timeout_s!r}')
        self._timeout_s = float(timeout_s)
        self._last_feed_s: Optional[float] = None

    @property
    def timeout_s(self) -> float:
        """Return the timeout in seconds."""
        return self._timeout_s

    @property
    def last_feed_s(self) -> Optional[float]:
        """Return the time of the last feed, None if never fed."""
        return self._last_feed_s

    def feed(self, now_s: float) -> None:
        """Record a fresh command at now_s."""
        if not math.isfinite(now_s):
            raise ValueError(f'now_s must be finite, got {now_s!r}')
        self._last_feed_s = float(now_s)

    def expired(self, now_s: float) -> bool:
        """Return True if no feed happened within timeout_s before now_s."""
        if self._last_feed_s is None or not math.isfinite(now_s):
            return True
        return abs(now_s - self._last_feed_s) > self._timeout_s

    def reset(self) -> None:
        """Forget the last feed (expired until fed again)."""
        self._last_feed_s = None


STATUS_OK = 'ok'
STATUS_TIMEOUT = 'timeout'
STATUS_ESTOP = 'estop'
STATUS_WAITING = 'waiting'


@dataclass
class MotorCommandState:
    """
    Snapshot of MotorCommandCore for diagnostics.

    status: 'ok', 'timeout', 'estop' or 'waiting' (no command yet, or none since
    the e-stop was released). target_twist: validated target, limited by limit_twist
    (m/s, m/s, rad/s); limited_twist: the twist commanded after rate limiting;
    wheel_speeds: rad/s FL, FR, RL, RR; estop_reason: '' when released.
    """

    status: str = STATUS_WAITING
    target_twist: Twist2D = ZERO_TWIST
    limited_twist: Twist2D = ZERO_TWIST
    wheel_speeds: WheelSpeeds = (0.0, 0.0, 0.0, 0.0)
    estop_reason: str = ''


class MotorCommandCore:
    """
    The motor_controller logic: commands in, wheel speeds out, independent of ROS.

    Call on_command() for each cmd_vel and update() at the control rate with the
    same clock. Decisions: a rejected command zeroes the target before raising; a
    command timeout zeroes the target and the robot decelerates with the
    acceleration limits; the e-stop zeroes the output immediately (bypassing the
    limits), commands are ignored while engaged, a release is refused while the
    e-stop input is still pressed, and after release the target stays zero until a
    new command arrives (the old command is not resumed).
    """

    def __init__(self, geometry: MecanumGeometry, limits: TwistLimits,
                 max_wheel_speed_rad_s: float, cmd_timeout_s: float) -> None:
        """Create a core at rest, waiting for a first command."""
        if not (math.isfinite(max_wheel_speed_rad_s) and max_wheel_speed_rad_s > 0.0):
            raise ValueError(
                f'max_wheel_speed_rad_s must be finite and > 0, got {max_wheel_speed_rad_s!r}')
        self._geometry = geometry
        self._limits = limits
        self._max_wheel_speed = float(max_wheel_speed_rad_s)
        self._watchdog = CommandWatchdog(cmd_timeout_s)
        self._limiter = RateLimiter(limits)
        self._estop = EmergencyStop()
        self._target: Twist2D = ZERO_TWIST
        self._has_command = False
        self._last_update_s: Optional[float] = None
        self._wheels: WheelSpeeds = (0.0, 0.0, 0.0, 0.0)
        self._status = STATUS_WAITING

    def on_command(self, vx: float, vy: float, wz: float, now_s: float) -> None:
        """
        Take a cmd_vel (m/s, m/s, rad/s) received at now_s.

        Raises CommandRejected (after zeroing the target) for a non-finite or absurd
        component. Ignored while the e-stop is engaged.
        """
        try:
            twist = limit_twist((vx, vy, wz), self._limits, self._geometry,
                                self._max_wheel_speed)
        except CommandRejected:
            self._target = ZERO_TWIST
            raise
        if self._estop.engaged:
            return
        self._target = twist
        self._watchdog.feed(now_s)
        self._has_command = True
        self._status = STATUS_OK

    def engage_estop(self, reason: str) -> None:
        """Engage the e-stop: zero target and output at once, ignore commands."""
        self._estop.engage(reason)
        self._stop_now()
        self._status = STATUS_ESTOP

    def set_estop_input(self, pressed: bool, reason: str = 'emergency_stop topic') -> bool:
        """
        Take the e-stop input's value; return True when it engaged the stop just now.

        True engages the latching stop (as engage_estop); false only records that the
        input was let go: the stop stays engaged until release_estop().
        """
        was_engaged = self._estop.engaged
        self._estop.set_pressed(pressed, reason)
        if self._estop.engaged and not was_engaged:
            self._stop_now()
            self._status = STATUS_ESTOP
            return True
        return False

    def release_estop(self) -> bool:
        """
        Release the e-stop; the output stays zero until a new command arrives.

        Returns False, and stays engaged, while the input is still pressed; True
        otherwise (also when it was not engaged).
        """
        if self._estop.engaged:
            if not self._estop.release():
                return False
            self._stop_now()
            self._status = STATUS_WAITING
        return True

    def update(self, now_s: float) -> WheelSpeeds:
        """
        Advance to now_s and return wheel speeds in rad/s (FL, FR, RL, RR).

        dt is the time since the previous update (none on the first call or if the
        clock did not advance, so the twist then stays where it is).
        """
        if not math.isfinite(now_s):
            raise ValueError(f'now_s must be finite, got {now_s!r}')
        dt_s = 0.0 if self._last_update_s is None else now_s - self._last_update_s
        self._last_update_s = float(now_s)
        if self._estop.engaged:
            self._stop_now()
            self._status = STATUS_ESTOP
            return self._wheels
        if not self._has_command:
            self._target = ZERO_TWIST
            self._status = STATUS_WAITING
        elif self._watchdog.expired(now_s):
            self._target = ZERO_TWIST
            self._status = STATUS_TIMEOUT
        else:
            self._status = STATUS_OK
        limited = self._limiter.step(self._target, dt_s)
        wheels = inverse_kinematics(self._geometry, *limited)
        self._wheels = desaturate(wheels, self._max_wheel_speed)
        return self._wheels

    @property
    def limited_twist(self) -> Twist2D:
        """Return the twist (m/s, m/s, rad/s) actually commanded after limiting."""
        return self._limiter.current

    @property
    def target_twist(self) -> Twist2D:
        """Return the current target twist (validated, limited by limit_twist)."""
        return self._target

    @property
    def wheel_speeds(self) -> WheelSpeeds:
        """Return the last wheel speeds output (rad/s, FL, FR, RL, RR)."""
        return self._wheels

    @property
    def status(self) -> str:
        """Return 'ok', 'timeout', 'estop' or 'waiting' as of the last call."""
        return self._status

    @property
    def estop_engaged(self) -> bool:
        """Return True while the e-stop is engaged."""
        return self._estop.engaged

    @property
    def estop_pressed(self) -> bool:
        """Return True while the e-stop input's last value was true."""
        return self._estop.pressed

    @property
    def state(self) -> MotorCommandState:
        """Return a snapshot for diagnostics."""
        return MotorCommandState(status=self._status, target_twist=self._target,
                                 limited_twist=self._limiter.current,
                                 wheel_speeds=self._wheels, estop_reason=self._estop.reason)

    def _stop_now(self) -> None:
        """Zero target, limiter and output immediately and forget the last command."""
        self._target = ZERO_TWIST
        self._has_command = False
        self._watchdog.reset()
        self._limiter.reset(ZERO_TWIST)
        self._wheels = (0.0, 0.0, 0.0, 0.0)
