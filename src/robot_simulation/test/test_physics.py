"""
Tests of the mecanum rigid-body physics (robot_simulation.physics).

Numbers come from config/motor_params.yaml: r = 0.04 m, lx = 0.095 m, ly = 0.12 m
(k = lx + ly = 0.215 m), m = 4 kg, Iz = 0.051 kg m^2, footprint R = 0.2 m,
mu = 0.6, omega_0 = 34.5 rad/s, tau_m = 0.08 s; J_wheel = 1e-4 kg m^2 (default).
Hand-worked constants used below:

    J_eq      = J_wheel + m r^2 / 4 = 1e-4 + 4 * 0.0016 / 4 = 0.0017 kg m^2
    tau_stall = J_eq * omega_0 / tau_m = 0.0017 * 34.5 / 0.08 = 0.733125 N m
    top speed = r * omega_0 = 1.38 m/s
    a no-slip full-duty start needs r * omega_0 / tau_m = 17.25 m/s^2 > mu g = 5.88,
    so the no-slip tests raise mu to 10 (limit 98 m/s^2).

Wheel order FL, FR, RL, RR. Per kinematics.inverse_kinematics a +vy strafe turns
FL and RR backwards: duties (-, +, +, -); a +wz turn: (-, +, -, +).
"""

import math

from mecanum_control.angles import wrap_angle
from mecanum_control.board_model import MotorModel, Wheel
from mecanum_control.kinematics import forward_kinematics
from mecanum_control.robot_config import default_config_path, load_robot_config
import numpy as np
import pytest
from robot_simulation.physics import MecanumPhysics, PhysicsParams

CONFIG = load_robot_config(default_config_path())
G = 9.80665
R_WHEEL = 0.04
K_ARM = 0.215
OMEGA0 = 34.5
TAU = 0.08
STRAFE_LEFT = (-1.0, 1.0, 1.0, -1.0)
TURN_LEFT = (-1.0, 1.0, -1.0, 1.0)
LOSSLESS = {'rolling_resistance_coefficient': 0.0, 'drive_friction_fraction': 0.0}


def params(**overrides):
    """Return PhysicsParams from motor_params.yaml with some fields overridden."""
    return PhysicsParams.from_robot_config(CONFIG, **overrides)


def run(sim, duties, seconds, dt=0.005, circles=None):
    """Step the simulation with constant duties; return the list of states after each step."""
    states = []
    for _ in range(int(round(seconds / dt))):
        sim.step(duties, dt, circles)
        states.append(sim.state)
    return states


def wall_x(x, half_length=2.0):
    """Return a segments array holding one vertical wall at x."""
    return np.array([[x, -half_length, x, half_length]])


# ---------------------------------------------------------------- parameters


def test_params_from_config_derive_the_stall_torque():
    """tau_stall = J_eq omega_0 / tau_m = 0.0017 * 34.5 / 0.08 = 0.733125 N m."""
    p = params()
    assert p.geometry == CONFIG.geometry
    assert (p.mass_kg, p.friction_coefficient, p.footprint_radius_m) == (4.0, 0.6, 0.2)
    assert p.equivalent_wheel_inertia_kg_m2 == pytest.approx(0.0017)
    assert p.stall_torque_n_m == pytest.approx(0.733125)
    assert p.wheel_normal_force_n == pytest.approx(4.0 * G / 4.0)
    assert p.top_speed_m_s == pytest.approx(1.38)
    assert params(wheel_inertia_kg_m2=2e-4).wheel_inertia_kg_m2 == 2e-4


@pytest.mark.parametrize('field, value', [
    ('mass_kg', -1.0), ('yaw_inertia_kg_m2', 0.0), ('footprint_radius_m', math.nan),
    ('friction_coefficient', -0.1), ('motor_time_constant_s', math.inf),
    ('dead_band_effort', 1.0), ('max_substep_s', 0.0), ('wheel_inertia_kg_m2', '1e-4'),
    ('drive_friction_fraction', True)])
def test_params_validation_names_the_field(field, value):
    """Each invalid field raises a ValueError that names it."""
    with pytest.raises(ValueError, match=field):
        params(**{field: value})


def test_params_reject_a_non_geometry():
    """The geometry must be a MecanumGeometry."""
    with pytest.raises(ValueError, match='geometry'):
        params(geometry=(0.04, 0.095, 0.12))


# ---------------------------------------------------------------- no slip


def test_straight_start_without_slip_matches_the_board_model():
    """
    Full duty from rest, friction not saturating: omega(t) = omega_0 (1 - exp(-t / tau)).

    Lossless, the exponential-fitted implicit step is exact (1e-9); with the
    default losses (drive friction 0.5 % and rolling resistance 0.01 * m g,
    about 1 % of the stall torque together) within 2 % of board_model.Wheel.
    """
    motor = MotorModel(OMEGA0, TAU)
    for overrides, tolerance in ((LOSSLESS, 1e-9), ({}, 0.02)):
        sim = MecanumPhysics(params(friction_coefficient=10.0, **overrides))
        wheel = Wheel()
        for step in range(1, 101):
            sim.step((1.0, 1.0, 1.0, 1.0), 0.005)
            wheel.step(motor, 1.0, 0.005)
            if step in (4, 16, 32, 60, 100):  # t = 0.02, 0.08, 0.16, 0.3, 0.5 s
                speeds = sim.state.wheel_speeds_rad_s
                assert speeds == pytest.approx([wheel.speed_rad_s] * 4, rel=tolerance)
                assert step != 16 or wheel.speed_rad_s == pytest.approx(
                    OMEGA0 * (1.0 - math.exp(-1.0)))


def test_steady_straight_speed_is_r_omega0():
    """After 12 tau, vx = r omega_0 = 1.38 m/s (default losses -1 %); no sideways or yaw."""
    sim = MecanumPhysics(params(friction_coefficient=10.0))
    run(sim, (1.0, 1.0, 1.0, 1.0), 1.0)
    s = sim.state
    assert s.vx == pytest.approx(R_WHEEL * OMEGA0, rel=0.02)
    assert s.vx < R_WHEEL * OMEGA0
    assert (s.vy, s.wz, s.y, s.yaw) == pytest.approx((0.0, 0.0, 0.0, 0.0), abs=1e-12)
    lossless = MecanumPhysics(params(friction_coefficient=10.0, **LOSSLESS))
    run(lossless, (0.5, 0.5, 0.5, 0.5), 2.0)
    assert lossless.state.vx == pytest.approx(0.5 * R_WHEEL * OMEGA0, rel=1e-9)


def test_strafe_left_moves_along_y_only():
    """Duties (-, +, +, -) give +vy = r omega_0 u; x and yaw stay 0."""
    sim = MecanumPhysics(params(friction_coefficient=10.0, **LOSSLESS))
    run(sim, tuple(0.5 * d for d in STRAFE_LEFT), 1.5)
    s = sim.state
    assert s.vy == pytest.approx(0.5 * R_WHEEL * OMEGA0, rel=1e-6)
    assert s.y > 0.5
    assert (s.x, s.yaw, s.vx, s.wz) == pytest.approx((0.0, 0.0, 0.0, 0.0), abs=1e-12)


def test_rotation_moves_yaw_only():
    """
    Duties (-, +, -, +): wz = r omega / (lx + ly); the centre stays put.

    At u = 0.5, omega = 17.25 rad/s and wz = 0.04 * 17.25 / 0.215 = 3.209 rad/s.
    """
    sim = MecanumPhysics(params(friction_coefficient=10.0, **LOSSLESS), x=1.0, y=2.0)
    run(sim, tuple(0.5 * d for d in TURN_LEFT), 1.0)
    s = sim.state
    assert s.wz == pytest.approx(R_WHEEL * 0.5 * OMEGA0 / K_ARM, rel=1e-6)
    assert s.wz == pytest.approx(R_WHEEL * s.wheel_speeds_rad_s[1] / K_ARM, rel=1e-12)
    assert (s.x, s.y, s.vx, s.vy) == pytest.approx((1.0, 2.0, 0.0, 0.0), abs=1e-12)
    assert s.yaw != 0.0


def test_combined_motion_follows_forward_kinematics():
    """
    Inconsistent duties: the motors settle on a consistent set, the body follows FK.

    The slip of every wheel is zero (to 1e-9 m/s) and the twist equals
    forward_kinematics(wheel speeds) to 1e-6. Steady circle: an accelerometer
    reads only the centripetal term, (-wz vy, wz vx).
    """
    sim = MecanumPhysics(params(friction_coefficient=10.0))
    run(sim, (0.2, 0.5, 0.1, 0.3), 2.0)
    s = sim.state
    assert (s.vx, s.vy, s.wz) == pytest.approx(
        forward_kinematics(CONFIG.geometry, s.wheel_speeds_rad_s), abs=1e-6)
    assert sim.slip_velocities() == pytest.approx((0.0,) * 4, abs=1e-9)
    assert s.vx > 0.3 and s.wz > 0.5
    ax, ay = sim.body_acceleration
    assert (ax, ay) == pytest.approx((-s.wz * s.vy, s.wz * s.vx), abs=2e-3)
    assert sim.body_velocity_rate == pytest.approx((0.0, 0.0), abs=1e-6)
    assert math.hypot(*sim.world_acceleration) == pytest.approx(math.hypot(ax, ay))


def test_accelerometer_during_a_straight_start():
    """Without rotation the accelerometer reads dvx/dt (finite difference of vx)."""
    sim = MecanumPhysics(params(friction_coefficient=10.0))
    run(sim, (0.3, 0.3, 0.3, 0.3), 0.05)
    before = sim.state.vx
    sim.step((0.3, 0.3, 0.3, 0.3), 0.01)
    assert sim.body_acceleration[0] == pytest.approx((sim.state.vx - before) / 0.01)
    assert sim.body_acceleration[1] == 0.0
    assert sim.body_velocity_rate == pytest.approx(sim.body_acceleration)


# ---------------------------------------------------------------- slip and motor lag


def test_low_friction_start_accelerates_at_mu_g():
    """
    Low friction (mu = 0.05), full duty from rest: each wheel saturates at mu m g / 4.

    Body: m a = 4 mu m g / 4  ->  a = mu g = 0.05 * 9.80665 = 0.4903 m/s^2.
    Wheels: alone, J_wheel omega_0 / tau_stall = 1e-4 * 34.5 / 0.733 = 4.7 ms lag,
    so they are near omega_0 within 0.05 s while the body crawls: slip ratio > 0.75.
    With the default rolling resistance C_rr = 0.01: a = (mu - C_rr) g = 0.3923.
    """
    sim = MecanumPhysics(params(friction_coefficient=0.05, rolling_resistance_coefficient=0.0))
    states = run(sim, (1.0, 1.0, 1.0, 1.0), 0.5)
    assert states[9].wheel_speeds_rad_s[0] > 0.9 * OMEGA0  # t = 0.05 s
    assert (states[99].vx - states[19].vx) / 0.4 == pytest.approx(0.05 * G, rel=1e-3)
    assert sim.body_acceleration[0] == pytest.approx(0.05 * G, rel=1e-3)
    slip = sim.slip_velocities()
    rim = R_WHEEL * sim.state.wheel_speeds_rad_s[0]
    assert slip[0] / rim > 0.75
    assert slip == pytest.approx((slip[0],) * 4)
    rolling = MecanumPhysics(params(friction_coefficient=0.05))
    states = run(rolling, (1.0, 1.0, 1.0, 1.0), 0.5)
    assert (states[99].vx - states[19].vx) / 0.4 == pytest.approx(0.04 * G, rel=1e-3)


def test_slipping_strafe_keeps_its_direction():
    """A saturated strafe (mu = 0.1) moves along +y only at (mu - C_rr) g = 0.8826 m/s^2."""
    sim = MecanumPhysics(params(friction_coefficient=0.1))
    states = run(sim, STRAFE_LEFT, 0.5)
    s = sim.state
    assert (s.vy - states[19].vy) / 0.4 == pytest.approx((0.1 - 0.01) * G, rel=1e-3)
    assert (s.x, s.vx, s.wz) == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)


@pytest.mark.parametrize('dt', [0.005, 0.02])
def test_motor_lag_time_constant_from_a_fit(dt):
    """
    Duty step 0.5: fit ln(1 - omega / omega_final) = -t / tau over 0..3 tau.

    The least-squares slope through the origin gives tau = 0.08 s within 5 %.
    """
    sim = MecanumPhysics(params(friction_coefficient=10.0))
    states = run(sim, (0.5, 0.5, 0.5, 0.5), 1.5, dt=dt)
    final = states[-1].wheel_speeds_rad_s[0]
    samples = [((i + 1) * dt, math.log(1.0 - s.wheel_speeds_rad_s[0] / final))
               for i, s in enumerate(states) if (i + 1) * dt <= 3 * TAU + 1e-9]
    slope = sum(t * y for t, y in samples) / sum(t * t for t, _ in samples)
    assert -1.0 / slope == pytest.approx(TAU, rel=0.05)


# ---------------------------------------------------------------- collisions


def test_wall_stops_the_robot_touching_and_counts_one_event():
    """
    Wall at x = 1, R = 0.2: the centre stops at 0.8 and never passes it.

    Pushing at full duty for 3 s is one collision event; the wheels spin on the
    floor (tau_stall = 0.73 N m > r mu N = 0.04 * 0.6 * 9.81 = 0.235 N m).
    """
    sim = MecanumPhysics(params(), wall_x(1.0))
    states = run(sim, (1.0, 1.0, 1.0, 1.0), 3.0)
    assert max(s.x for s in states) <= 0.8 + 1e-9
    assert sim.state.x == pytest.approx(0.8, abs=1e-3)
    assert abs(sim.state.vx) < 1e-9
    assert sim.collision_count == 1 and sim.in_contact
    (contact,) = sim.contacts
    assert (contact.kind, contact.index) == ('segment', 0)
    assert (contact.normal_x, contact.normal_y) == pytest.approx((-1.0, 0.0))
    assert min(sim.state.wheel_speeds_rad_s) > 0.5 * OMEGA0


def test_pushing_a_wall_gently_stalls_the_wheels():
    """At duty 0.2 the push (0.2 * 0.733 = 0.147 N m) is below r mu N: wheels stop."""
    sim = MecanumPhysics(params(), wall_x(1.0), x=0.5)
    run(sim, (0.2, 0.2, 0.2, 0.2), 3.0)
    assert sim.state.x == pytest.approx(0.8, abs=1e-9)
    assert sim.state.wheel_speeds_rad_s == pytest.approx((0.0,) * 4, abs=1e-9)
    assert sim.collision_count == 1


def test_backing_off_and_hitting_again_counts_two():
    """Reverse away from the wall (contact ends), drive back in: a second event."""
    sim = MecanumPhysics(params(), wall_x(1.0))
    run(sim, (1.0, 1.0, 1.0, 1.0), 2.0)
    run(sim, (-1.0, -1.0, -1.0, -1.0), 1.0)
    assert not sim.in_contact and sim.state.x < 0.5
    assert sim.collision_count == 1
    run(sim, (1.0, 1.0, 1.0, 1.0), 2.0)
    assert sim.collision_count == 2
    assert sim.state.x == pytest.approx(0.8, abs=1e-9)


@pytest.mark.parametrize('dt, max_substep', [(0.02, 0.005), (0.2, 0.2)])
@pytest.mark.parametrize('wall', [2.9, 3.1, 3.3])
def test_no_tunnelling_through_a_thin_wall_at_3_m_s(dt, max_substep, wall):
    """
    omega_0 = 75 rad/s makes the top speed 3 m/s.

    With 0.2 s steps an unlimited substep would move 0.6 m, more than the
    footprint's diameter: for one of these wall positions (0.2 m apart, a third
    of 0.6 m) the centre would land beyond the wall and be pushed out on the
    far side. The R / 2 travel limit keeps each substep <= 0.1 m.
    """
    sim = MecanumPhysics(params(friction_coefficient=10.0, motor_no_load_speed_rad_s=75.0,
                                max_substep_s=max_substep), wall_x(wall))
    states = run(sim, (1.0, 1.0, 1.0, 1.0), 3.0, dt=dt)
    assert max(s.vx for s in states) > 2.5
    assert max(s.x for s in states) <= wall - 0.2 + 1e-9
    assert sim.state.x == pytest.approx(wall - 0.2, abs=1e-9)
    assert sim.collision_count == 1


def test_scraping_along_a_wall_while_turning_is_one_event():
    """
    Driving an arc (left wheels faster) into a wall and scraping off it: one event.

    While turning, the body-frame velocity turns with the robot, so the contact
    clearance flickers around zero; the event re-arms only after 1 mm clearance.
    """
    sim = MecanumPhysics(params(), wall_x(1.0, half_length=3.0), x=0.5)
    states = run(sim, (1.0, 0.6, 1.0, 0.6), 3.0)
    assert max(s.x for s in states) <= 0.8 + 1e-9
    assert sum(s.x > 0.8 - 1e-6 for s in states) > 20
    assert sim.collision_count == 1


def test_wall_of_many_short_segments_uses_the_vectorised_check():
    """Forty 5 cm segments at x = 1 (numpy narrow phase): still stops at 0.8, one event."""
    ys = np.linspace(-1.0, 1.0, 41)
    segments = np.column_stack([np.full(40, 1.0), ys[:-1], np.full(40, 1.0), ys[1:]])
    sim = MecanumPhysics(params(), segments)
    states = run(sim, (1.0, 1.0, 1.0, 1.0), 2.0)
    assert max(s.x for s in states) <= 0.8 + 1e-9
    assert sim.state.x == pytest.approx(0.8, abs=1e-9)
    assert sim.collision_count == 1
    assert {c.index for c in sim.contacts} <= {19, 20}


def test_circle_obstacle_stops_the_robot():
    """Circle r = 0.1 at (1, 0): the centre stops at 1 - 0.1 - 0.2 = 0.7."""
    circles = np.array([[1.0, 0.0, 0.1]])
    sim = MecanumPhysics(params())
    states = run(sim, (1.0, 1.0, 1.0, 1.0), 2.0, circles=circles)
    assert max(s.x for s in states) <= 0.7 + 1e-9
    assert sim.state.x == pytest.approx(0.7, abs=1e-3)
    assert abs(sim.state.vx) < 1e-9
    assert sim.collision_count == 1
    assert sim.contacts[0].kind == 'circle'


def test_moving_circle_pushes_the_robot():
    """A circle moving at -0.5 m/s from x = 0.5 into a robot at rest shoves it to -0.3."""
    sim = MecanumPhysics(params())
    cx = 0.5
    for _ in range(200):
        cx -= 0.5 * 0.005
        sim.step((0.0, 0.0, 0.0, 0.0), 0.005, np.array([[cx, 0.0, 0.1]]))
        assert sim.state.x <= cx - 0.3 + 1e-9
    assert sim.state.x == pytest.approx(-0.3, abs=1e-9)
    assert sim.collision_count == 1


def test_diagonal_drive_slides_along_a_wall_into_a_corner():
    """
    Duties (0, 1, 1, 0) drive vx = vy; the wall at x = 1 stops x, y keeps going.

    Free: vx = vy = r omega_0 / 2 = 0.69 m/s. Along the wall (vx = 0) FL and RR
    must turn backwards at omega against their brakes (torque c omega), FR and RL
    forwards (torque c (omega_0 - omega)): the y force balances at omega_0 / 2, so
    vy stays r omega_0 / 2 (lossless) if no wheel slips (mu = 10; at
    mu = 0.6 FR and RL would press c omega_0 / 2 / r = 9.2 N > mu N = 5.9 N into
    the wall and slip). Sliding and then meeting the wall at y = 1 is one
    continued contact: one event; it ends at (0.8, 0.8) without turning.
    """
    segments = np.array([[1.0, -2.0, 1.0, 2.0], [-2.0, 1.0, 2.0, 1.0]])
    sim = MecanumPhysics(params(friction_coefficient=10.0, **LOSSLESS), segments, x=0.5)
    states = run(sim, (0.0, 1.0, 1.0, 0.0), 1.0)
    touching = [s for s in states if s.x >= 0.8 - 1e-9]
    assert touching and touching[-1].y > touching[0].y + 0.2
    assert touching[-1].vy == pytest.approx(R_WHEEL * OMEGA0 / 2, rel=1e-4)
    assert sim.slip_velocities() == pytest.approx((0.0,) * 4, abs=1e-9)
    assert all(s.x <= 0.8 + 1e-9 and s.y <= 0.8 + 1e-9 for s in states)
    run(sim, (0.0, 1.0, 1.0, 0.0), 3.0)
    s = sim.state
    assert (s.x, s.y, s.yaw) == pytest.approx((0.8, 0.8, 0.0), abs=1e-9)
    assert sim.collision_count == 1
    assert len(sim.contacts) == 2


# ---------------------------------------------------------------- determinism, dt, energy


def drive_schedule(sim, dt):
    """Run a fixed 3 s duty schedule with starts, strafes, turns and a wall."""
    for duties, seconds in (((1.0, 1.0, 1.0, 1.0), 0.8), ((0.7, -0.2, 0.5, 0.9), 0.7),
                            (STRAFE_LEFT, 0.5), ((0.0, 0.0, 0.0, 0.0), 1.0)):
        run(sim, duties, seconds, dt=dt)


def test_same_inputs_give_the_same_trajectory_bitwise():
    """Two simulators fed the same inputs end in identical states."""
    sims = [MecanumPhysics(params(), wall_x(1.2)) for _ in range(2)]
    for sim in sims:
        drive_schedule(sim, 0.005)
    assert sims[0].state == sims[1].state
    assert sims[0].collision_count == sims[1].collision_count


def test_substep_size_barely_matters():
    """1 ms and 5 ms substeps (slip, turns, strafe, braking) agree within 1 cm and 0.01 rad."""
    fine = MecanumPhysics(params(max_substep_s=0.001))
    coarse = MecanumPhysics(params(max_substep_s=0.005))
    drive_schedule(fine, 0.005)
    drive_schedule(coarse, 0.005)
    assert (coarse.state.x, coarse.state.y) == pytest.approx((fine.state.x, fine.state.y),
                                                             abs=0.01)
    assert wrap_angle(coarse.state.yaw - fine.state.yaw) == pytest.approx(0.0, abs=0.01)
    assert math.hypot(fine.state.x, fine.state.y) > 1.0


@pytest.mark.parametrize('mu', [0.6, 10.0])
def test_coasting_with_zero_duty_stops_without_reversing(mu):
    """
    Zero duty brakes: no-slip (mu = 10) the speed decays with tau_m; mu = 0.6 skids.

    The body speed never increases or turns negative and reaches rest.
    """
    sim = MecanumPhysics(params(friction_coefficient=mu))
    run(sim, (1.0, 1.0, 1.0, 1.0), 1.0)
    assert sim.state.vx > 1.0
    states = run(sim, (0.0, 0.0, 0.0, 0.0), 2.0)
    speeds = [s.vx for s in states]
    assert all(b <= a for a, b in zip(speeds, speeds[1:]))
    assert min(speeds) >= 0.0
    assert speeds[-1] < 1e-9
    assert min(min(s.wheel_speeds_rad_s) for s in states) >= 0.0


def test_rolling_resistance_shortens_the_coast():
    """
    Strong rolling resistance (C_rr = 0.5, 4.9 m/s^2) stops the robot sooner, never reversing.

    Without it only the brake acts: v = 0.69 exp(-t / 0.08) needs 0.52 s to fall
    below 1 mm/s; 4.9 m/s^2 more makes it well under 0.2 s.
    """
    def stop_time(rolling):
        sim = MecanumPhysics(params(friction_coefficient=10.0, drive_friction_fraction=0.0,
                                    rolling_resistance_coefficient=rolling))
        run(sim, (0.5, 0.5, 0.5, 0.5), 1.0)
        states = run(sim, (0.0, 0.0, 0.0, 0.0), 1.0)
        assert min(s.vx for s in states) >= 0.0 and states[-1].vx < 1e-5
        return next(i for i, s in enumerate(states) if s.vx < 1e-3) * 0.005

    assert stop_time(0.0) == pytest.approx(0.52, abs=0.01)
    assert stop_time(0.5) < 0.2


# ---------------------------------------------------------------- inputs


def test_duties_are_clamped_dead_banded_and_nan_rejected():
    """Duty 5 acts as 1; 0.02 (inside the 0.03 dead band) and NaN act as 0."""
    clamped, full = MecanumPhysics(params()), MecanumPhysics(params())
    run(clamped, (5.0, 5.0, 5.0, 5.0), 0.2)
    run(full, (1.0, 1.0, 1.0, 1.0), 0.2)
    assert clamped.state == full.state
    sim = MecanumPhysics(params())
    run(sim, (0.02, -0.03, math.nan, 0.0), 0.5)
    assert sim.state.x == 0.0 and sim.state.wheel_speeds_rad_s == (0.0,) * 4
    assert sim.rejected_duties == 100
    assert clamped.rejected_duties == 0


def test_teleport_resets_pose_and_velocities():
    """Teleport puts the robot at rest at the new pose (yaw wrapped)."""
    sim = MecanumPhysics(params())
    run(sim, (1.0, 0.5, 1.0, 0.5), 0.5)
    sim.teleport(1.0, 2.0, 4.0)
    s = sim.state
    assert (s.x, s.y, s.yaw) == (1.0, 2.0, wrap_angle(4.0))
    assert (s.vx, s.vy, s.wz, s.wheel_speeds_rad_s) == (0.0, 0.0, 0.0, (0.0,) * 4)
    assert sim.body_acceleration == sim.body_velocity_rate == (0.0, 0.0)


@pytest.mark.parametrize('call', [
    lambda sim: sim.step((1.0, 1.0, 1.0), 0.005),
    lambda sim: sim.step((1.0,) * 4, -0.001),
    lambda sim: sim.step((1.0,) * 4, math.nan),
    lambda sim: sim.step((1.0,) * 4, 0.005, np.zeros((2, 2))),
    lambda sim: sim.step((1.0,) * 4, 0.005, np.array([[0.0, 0.0, -1.0]])),
    lambda sim: sim.set_segments(np.zeros((3, 3))),
    lambda sim: sim.set_segments(np.array([[0.0, 0.0, math.inf, 1.0]])),
    lambda sim: sim.teleport(math.nan, 0.0, 0.0),
])
def test_invalid_inputs_raise(call):
    """Malformed duties, step sizes, obstacles and poses raise ValueError."""
    with pytest.raises(ValueError):
        call(MecanumPhysics(params()))


@pytest.mark.parametrize('person_stops_at', [1.2, 0.2])
def test_a_person_pressing_the_robot_against_a_wall_never_pushes_it_through(
        person_stops_at):
    """
    A 0.1 m thick wall from x = 0.8 to 0.9; the robot (radius 0.2) rests at x = 1.3.

    A person (radius 0.25) walks in from x = 4 towards the wall. The robot is pushed to
    the wall's face (centre at 0.9 + 0.2 = 1.1) and stays on its side even when the
    person's path goes on into the wall: walls win, the overlap counts as a collision.
    """
    wall = np.array([[0.8, -5.0, 0.8, 5.0], [0.9, -5.0, 0.9, 5.0],
                     [0.8, -5.0, 0.9, -5.0], [0.8, 5.0, 0.9, 5.0]])
    physics = MecanumPhysics(params(), wall, x=1.3, y=0.0)
    lowest = math.inf
    for step in range(800):
        person_x = max(person_stops_at, 4.0 - 0.8 * step * 0.005)
        physics.step([0.0] * 4, 0.005, np.array([[person_x, 0.0, 0.25]]))
        lowest = min(lowest, physics.state.x)
    assert lowest >= 1.1 - 1e-6
    assert physics.collision_count >= 1
