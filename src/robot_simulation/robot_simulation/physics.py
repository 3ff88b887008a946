"""
Planar rigid-body physics of the four-wheel mecanum robot (pure Python, no ROS).

Conventions as in :mod:`mecanum_control.kinematics` (REP-103): the pose (x, y, yaw)
is in the world frame, the velocity v = (vx, vy, wz) in the body frame (base_link),
wheel order FL, FR, RL, RR, rollers in the X arrangement, k = lx + ly. Wheel i
rolls the robot along the row a_i of the inverse kinematics (r * omega_i = a_i . v)::

    a_FL = (1, -1, -k)   a_FR = (1, 1, k)   a_RL = (1, 1, -k)   a_RR = (1, -1, k)

The rows are orthogonal: sum_i a_i a_i^T = diag(4, 4, 4 k^2).

Motors (one DC gear motor per wheel, PWM duty u in [-1, 1], torque at the wheel)::

    tau_i = tau_stall * (u_i - omega_i / omega_0) - c_v * omega_i - tau_c * sgn(omega_i)

Linear torque-speed curve; omega_0 is the no-load wheel speed at full duty. Duties
with |u| <= dead_band_effort are 0, and 0 duty BRAKES (the H-bridge shorts the
motor: the back-EMF term still acts), like the real boards and like
``mecanum_control.board_model.Wheel``, whose speed decays to 0 with the same time
constant. tau_c = drive_friction_fraction * tau_stall (Coulomb drive-train
friction, never reversing a wheel by itself) and c_v = drive_viscous_fraction *
tau_stall / omega_0. The stall torque is derived from the configured time constant
tau_m: in straight motion each wheel carries J_eq = J_wheel + m r^2 / 4, so::

    tau_stall = J_eq * omega_0 / tau_m

and without slip or losses J_eq d(omega)/dt = tau_stall (u - omega / omega_0),
exactly board_model's first-order lag (omega -> u * omega_0 with time constant tau_m).

Body (Newton-Euler in the rotating body frame, M = diag(m, m, Iz))::

    J_wheel d(omega_i)/dt = tau_i - r F_i
    M (dv/dt + w x v) = sum_i a_i F_i + Q_rr,   w x v = (-wz vy, wz vx, 0)

F_i is the traction force of wheel i along its rolling direction (its generalised
force on the body is a_i F_i; the power F_i (a_i . v) balances the rim's). Q_rr is
rolling resistance, a force of C_rr m g against the translation and a torque of
C_rr m g sqrt(lx^2 + ly^2) against the rotation, never reversing the motion.

Traction (rollers, Coulomb friction): slip s_i = r omega_i - a_i . v. The wheel
sticks (s_i = 0) while |F_i| < mu N, N = m g / 4 (equal loads); otherwise it slips
with F_i = mu N sgn(s_i) ("roller slip"). The limit applies to F_i, so a
saturated straight start accelerates at exactly mu g. (A real 45-degree roller
passes its force along the roller axis, |force| = sqrt(2) |F_i|; fold that into
``friction_coefficient`` if wanted.) :meth:`MecanumPhysics.set_traction_factors`
scales each wheel's limit apart (a wheel on a slippery patch: the wheel_slip fault):
|F_i| < f_i mu N; a wheel with f_i = 0 transmits no force at all.

Time stepping (substep h <= max_substep_s, and short enough that the body moves
at most half the footprint radius at the larger of its speed and r omega_0): a
stiff slip spring would be unstable with the small wheel inertia, so each substep
solves for the traction IMPULSES P_i = F_i h that make every slip zero at the end
of the substep, implicitly in the motors' back-EMF damping c = tau_stall /
omega_0 (+ c_v); the drive-train friction impulse is capped at J_wheel |omega_i|::

    D     = J_wheel + h c
    b_i   = J_wheel omega_i + h (c omega_0 u_i - tau_c sgn(omega_i))
    omega_i' = (b_i - r P_i) / D
    v^    = R(-wz h) v + h M^-1 Q_rr             (free flight: the frame turns)
    v'    = v^ + M^-1 sum_i a_i P_i (+ contact impulses)

With no wheel saturated, slip' = 0 gives a DIAGONAL system (orthogonal rows)::

    (M + (D / r^2) diag(4, 4, 4 k^2)) v' = M v^ + (1 / r) sum_i a_i b_i
    P_i = (b_i - D (a_i . v') / r) / r

If some |P_i| > mu N h, an active-set loop fixes those wheels at +-mu N h
(they slip; the sign must agree with their slip), re-solves the rest (a 3x3
system), and releases a wheel whose slip disagrees; it is the exact solution of
the box-constrained problem (the Coulomb law with maximal dissipation), found in a
few iterations. For the straight no-slip case the scheme reads
(J_eq + h c) omega' = J_eq omega + h c omega_0 u; c is scaled by
expm1(h / tau_m) / (h / tau_m) so that this is the EXACT exponential step: a
straight, non-slipping start matches board_model for any step size. (Only there:
the loss torques are not scaled, so their ~1 % effect on the top speed varies by
~3 % of itself with h; rotation and slipping wheels, with other inertias, get a
stable implicit step that is slightly over-damped.)

Collisions: the footprint is a circle of radius R. After each substep the centre
is pushed out of every segment (world, (N, 4) x1 y1 x2 y2) and circle ((K, 3)
x y radius, e.g. moving obstacles, given per step and static during it) along the
contact normal to exactly touching, and the body velocity component into the
obstacle is removed (inelastic, frictionless walls). While touching (clearance <=
1e-6 m) the contact is also a unilateral constraint n . v' >= 0 in the next
substeps' impulse solve, so a robot pushing a wall stalls its wheels (or spins
them when the push exceeds friction). A collision event is the rising edge of
being in contact with anything; it re-arms only after a clearance of 1 mm from
every obstacle (a continued contact, sliding along a polyline wall or into a
corner, is one event). No tunnelling: the body moves at most R / 2 per substep, so
the centre cannot cross a thin wall between two checks. Broad phase: a uniform
grid over the world, each cell holding the segments that can touch a robot
centred in it (precomputed once); an open-room step checks no segment at all.

Accelerometer: ``MecanumPhysics.body_acceleration`` is the inertial
acceleration of the centre expressed in the body frame, averaged over the last
step: a = dv/dt + w x v = (dvx/dt - wz vy, dvy/dt + wz vx), i.e. the x, y specific
force an ideal IMU at the centre aligned with base_link reads (z reads +g).
``body_velocity_rate`` is (dvx/dt, dvy/dt) alone, for IMU models that add the
w x v terms themselves; ``world_acceleration`` is a in the world frame.
"""

from dataclasses import dataclass
import math
import numbers
from typing import Dict, List, Optional, Sequence, Tuple

from mecanum_control.angles import wrap_angle
from mecanum_control.kinematics import integrate_pose, MecanumGeometry
from mecanum_control.robot_config import RobotConfig
import numpy as np

STANDARD_GRAVITY_M_S2 = 9.80665
#: Clearance (m) below which an obstacle counts as touching (contact constraint, in_contact).
TOUCH_TOLERANCE_M = 1e-6
#: Clearance (m) from every obstacle that ends a collision event (re-arms the counter).
RELEASE_CLEARANCE_M = 1e-3
# Sign of vy and of wz in each wheel's inverse kinematics row, FL FR RL RR.
_SY = (-1.0, 1.0, 1.0, -1.0)
_SW = (-1.0, 1.0, -1.0, 1.0)
_MAX_SOLVER_ITERATIONS = 24
_PUSH_OUT_PASSES = 8
_SLIP_TOLERANCE_M_S = 1e-12
_PARALLEL_COS = 1.0 - 1e-9
# Cells with more candidate segments than this are checked with numpy.
_NUMPY_MIN_SEGMENTS = 12


def _real(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


@dataclass(frozen=True)
class PhysicsParams:
    """Physical parameters of the simulated robot (SI units, see the module docstring)."""

    geometry: MecanumGeometry
    mass_kg: float
    yaw_inertia_kg_m2: float
    footprint_radius_m: float
    friction_coefficient: float
    motor_no_load_speed_rad_s: float
    motor_time_constant_s: float
    wheel_inertia_kg_m2: float = 1e-4
    dead_band_effort: float = 0.03
    rolling_resistance_coefficient: float = 0.01
    drive_friction_fraction: float = 0.005
    drive_viscous_fraction: float = 0.0
    max_substep_s: float = 0.005
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2

    def __post_init__(self) -> None:
        if not isinstance(self.geometry, MecanumGeometry):
            raise ValueError(f'geometry must be a MecanumGeometry, got {self.geometry!r}')
        checks = (
            ('mass_kg', 0.0, False, math.inf), ('yaw_inertia_kg_m2', 0.0, False, math.inf),
            ('footprint_radius_m', 0.0, False, math.inf),
            ('friction_coefficient', 0.0, True, math.inf),
            ('motor_no_load_speed_rad_s', 0.0, False, math.inf),
            ('motor_time_constant_s', 0.0, False, math.inf),
            ('wheel_inertia_kg_m2', 0.0, False, math.inf),
            ('dead_band_effort', 0.0, True, 1.0),
            ('rolling_resistance_coefficient', 0.0, True, math.inf),
            ('drive_friction_fraction', 0.0, True, 1.0),
            ('drive_viscous_fraction', 0.0, True, math.inf),
            ('max_substep_s', 0.0, False, math.inf), ('gravity_m_s2', 0.0, False, math.inf))
        for name, low, low_ok, high in checks:
            value = getattr(self, name)
            if not (_real(value) and math.isfinite(value)
                    and (value >= low if low_ok else value > low) and value < high):
                bound = f'>= {low}' if low_ok else f'> {low}'
                upper = f' and < {high}' if math.isfinite(high) else ''
                raise ValueError(f'{name} must be a finite number {bound}{upper}, got {value!r}')

    @classmethod
    def from_robot_config(cls, config: RobotConfig, **overrides) -> 'PhysicsParams':
        """Build from the validated motor_params.yaml; keyword arguments override fields."""
        values = {
            'geometry': config.geometry, 'mass_kg': config.robot_mass_kg,
            'yaw_inertia_kg_m2': config.robot_yaw_inertia_kg_m2,
            'footprint_radius_m': config.footprint_radius_m,
            'friction_coefficient': config.wheel_friction_coefficient,
            'motor_no_load_speed_rad_s': config.motor_no_load_speed_rad_s,
            'motor_time_constant_s': config.motor_time_constant_s}
        values.update(overrides)
        return cls(**values)

    @property
    def equivalent_wheel_inertia_kg_m2(self) -> float:
        """Return J_eq = J_wheel + m r^2 / 4, the inertia one wheel drives in straight motion."""
        r = self.geometry.wheel_radius_m
        return self.wheel_inertia_kg_m2 + self.mass_kg * r * r / 4.0

    @property
    def stall_torque_n_m(self) -> float:
        """Return the wheel torque at full duty and zero speed, J_eq * omega_0 / tau_m."""
        return (self.equivalent_wheel_inertia_kg_m2 * self.motor_no_load_speed_rad_s
                / self.motor_time_constant_s)

    @property
    def wheel_normal_force_n(self) -> float:
        """Return the load on each wheel, m g / 4."""
        return self.mass_kg * self.gravity_m_s2 / 4.0

    @property
    def top_speed_m_s(self) -> float:
        """Return the no-load straight speed at full duty, r * omega_0."""
        return self.geometry.wheel_radius_m * self.motor_no_load_speed_rad_s


@dataclass
class BodyState:
    """Snapshot of the robot: world pose, body-frame twist, wheel speeds and angles."""

    x: float
    y: float
    yaw: float
    vx: float
    vy: float
    wz: float
    wheel_speeds_rad_s: Tuple[float, float, float, float]
    wheel_angles_rad: Tuple[float, float, float, float]


@dataclass(frozen=True)
class Contact:
    """An obstacle touching the footprint; the normal points from the obstacle to the robot."""

    kind: str  # 'segment' or 'circle'
    index: int  # row in the segments / circles array
    normal_x: float  # world frame, unit
    normal_y: float
    clearance_m: float  # distance from the footprint circle (<= TOUCH_TOLERANCE_M)


class _SegmentGrid:
    """Uniform grid broad phase: per cell, the segments a footprint centred in it may touch."""

    def __init__(self, segments, reach: float) -> None:
        array = np.asarray(segments if segments is not None else np.empty((0, 4)), dtype=float)
        if array.size == 0:
            array = array.reshape(0, 4)
        if array.ndim != 2 or array.shape[1] != 4:
            raise ValueError(f'segments must be an (N, 4) array x1 y1 x2 y2, got {array.shape}')
        if not np.all(np.isfinite(array)):
            raise ValueError('segments must be finite')
        self.segments = array
        self.cell = max(2.0 * reach, 0.1)
        self.inv_cell = 1.0 / self.cell
        self.cells: Dict[Tuple[int, int], tuple] = {}
        self.arrays: Dict[Tuple[int, int], tuple] = {}
        members: Dict[Tuple[int, int], List[int]] = {}
        # A centre inside a cell is within half a diagonal of the cell's centre.
        threshold = reach + self.cell * math.sqrt(0.5) + 1e-9
        for index, (x1, y1, x2, y2) in enumerate(array):
            ix = np.arange(math.floor((min(x1, x2) - threshold) * self.inv_cell),
                           math.floor((max(x1, x2) + threshold) * self.inv_cell) + 1)
            iy = np.arange(math.floor((min(y1, y2) - threshold) * self.inv_cell),
                           math.floor((max(y1, y2) + threshold) * self.inv_cell) + 1)
            gx, gy = np.meshgrid(ix, iy, indexing='ij')
            cx, cy = (gx + 0.5) * self.cell, (gy + 0.5) * self.cell
            distance = _point_segment_distance(cx, cy, x1, y1, x2, y2)
            for i, j in zip(gx[distance <= threshold], gy[distance <= threshold]):
                members.setdefault((int(i), int(j)), []).append(index)
        for key, indices in members.items():
            rows = []
            for index in indices:
                x1, y1, x2, y2 = (float(value) for value in array[index])
                dx, dy = x2 - x1, y2 - y1
                length2 = dx * dx + dy * dy
                rows.append((x1, y1, dx, dy, 1.0 / length2 if length2 > 0.0 else 0.0, index))
            self.cells[key] = tuple(rows)
            if len(rows) >= _NUMPY_MIN_SEGMENTS:
                self.arrays[key] = tuple(np.array(column) for column in zip(*rows))

    def lookup(self, x: float, y: float):
        """Return the candidate rows of the cell containing (x, y) and its key."""
        key = (math.floor(x * self.inv_cell), math.floor(y * self.inv_cell))
        return self.cells.get(key, ()), key


def _point_segment_distance(px, py, x1, y1, x2, y2):
    """Vectorised distance from points (px, py) to one segment."""
    dx, dy = x2 - x1, y2 - y1
    length2 = dx * dx + dy * dy
    if length2 > 0.0:
        t = np.clip(((px - x1) * dx + (py - y1) * dy) / length2, 0.0, 1.0)
    else:
        t = np.zeros_like(px, dtype=float)
    return np.hypot(px - (x1 + t * dx), py - (y1 + t * dy))


def _solve2(a11, a12, a21, a22, r1, r2):
    det = a11 * a22 - a12 * a21
    return (r1 * a22 - a12 * r2) / det, (a11 * r2 - a21 * r1) / det


def _solve3(kmat, rhs):
    (a, b, c), (d, e, f), (g, h, i) = kmat
    co_a, co_b, co_c = e * i - f * h, f * g - d * i, d * h - e * g
    inv_det = 1.0 / (a * co_a + b * co_b + c * co_c)
    r0, r1, r2 = rhs
    return ((co_a * r0 + (c * h - b * i) * r1 + (b * f - c * e) * r2) * inv_det,
            (co_b * r0 + (a * i - c * g) * r1 + (c * d - a * f) * r2) * inv_det,
            (co_c * r0 + (b * g - a * h) * r1 + (a * e - b * d) * r2) * inv_det)


class MecanumPhysics:
    """Rigid planar mecanum robot: motor dynamics, roller slip, circle-footprint contacts."""

    def __init__(self, params: PhysicsParams, segments: Optional[np.ndarray] = None,
                 x: float = 0.0, y: float = 0.0, yaw: float = 0.0) -> None:
        if not isinstance(params, PhysicsParams):
            raise ValueError(f'params must be PhysicsParams, got {params!r}')
        self.params = params
        geometry = params.geometry
        self._r = geometry.wheel_radius_m
        self._k = geometry.rotation_arm_m
        self._rows = tuple((1.0, sy, sw * self._k) for sy, sw in zip(_SY, _SW))
        self._m = params.mass_kg
        self._iz = params.yaw_inertia_kg_m2
        self._jw = params.wheel_inertia_kg_m2
        self._radius = params.footprint_radius_m
        self._omega0 = params.motor_no_load_speed_rad_s
        stall = params.stall_torque_n_m
        self._damping = stall / self._omega0 * (1.0 + params.drive_viscous_fraction)
        self._drive_gain = stall  # c * omega_0 (the viscous part does not drive)
        self._decay_rate = (self._damping / params.equivalent_wheel_inertia_kg_m2)
        self._coulomb = params.drive_friction_fraction * stall
        weight = self._m * params.gravity_m_s2
        self._traction_limit = params.friction_coefficient * weight / 4.0
        self._rr_force = params.rolling_resistance_coefficient * weight
        self._rr_torque = self._rr_force * math.hypot(geometry.half_wheelbase_m,
                                                      geometry.half_track_m)
        self._coeff_h = None
        self._coeffs = (0.0, 0.0, 0.0, 0.0)
        self.set_segments(segments)
        self._x, self._y, self._yaw = 0.0, 0.0, 0.0
        self._omega = [0.0] * 4
        self._angle = [0.0] * 4
        self.collision_count = 0
        self.rejected_duties = 0
        self._traction_factors: Optional[Tuple[float, float, float, float]] = None
        self.teleport(x, y, yaw)

    # ------------------------------------------------------------------ public API

    def set_segments(self, segments: Optional[np.ndarray]) -> None:
        """Replace the static world: an (N, 4) array of wall segments x1 y1 x2 y2."""
        self._grid = _SegmentGrid(segments, self._radius + RELEASE_CLEARANCE_M + 1e-9)

    @property
    def segments(self) -> np.ndarray:
        """Return the static wall segments, an (N, 4) array."""
        return self._grid.segments

    def teleport(self, x: float, y: float, yaw: float) -> None:
        """Put the robot at a pose at rest (velocities and wheel speeds zero, angles kept)."""
        if not all(_real(v) and math.isfinite(v) for v in (x, y, yaw)):
            raise ValueError(f'non-finite pose ({x}, {y}, {yaw})')
        self._x, self._y, self._yaw = float(x), float(y), wrap_angle(float(yaw))
        self._vx = self._vy = self._wz = 0.0
        self._omega = [0.0] * 4
        self._contacts: Tuple[Contact, ...] = ()
        self._latched = False
        self._accel_body = (0.0, 0.0)
        self._accel_world = (0.0, 0.0)
        self._velocity_rate = (0.0, 0.0)
        self._warm_signs: List[Optional[float]] = [None] * 4
        self._warm_contacts = frozenset()

    def move_to(self, x: float, y: float, yaw: float) -> None:
        """
        Put the robot at a pose keeping its motion (the kidnap fault: picked up and set down).

        The body-frame twist and the wheel speeds and angles are kept; the contacts are
        found anew in the next step. Nothing checks the pose: the caller keeps it clear
        of obstacles (an overlap is pushed out in the next step, counting a collision).
        """
        if not all(_real(v) and math.isfinite(v) for v in (x, y, yaw)):
            raise ValueError(f'non-finite pose ({x}, {y}, {yaw})')
        self._x, self._y, self._yaw = float(x), float(y), wrap_angle(float(yaw))
        self._contacts = ()
        self._latched = False
        self._warm_contacts = frozenset()

    def set_traction_factors(self, factors: Optional[Sequence[float]]) -> None:
        """
        Scale each wheel's friction limit (FL FR RL RR, each >= 0; None: all 1).

        Factor f_i: wheel i sticks while |F_i| < f_i mu N and slips at f_i mu N beyond
        (the wheel_slip fault); 0 transmits no force. All ones is the same as None.
        """
        if factors is not None:
            factors = tuple(factors)
            if len(factors) != 4 or not all(_real(f) and math.isfinite(f) and f >= 0.0
                                            for f in factors):
                raise ValueError('traction factors must be 4 finite numbers >= 0 '
                                 f'(FL, FR, RL, RR), got {factors!r}')
            factors = tuple(float(f) for f in factors)
            if factors == (1.0, 1.0, 1.0, 1.0):
                factors = None
        self._traction_factors = factors
        self._warm_signs = [None] * 4

    @property
    def traction_factors(self) -> Tuple[float, float, float, float]:
        """Return each wheel's friction limit factor, FL FR RL RR (1: the floor's)."""
        return self._traction_factors or (1.0, 1.0, 1.0, 1.0)

    @property
    def state(self) -> BodyState:
        """Return a snapshot of pose, body twist, wheel speeds and wheel angles."""
        return BodyState(self._x, self._y, self._yaw, self._vx, self._vy, self._wz,
                         tuple(self._omega), tuple(self._angle))

    @property
    def contacts(self) -> Tuple[Contact, ...]:
        """Return the obstacles touching the footprint after the last step."""
        return self._contacts

    @property
    def in_contact(self) -> bool:
        """Return whether any obstacle touches the footprint."""
        return bool(self._contacts)

    @property
    def body_acceleration(self) -> Tuple[float, float]:
        """
        Return the mean inertial acceleration over the last step, in the body frame.

        (dvx/dt - wz vy, dvy/dt + wz vx): what an accelerometer at the centre reads
        in x and y. Do not add the w x v terms again (see body_velocity_rate).
        """
        return self._accel_body

    @property
    def body_velocity_rate(self) -> Tuple[float, float]:
        """Return (dvx/dt, dvy/dt) over the last step: the body-frame components' rate only."""
        return self._velocity_rate

    @property
    def world_acceleration(self) -> Tuple[float, float]:
        """Return the mean acceleration over the last step in the world frame."""
        return self._accel_world

    def slip_velocities(self) -> Tuple[float, float, float, float]:
        """Return each wheel's slip r * omega_i - a_i . v (m/s), FL FR RL RR."""
        r, vx, vy, wz = self._r, self._vx, self._vy, self._wz
        fl, fr, rl, rr = (r * w - (a0 * vx + a1 * vy + a2 * wz)
                          for w, (a0, a1, a2) in zip(self._omega, self._rows))
        return fl, fr, rl, rr

    def step(self, duties: Sequence[float], dt_s: float,
             circles: Optional[np.ndarray] = None) -> None:
        """
        Advance by dt_s seconds with the four duties (FL FR RL RR) held constant.

        Duties are clamped to [-1, 1]; NaN or infinite duties count in
        ``rejected_duties`` and act as 0. ``circles`` (K, 3) x y radius are
        obstacles at their positions for this step (None: none).
        """
        if not (_real(dt_s) and math.isfinite(dt_s) and dt_s >= 0.0):
            raise ValueError(f'dt_s must be a finite number >= 0, got {dt_s!r}')
        if len(duties) != 4:
            raise ValueError(f'expected 4 duties (FL, FR, RL, RR), got {len(duties)}')
        dead_band = self.params.dead_band_effort
        efforts = []
        for duty in duties:
            duty = float(duty)
            if not math.isfinite(duty):
                self.rejected_duties += 1
                duty = 0.0
            duty = 1.0 if duty > 1.0 else -1.0 if duty < -1.0 else duty
            efforts.append(0.0 if abs(duty) <= dead_band else duty)
        if dt_s == 0.0:
            return
        circle_rows = self._circle_rows(circles)
        # Substeps: at most max_substep_s, and at most R / 2 of travel at the top speed.
        speed = max(math.hypot(self._vx, self._vy), self.params.top_speed_m_s)
        count = max(1, math.ceil(dt_s / self.params.max_substep_s - 1e-9),
                    math.ceil(speed * dt_s / (0.5 * self._radius) - 1e-9))
        h = dt_s / count
        if h != self._coeff_h:
            self._set_coefficients(h)
        sums = [0.0, 0.0, 0.0, 0.0]
        start_vx, start_vy = self._vx, self._vy
        for _ in range(count):
            self._substep(efforts, h, circle_rows, sums)
        self._accel_body = (sums[0] / dt_s, sums[1] / dt_s)
        self._accel_world = (sums[2] / dt_s, sums[3] / dt_s)
        self._velocity_rate = ((self._vx - start_vx) / dt_s, (self._vy - start_vy) / dt_s)

    # ------------------------------------------------------------------ internals

    def _set_coefficients(self, h: float) -> None:
        # Exponential fitting: (J_eq + h s c) omega' = J_eq omega + ... is the exact step of
        # the straight no-slip first-order lag when s = expm1(x) / x, x = h c / J_eq.
        x = h * self._decay_rate
        scale = math.expm1(x) / x
        damping = self._damping * scale
        self._coeffs = (self._jw + h * damping, h * self._drive_gain * scale,
                        self._traction_limit * h, damping)
        self._coeff_h = h

    @staticmethod
    def _circle_rows(circles) -> tuple:
        if circles is None:
            return ()
        array = np.asarray(circles, dtype=float)
        if array.size == 0:
            return ()
        if array.ndim != 2 or array.shape[1] != 3:
            raise ValueError(f'circles must be a (K, 3) array x y radius, got {array.shape}')
        if not np.all(np.isfinite(array)) or np.any(array[:, 2] < 0.0):
            raise ValueError('circles must be finite with radius >= 0')
        return tuple(tuple(row) for row in array.tolist())

    def _substep(self, efforts, h, circle_rows, sums) -> None:
        r, m, iz, jw = self._r, self._m, self._iz, self._jw
        big_d, drive, limit, _ = self._coeffs
        # Free flight: body-frame velocity of a force-free body turns with the frame.
        vx, vy, wz = self._vx, self._vy, self._wz
        turn = wz * h
        if turn != 0.0:
            cos_t, sin_t = math.cos(turn), math.sin(turn)
            vx, vy = vx * cos_t + vy * sin_t, vy * cos_t - vx * sin_t
        free_vx, free_vy = vx, vy
        if self._rr_force > 0.0:
            speed = math.hypot(vx, vy)
            if speed > 0.0:
                scale = max(0.0, speed - self._rr_force * h / m) / speed
                vx *= scale
                vy *= scale
            if wz != 0.0:
                change = min(self._rr_torque * h / iz, abs(wz))
                wz = wz - change if wz > 0.0 else wz + change
        # Wheel momentum plus motor drive and drive-train friction impulses.
        coulomb_h = self._coulomb * h
        bs = []
        for omega, effort in zip(self._omega, efforts):
            impulse = jw * omega + drive * effort
            if omega > 0.0:
                impulse -= min(coulomb_h, jw * omega)
            elif omega < 0.0:
                impulse += min(coulomb_h, -jw * omega)
            bs.append(impulse)
        contacts = self._contacts
        solution = None
        if not contacts:
            solution = self._solve_free(vx, vy, wz, bs, big_d, limit)
            if solution is not None:
                self._warm_signs = [None] * 4
        if solution is None:
            cos_y, sin_y = math.cos(self._yaw), math.sin(self._yaw)
            normals = [(cos_y * c.normal_x + sin_y * c.normal_y,
                        cos_y * c.normal_y - sin_y * c.normal_x) for c in contacts]
            keys = [(c.kind, c.index) for c in contacts]
            solution = self._solve_general(vx, vy, wz, bs, big_d, limit, normals, keys)
        vx, vy, wz, impulses = solution
        omega_old = self._omega
        omega_new = [(b - r * p) / big_d for b, p in zip(bs, impulses)]
        half_h = 0.5 * h
        self._angle = [angle + half_h * (w0 + w1)
                       for angle, w0, w1 in zip(self._angle, omega_old, omega_new)]
        self._omega = omega_new
        self._x, self._y, self._yaw = integrate_pose(self._x, self._y, self._yaw, vx, vy, wz, h)
        self._vx, self._vy, self._wz = vx, vy, wz
        self._collide(circle_rows)
        cos_y, sin_y = math.cos(self._yaw), math.sin(self._yaw)
        dvx, dvy = self._vx - free_vx, self._vy - free_vy
        sums[0] += dvx
        sums[1] += dvy
        sums[2] += cos_y * dvx - sin_y * dvy
        sums[3] += sin_y * dvx + cos_y * dvy

    def _solve_free(self, vx, vy, wz, bs, big_d, limit):
        """No contacts: the all-wheels-stick solution, or None when a wheel would slip."""
        r, m, iz, k = self._r, self._m, self._iz, self._k
        b0, b1, b2, b3 = bs
        g4 = 4.0 * big_d / (r * r)
        nvx = (m * vx + (b0 + b1 + b2 + b3) / r) / (m + g4)
        nvy = (m * vy + (b1 + b2 - b0 - b3) / r) / (m + g4)
        nwz = (iz * wz + k * (b1 + b3 - b0 - b2) / r) / (iz + g4 * k * k)
        scale = big_d / r
        kw = k * nwz
        p0 = (b0 - scale * (nvx - nvy - kw)) / r
        p1 = (b1 - scale * (nvx + nvy + kw)) / r
        p2 = (b2 - scale * (nvx + nvy - kw)) / r
        p3 = (b3 - scale * (nvx - nvy + kw)) / r
        factors = self._traction_factors
        if factors is None:
            if max(abs(p0), abs(p1), abs(p2), abs(p3)) > limit:
                return None
        elif (abs(p0) > limit * factors[0] or abs(p1) > limit * factors[1]
              or abs(p2) > limit * factors[2] or abs(p3) > limit * factors[3]):
            return None
        return nvx, nvy, nwz, (p0, p1, p2, p3)

    def _solve_general(self, vx, vy, wz, bs, big_d, limit, normals, keys):
        """
        Active-set solve of the traction impulses with friction limits and contacts.

        Wheels are free (stick, slip' = 0) or fixed at +-limit (slip in the same
        direction); contacts are active (n . v' = 0, impulse >= 0) or inactive
        (n . v' >= 0). The search starts from the previous substep's final sets,
        so it usually ends after one solve; after the iteration cap the last
        iterate is used.
        """
        r, m, iz, k = self._r, self._m, self._iz, self._k
        g = big_d / (r * r)
        gk, gkk = g * k, g * k * k
        inv_r = 1.0 / r
        factors = self._traction_factors
        limits = (limit,) * 4 if factors is None else tuple(limit * f for f in factors)
        # A wheel without grip (limit 0) transmits nothing: fixed at 0, never released.
        fixed: List[Optional[float]] = [
            0.0 if wheel_limit <= 0.0 else None if sign is None else sign * wheel_limit
            for sign, wheel_limit in zip(self._warm_signs, limits)]
        active = [j for j, key in enumerate(keys) if key in self._warm_contacts]
        base = (m * vx, m * vy, iz * wz)
        v = (vx, vy, wz)
        impulses = [0.0] * 4
        lambdas: List[float] = []
        for _ in range(_MAX_SOLVER_ITERATIONS):
            k00, k11, k22 = m, m, iz
            k01 = k02 = k12 = 0.0
            r0, r1, r2 = base
            for sy, sw, b, p in zip(_SY, _SW, bs, fixed):
                if p is None:
                    k00 += g
                    k11 += g
                    k22 += gkk
                    k01 += g * sy
                    k02 += gk * sw
                    k12 += gk * sy * sw
                    p = b * inv_r
                r0 += p
                r1 += p * sy
                r2 += p * sw * k
            kmat = ((k00, k01, k02), (k01, k11, k12), (k02, k12, k22))
            v, lambdas = self._constrained_solve(kmat, (r0, r1, r2), [normals[j] for j in active])
            along = [v[0] + sy * v[1] + sw * k * v[2] for sy, sw in zip(_SY, _SW)]
            impulses = [(b - big_d * s * inv_r) * inv_r if p is None else p
                        for b, s, p in zip(bs, along, fixed)]
            changed = False
            for i, p in enumerate(impulses):
                if fixed[i] is None and abs(p) > limits[i]:
                    fixed[i] = limits[i] if p > 0.0 else -limits[i]
                    changed = True
            if changed:
                continue
            if limit > 0.0:
                worst, worst_i = -_SLIP_TOLERANCE_M_S, None
                for i, p in enumerate(fixed):
                    if p is not None and limits[i] > 0.0:
                        slip = r * (bs[i] - r * p) / big_d - along[i]
                        agreement = slip if p > 0.0 else -slip
                        if agreement < worst:
                            worst, worst_i = agreement, i
                if worst_i is not None:
                    fixed[worst_i] = None
                    continue
            if lambdas:
                smallest = min(lambdas)
                if smallest < -1e-12:
                    del active[lambdas.index(smallest)]
                    continue
            worst, worst_j = -_SLIP_TOLERANCE_M_S, None
            for j, (nx, ny) in enumerate(normals):
                if j not in active:
                    approach = nx * v[0] + ny * v[1]
                    if approach < worst:
                        worst, worst_j = approach, j
            if worst_j is None:
                break
            if any(nx * normals[worst_j][0] + ny * normals[worst_j][1] > _PARALLEL_COS
                   for nx, ny in (normals[j] for j in active)):
                break  # the same constraint is active already (numerical residue)
            if len(active) == 2:
                del active[0 if lambdas[0] <= lambdas[1] else 1]
            active.append(worst_j)
        if limit > 0.0:
            self._warm_signs = [None if p is None or wheel_limit <= 0.0
                                else (1.0 if p > 0.0 else -1.0)
                                for p, wheel_limit in zip(fixed, limits)]
        self._warm_contacts = frozenset(keys[j] for j in active)
        return v[0], v[1], v[2], tuple(impulses)

    @staticmethod
    def _constrained_solve(kmat, rhs, normals):
        """Solve K v = rhs + sum_j lambda_j (n_j, 0) with n_j . v = 0; return v and lambdas."""
        if not normals:
            return _solve3(kmat, rhs), []
        n1x, n1y = normals[0]
        independent = (len(normals) == 2
                       and abs(n1x * normals[1][0] + n1y * normals[1][1]) < _PARALLEL_COS)
        if independent:
            # Translation locked: only the rotation is free.
            v = (0.0, 0.0, rhs[2] / kmat[2][2])
        else:
            tx, ty = -n1y, n1x
            k_tt = (tx * (kmat[0][0] * tx + kmat[0][1] * ty)
                    + ty * (kmat[1][0] * tx + kmat[1][1] * ty))
            k_tw = tx * kmat[0][2] + ty * kmat[1][2]
            z1, z2 = _solve2(k_tt, k_tw, k_tw, kmat[2][2], tx * rhs[0] + ty * rhs[1], rhs[2])
            v = (z1 * tx, z1 * ty, z2)
        fx = kmat[0][0] * v[0] + kmat[0][1] * v[1] + kmat[0][2] * v[2] - rhs[0]
        fy = kmat[1][0] * v[0] + kmat[1][1] * v[1] + kmat[1][2] * v[2] - rhs[1]
        if independent:
            (n2x, n2y) = normals[1]
            return v, list(_solve2(n1x, n2x, n1y, n2y, fx, fy))
        along = fx * n1x + fy * n1y
        if len(normals) == 1:
            return v, [along]
        # Two parallel constraints: one line; opposite normals share the force by its sign.
        same = n1x * normals[1][0] + n1y * normals[1][1] > 0.0
        if same:
            return v, [along, along]
        return v, [max(along, 0.0), max(-along, 0.0)]

    def _find(self, x, y, circle_rows, reach):
        """Return (kind, index, clearance, nx, ny) of obstacles within reach of the footprint."""
        radius = self._radius
        limit = radius + reach
        found = []
        rows, key = self._grid.lookup(x, y)
        if rows:
            arrays = self._grid.arrays.get(key)
            if arrays is not None:
                rows = self._numpy_candidates(x, y, arrays, limit, rows)
            for x1, y1, dx, dy, inv_length2, index in rows:
                ex, ey = x - x1, y - y1
                t = (ex * dx + ey * dy) * inv_length2
                t = 0.0 if t < 0.0 else 1.0 if t > 1.0 else t
                ex -= t * dx
                ey -= t * dy
                distance2 = ex * ex + ey * ey
                if distance2 <= limit * limit:
                    distance = math.sqrt(distance2)
                    if distance > 1e-12:
                        nx, ny = ex / distance, ey / distance
                    else:
                        nx, ny = self._fallback_normal(-dy, dx)
                    found.append(('segment', index, distance - radius, nx, ny))
        for index, (cx, cy, cr) in enumerate(circle_rows):
            ex, ey = x - cx, y - cy
            span = limit + cr
            if abs(ex) <= span and abs(ey) <= span:
                distance = math.hypot(ex, ey)
                if distance <= span:
                    if distance > 1e-12:
                        nx, ny = ex / distance, ey / distance
                    else:
                        nx, ny = self._fallback_normal(1.0, 0.0)
                    found.append(('circle', index, distance - cr - radius, nx, ny))
        return found

    def _fallback_normal(self, nx, ny):
        """Return a unit normal for a centre exactly on an obstacle (against the motion)."""
        length = math.hypot(nx, ny) or 1.0
        nx, ny = nx / length, ny / length
        cos_y, sin_y = math.cos(self._yaw), math.sin(self._yaw)
        wvx = cos_y * self._vx - sin_y * self._vy
        wvy = sin_y * self._vx + cos_y * self._vy
        if nx * wvx + ny * wvy > 0.0:
            return -nx, -ny
        return nx, ny

    @staticmethod
    def _numpy_candidates(x, y, arrays, limit, rows):
        """Narrow a large candidate list with one vectorised point-segment distance."""
        x1, y1, dx, dy, inv_length2, _ = arrays
        t = np.clip(((x - x1) * dx + (y - y1) * dy) * inv_length2, 0.0, 1.0)
        ex, ey = x - x1 - t * dx, y - y1 - t * dy
        near = np.flatnonzero(ex * ex + ey * ey <= limit * limit * (1.0 + 1e-9) + 1e-18)
        return [rows[i] for i in near.tolist()]

    def _collide(self, circle_rows) -> None:
        """Push the footprint out of obstacles, stop motion into them, count events."""
        x, y = self._x, self._y
        found = self._find(x, y, circle_rows, RELEASE_CLEARANCE_M)
        pushed = False
        yielding = set()  # circles whose push would drive the robot into a wall
        for _ in range(_PUSH_OUT_PASSES):
            deepest = None
            for item in found:
                if (item[2] < 0.0 and (item[0], item[1]) not in yielding
                        and (deepest is None or item[2] < deepest[2])):
                    deepest = item
            if deepest is None:
                break
            kind, index, clearance, nx, ny = deepest
            new_x, new_y = x - clearance * nx, y - clearance * ny
            new_found = self._find(new_x, new_y, circle_rows, RELEASE_CLEARANCE_M)
            if kind == 'circle' and any(item[0] == 'segment' and item[2] < -1e-9
                                        for item in new_found):
                # Walls win: a person pressing the robot against a wall overlaps it
                # (a collision) instead of pushing it through the wall.
                yielding.add((kind, index))
                continue
            x, y, found = new_x, new_y, new_found
            pushed = True
        touching = [item for item in found if item[2] <= TOUCH_TOLERANCE_M]
        if pushed:
            self._x, self._y = x, y
        if touching:
            cos_y, sin_y = math.cos(self._yaw), math.sin(self._yaw)
            wvx = cos_y * self._vx - sin_y * self._vy
            wvy = sin_y * self._vx + cos_y * self._vy
            for _ in range(2):  # twice: sequential projections into an acute corner
                for _, _, _, nx, ny in touching:
                    into = wvx * nx + wvy * ny
                    if into < 0.0:
                        wvx -= into * nx
                        wvy -= into * ny
            self._vx = cos_y * wvx + sin_y * wvy
            self._vy = cos_y * wvy - sin_y * wvx
            if not self._latched:
                self.collision_count += 1
                self._latched = True
            self._contacts = tuple(Contact(kind, index, nx, ny, clearance)
                                   for kind, index, clearance, nx, ny in touching)
        else:
            self._contacts = ()
            if not found:
                self._latched = False
