"""
Pure core of the motor_controller node: cmd_vel to wheel speeds (no ROS).

Twists are body-frame REP-103 (vx m/s forward, vy m/s left, wz rad/s CCW); wheel
speeds are rad/s in the order FL, FR, RL, RR; times are seconds on any clock that
the caller uses consistently.

Pipeline of ``MotorCommandCore``:

1. ``validate_twist``: non-finite or absurd components reject the whole command
   (and zero the target); otherwise each component is clamped to its max_velocity.
2. The target is scaled down as a whole (direction kept) until no wheel exceeds
   max_wheel_speed_rad_s. Doing this *before* rate limiting keeps the rate limiter's
   state equal to what the wheels really do, so acceleration limits hold on the real
   output: the set of reachable twists is convex and the rate limiter moves on the
   straight line from its current twist toward the target.
3. ``RateLimiter``: per-axis acceleration limits.
4. ``inverse_kinematics`` then ``desaturate`` (a safety net; a no-op up to rounding).

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


class CommandRejected(ValueError):
    """A velocity command that must not be executed (non-finite or absurd)."""


def validate_twist(vx: float, vy: float, wz: float, limits: TwistLimits) -> Twist2D:
    """
    Check a commanded twist (m/s, m/s, rad/s) and clamp it to the velocity limits.

    Raises CommandRejected naming the axis for a nan/inf component, or for one whose
    magnitude exceeds absurd_factor * max_velocity. Otherwise returns each component
    clamped to +-max_velocity.
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
        result.append(max(-axis.max_velocity, min(axis.max_velocity, value)))
    return result[0], result[1], result[2]


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
    """Latching emergency stop: stays engaged until release() is called."""

    def __init__(self) -> None:
        """Create a released e-stop."""
        self._engaged = False
        self._reason = ''

    @property
    def engaged(self) -> bool:
        """Return True while engaged."""
        return self._engaged

    @property
    def reason(self) -> str:
        """Return the reason given when first engaged ('' when released)."""
        return self._reason

    def engage(self, reason: str) -> None:
        """Engage; while already engaged the first reason is kept."""
        if not self._engaged:
            self._engaged = True
            self._reason = str(reason)

    def release(self) -> None:
        """Release the latch."""
        self._engaged = False
        self._reason = ''


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
    the e-stop was released). target_twist: validated, desaturated target
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
    limits), commands are ignored while engaged, and after release the target stays
    zero until a new command arrives (the old command is not resumed).
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
            twist = validate_twist(vx, vy, wz, self._limits)
        except CommandRejected:
            self._target = ZERO_TWIST
            raise
        if self._estop.engaged:
            return
        self._target = self._desaturate_twist(twist)
        self._watchdog.feed(now_s)
        self._has_command = True
        self._status = STATUS_OK

    def engage_estop(self, reason: str) -> None:
        """Engage the e-stop: zero target and output at once, ignore commands."""
        self._estop.engage(reason)
        self._stop_now()
        self._status = STATUS_ESTOP

    def release_estop(self) -> None:
        """Release the e-stop; the output stays zero until a new command arrives."""
        if self._estop.engaged:
            self._estop.release()
            self._stop_now()
            self._status = STATUS_WAITING

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
        """Return the current target twist (validated, clamped, desaturated)."""
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

    def _desaturate_twist(self, twist: Twist2D) -> Twist2D:
        """Scale a twist as a whole so that no wheel exceeds max_wheel_speed_rad_s."""
        peak = max(abs(w) for w in inverse_kinematics(self._geometry, *twist))
        if peak <= self._max_wheel_speed:
            return twist
        scale = self._max_wheel_speed / peak
        vx, vy, wz = (v * scale for v in twist)
        return vx, vy, wz
