"""
Hand-worked tests of the physics' fault inputs: per-wheel traction factors, move_to.

Numbers from config/motor_params.yaml as in test_physics: r = 0.04 m, k = 0.215 m,
m = 4 kg, Iz = 0.051 kg m^2, omega_0 = 34.5 rad/s, tau_stall = 0.733125 N m,
J_wheel = 1e-4 kg m^2, drive friction 0.5 % of the stall torque.
"""

import math

from mecanum_control.robot_config import default_config_path, load_robot_config
import pytest
from robot_simulation.physics import MecanumPhysics, PhysicsParams

CONFIG = load_robot_config(default_config_path())
G = 9.80665
OMEGA0 = 34.5
K_ARM = 0.215
MASS = 4.0
IZ = 0.051


def params(**overrides):
    """Return PhysicsParams from motor_params.yaml with some fields overridden."""
    return PhysicsParams.from_robot_config(CONFIG, **overrides)


def run(sim, duties, seconds, dt=0.005):
    """Step with constant duties; return the states after each step."""
    states = []
    for _ in range(int(round(seconds / dt))):
        sim.step(duties, dt)
        states.append(sim.state)
    return states


def test_a_wheel_without_grip_spins_free_and_moves_nothing():
    """
    FL with traction 0, driven alone at full duty: it transmits no force.

    The body stays exactly at rest (the other wheels have nothing to do), and FL spins
    up like a free motor, with the wheel's own lag J_wheel omega_0 / tau_stall = 4.7 ms,
    to where the drive balances the drive friction (0.5 % of the stall torque). The
    step's exponential fitting scales the drive and damping (not the friction) by
    s = expm1(x) / x, x = h (tau_stall / omega_0) / J_eq = 0.005 * 0.02125 / 0.0017 =
    0.0625, s = 1.0319112: omega = omega_0 (1 - 0.005 / s) = 34.332834 rad/s.
    """
    sim = MecanumPhysics(params())
    sim.set_traction_factors((0.0, 1.0, 1.0, 1.0))
    run(sim, (1.0, 0.0, 0.0, 0.0), 0.2)
    s = sim.state
    assert (s.x, s.y, s.yaw, s.vx, s.vy, s.wz) == (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    scale = math.expm1(0.0625) / 0.0625
    assert s.wheel_speeds_rad_s[0] == pytest.approx(OMEGA0 * (1.0 - 0.005 / scale), rel=1e-6)
    assert s.wheel_speeds_rad_s[1:] == (0.0, 0.0, 0.0)
    # With grip the same duty moves the robot.
    gripping = MecanumPhysics(params())
    run(gripping, (1.0, 0.0, 0.0, 0.0), 0.2)
    assert gripping.state.x > 0.01


def test_halved_traction_halves_a_saturated_start():
    """Low friction mu = 0.05, all factors 0.5, full duty: a = 0.5 mu g = 0.24517 m/s^2."""
    sim = MecanumPhysics(params(friction_coefficient=0.05, rolling_resistance_coefficient=0.0))
    sim.set_traction_factors((0.5, 0.5, 0.5, 0.5))
    states = run(sim, (1.0, 1.0, 1.0, 1.0), 0.5)
    assert (states[99].vx - states[19].vx) / 0.4 == pytest.approx(0.5 * 0.05 * G, rel=1e-3)
    assert sim.traction_factors == (0.5, 0.5, 0.5, 0.5)


def test_one_slipping_wheel_pulls_the_robot_left_and_turns_it_left():
    """
    Floor mu = 0.05, FL at 0.2 of its grip, full duty forward: every wheel slips.

    Each wheel pushes its limit L_i = f_i mu m g / 4 along its row a_i; FL has 0.2 L:
    force x (L) (0.2 + 1 + 1 + 1) = 3.2 L, force y (L) (-0.2 + 1 + 1 - 1) = 0.8 L, torque
    k L (-0.2 + 1 - 1 + 1) = 0.8 k L, with L = 0.05 * 4 * 9.80665 / 4 = 0.0490333 N. The
    accelerometer reads the force over the mass: (3.2 L / m, 0.8 L / m) =
    (0.0392266, 0.0098067) m/s^2, and wz grows at 0.8 k L / Iz = 0.165368 rad/s^2.
    """
    sim = MecanumPhysics(params(friction_coefficient=0.05, rolling_resistance_coefficient=0.0))
    sim.set_traction_factors((0.2, 1.0, 1.0, 1.0))
    states = run(sim, (1.0, 1.0, 1.0, 1.0), 0.3)
    limit = 0.05 * MASS * G / 4.0
    assert sim.body_acceleration == pytest.approx((3.2 * limit / MASS, 0.8 * limit / MASS),
                                                  rel=1e-6)
    assert (states[59].wz - states[19].wz) / 0.2 == pytest.approx(
        0.8 * K_ARM * limit / IZ, rel=1e-6)
    assert sim.state.yaw > 0.0 and sim.state.vy > 0.0


def test_factors_of_one_are_no_factors_at_all():
    """All ones is the floor itself: the same trajectory to the bit, with contacts too."""
    plain, ones = MecanumPhysics(params(friction_coefficient=0.1)), MecanumPhysics(
        params(friction_coefficient=0.1))
    ones.set_traction_factors((1.0, 1.0, 1.0, 1.0))
    assert ones.traction_factors == (1.0, 1.0, 1.0, 1.0)
    for duties in ((1.0, 0.4, 1.0, 0.4), (-1.0, 1.0, 1.0, -1.0)):
        assert run(plain, duties, 0.5) == run(ones, duties, 0.5)
    # Clearing the factors restores the floor's grip.
    sim = MecanumPhysics(params(friction_coefficient=0.05, rolling_resistance_coefficient=0.0))
    sim.set_traction_factors((0.5, 0.5, 0.5, 0.5))
    sim.set_traction_factors(None)
    states = run(sim, (1.0, 1.0, 1.0, 1.0), 0.5)
    assert (states[99].vx - states[19].vx) / 0.4 == pytest.approx(0.05 * G, rel=1e-3)


@pytest.mark.parametrize('factors', [(1.0, 1.0, 1.0), (1.0, 1.0, 1.0, -0.1),
                                     (1.0, 1.0, math.nan, 1.0), (1.0, True, 1.0, 1.0)])
def test_bad_traction_factors_raise(factors):
    with pytest.raises(ValueError, match='traction factors'):
        MecanumPhysics(params()).set_traction_factors(factors)


def test_move_to_keeps_the_motion():
    """A kidnap moves the pose; body twist, wheel speeds and angles go on."""
    sim = MecanumPhysics(params())
    run(sim, (1.0, 0.5, 1.0, 0.5), 0.5)
    before = sim.state
    sim.move_to(3.0, -1.0, 4.0)
    after = sim.state
    assert (after.x, after.y, after.yaw) == (3.0, -1.0, 4.0 - 2.0 * math.pi)
    assert (after.vx, after.vy, after.wz) == (before.vx, before.vy, before.wz)
    assert after.wheel_speeds_rad_s == before.wheel_speeds_rad_s
    assert after.wheel_angles_rad == before.wheel_angles_rad
    with pytest.raises(ValueError):
        sim.move_to(math.inf, 0.0, 0.0)
