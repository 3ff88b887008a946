"""Hand-worked, closed-loop and property tests of mecanum_control.pid."""

import math
import random

from hypothesis import given, strategies as st
from mecanum_control.pid import _clamp, FAULT_STALLED, FAULT_WRONG_DIRECTION
from mecanum_control.pid import PidController, PidGains, StallConfig, StallDetector
import pytest

# Simulated wheel: d(omega)/dt = (K * effort - omega) / tau, no-load 20 rad/s at full duty.
PLANT_GAIN = 20.0      # rad/s per unit effort
PLANT_TAU_S = 0.1
NOMINAL_DT_S = 0.02    # 50 Hz

# PI with the zero on the plant pole (ki / kp = 1 / tau): closed-loop time constant
# tau / (K * kp) = 0.1 s. kf slightly off (true 1/K = 0.05) so the integrator must work.
TUNED = PidGains(kp=0.05, ki=0.5, kd=0.0, kf=0.045)


def plant_step(omega: float, effort: float, dt_s: float) -> float:
    """Advance the first-order wheel exactly over dt_s with the effort held."""
    steady = PLANT_GAIN * effort
    return steady + (omega - steady) * math.exp(-dt_s / PLANT_TAU_S)


def jittered_dts(seed: int):
    """Yield control periods uniformly in [0.015, 0.025] s, forever."""
    rng = random.Random(seed)
    while True:
        yield rng.uniform(0.015, 0.025)


def simulate(controller, target_at, duration_s, seed=0, omega=0.0, t0=0.0):
    """
    Run the closed loop and return [(t, omega, effort)] sampled after each step.

    controller is anything with update(target, measured, dt); target_at(t) gives the
    target in rad/s.
    """
    t = t0
    trace = []
    dts = jittered_dts(seed)
    while t < t0 + duration_s:
        dt = next(dts)
        effort = controller.update(target_at(t), omega, dt)
        omega = plant_step(omega, effort, dt)
        t += dt
        trace.append((t, omega, effort))
    return trace


class NaivePi:
    """PI + feedforward without anti-windup, for contrast with PidController."""

    def __init__(self, gains: PidGains) -> None:
        """Store gains; the integral is unbounded."""
        self.g = gains
        self.integral = 0.0

    def update(self, target: float, measured: float, dt: float) -> float:
        """Integrate always, clip only the output."""
        error = target - measured
        self.integral += self.g.ki * error * dt
        raw = self.g.kf * target + self.g.kp * error + self.integral
        return max(-self.g.max_effort, min(self.g.max_effort, raw))


# --- gains validation -------------------------------------------------------------

@pytest.mark.parametrize('field', ['kp', 'ki', 'kd', 'kf', 'static_effort',
                                   'derivative_filter_tau_s'])
@pytest.mark.parametrize('bad', [-0.1, float('nan'), float('inf')])
def test_gains_reject_bad_values(field, bad):
    """A negative or non-finite gain raises ValueError naming the field."""
    values = {'kp': 0.1, 'ki': 0.1, 'kd': 0.0}
    values[field] = bad
    with pytest.raises(ValueError, match=field):
        PidGains(**values)


@pytest.mark.parametrize('bad', [0.0, -0.5, 1.01, float('nan'), float('inf')])
def test_gains_reject_bad_max_effort(bad):
    """max_effort must lie in (0, 1]."""
    with pytest.raises(ValueError, match='max_effort'):
        PidGains(kp=0.1, ki=0.0, kd=0.0, max_effort=bad)


def test_gains_accept_edges():
    """Zero gains and max_effort = 1 are valid."""
    PidGains(kp=0.0, ki=0.0, kd=0.0, max_effort=1.0)


# --- hand-worked outputs ----------------------------------------------------------

def test_p_only_hand_worked():
    """With kp = 0.1, error 5 - 2 = 3 rad/s -> 0.3; error 12 -> clipped to max_effort 0.8."""
    pid = PidController(PidGains(kp=0.1, ki=0.0, kd=0.0, max_effort=0.8))
    assert pid.update(5.0, 2.0, 0.02) == pytest.approx(0.3)
    assert pid.update(-5.0, -2.0, 0.02) == pytest.approx(-0.3)
    assert pid.update(10.0, -2.0, 0.02) == 0.8
    assert pid.update(-10.0, 2.0, 0.02) == -0.8


def test_feedforward_and_static_effort_hand_worked():
    """Feedforward kf * target + sign(target) * static: 0.05 * 4 + 0.1 = 0.3 at zero error."""
    pid = PidController(PidGains(kp=0.2, ki=0.0, kd=0.0, kf=0.05, static_effort=0.1))
    assert pid.update(4.0, 4.0, 0.02) == pytest.approx(0.3)
    assert pid.update(-4.0, -4.0, 0.02) == pytest.approx(-0.3)
    # With an error of 1 rad/s the P term adds 0.2: 0.2 + 0.1 + 0.2.
    assert pid.update(4.0, 3.0, 0.02) == pytest.approx(0.5)
    # Static effort follows the sign of the TARGET, not of the error.
    assert pid.update(0.5, 1.0, 0.02) == pytest.approx(0.025 + 0.1 - 0.1)


# --- derivative on measurement ----------------------------------------------------

def test_target_step_gives_no_derivative_kick():
    """A step of the target with a steady measurement: output identical to kd = 0."""
    with_d = PidController(PidGains(kp=0.05, ki=0.0, kd=0.01))
    without_d = PidController(PidGains(kp=0.05, ki=0.0, kd=0.0))
    for pid in (with_d, without_d):
        pid.update(1.0, 2.0, 0.02)
    assert with_d.update(10.0, 2.0, 0.02) == without_d.update(10.0, 2.0, 0.02)
    assert with_d.derivative_effort == 0.0


def test_measurement_change_gives_derivative():
    """Measured 2 -> 3 rad/s in 0.02 s: D term = -kd * 50 rad/s^2 = -0.5 for kd = 0.01."""
    with_d = PidController(PidGains(kp=0.05, ki=0.0, kd=0.01))
    without_d = PidController(PidGains(kp=0.05, ki=0.0, kd=0.0))
    for pid in (with_d, without_d):
        pid.update(5.0, 2.0, 0.02)
    difference = with_d.update(5.0, 3.0, 0.02) - without_d.update(5.0, 3.0, 0.02)
    assert difference == pytest.approx(-0.5)


def test_derivative_filter_hand_worked():
    """Filter tau = 0.02 s, dt = 0.02 s: alpha = 1/2, the D term goes -0.25 then -0.375."""
    pid = PidController(PidGains(kp=0.0, ki=0.0, kd=0.01, derivative_filter_tau_s=0.02))
    pid.update(5.0, 2.0, 0.02)
    assert pid.update(5.0, 3.0, 0.02) == pytest.approx(-0.25)
    assert pid.update(5.0, 4.0, 0.02) == pytest.approx(-0.375)


# --- real dt ----------------------------------------------------------------------

def test_integral_uses_real_unequal_dts():
    """Integral after N steps = ki * error * sum(dt) with unequal dt."""
    pid = PidController(PidGains(kp=0.0, ki=0.5, kd=0.0))
    dts = [0.01, 0.03, 0.02, 0.05, 0.015]
    for dt in dts:
        effort = pid.update(3.0, 2.0, dt)
    assert pid.integral_effort == pytest.approx(0.5 * 1.0 * sum(dts))   # 0.0625
    assert effort == pytest.approx(0.0625)


@pytest.mark.parametrize('dt', [0.0, -0.01, float('nan'), float('inf')])
def test_bad_dt_neither_integrates_nor_differentiates(dt):
    """A dt <= 0 or non-finite: output is feedforward + P + held integral, no crash."""
    pid = PidController(PidGains(kp=0.1, ki=1.0, kd=0.5, kf=0.01))
    pid.update(5.0, 4.0, 0.1)                     # integral = 1.0 * 1.0 * 0.1 = 0.1
    effort = pid.update(5.0, 3.0, dt)             # measurement jumped, but no D
    assert effort == pytest.approx(0.01 * 5.0 + 0.1 * 2.0 + 0.1)
    assert pid.integral_effort == pytest.approx(0.1)


def test_first_step_with_zero_dt_is_safe():
    """The very first call may have dt = 0 (no previous time)."""
    pid = PidController(PidGains(kp=0.1, ki=1.0, kd=1.0))
    assert pid.update(2.0, 0.0, 0.0) == pytest.approx(0.2)


# --- stop, NaN --------------------------------------------------------------------

def test_zero_target_gives_exact_zero_and_resets_integrator():
    """A target of 0.0 gives effort exactly 0.0 and clears the integrator."""
    pid = PidController(PidGains(kp=0.1, ki=1.0, kd=0.1, kf=0.05, static_effort=0.1))
    for _ in range(10):
        pid.update(5.0, 4.0, 0.02)
    assert pid.integral_effort > 0.0
    assert pid.update(0.0, 0.3, 0.02) == 0.0
    assert pid.integral_effort == 0.0
    assert pid.update(0.0, -3.0, 0.02) == 0.0
    # Restarting: no stale derivative history (measurement 0.3 -> 5.0 is not a step).
    assert pid.update(1.0, 5.0, 0.02) == pytest.approx(0.05 + 0.1 + 0.1 * (1.0 - 5.0)
                                                       + 1.0 * (1.0 - 5.0) * 0.02)


@pytest.mark.parametrize('target, measured', [(float('nan'), 0.0), (1.0, float('nan')),
                                              (float('inf'), 0.0), (1.0, -float('inf'))])
def test_non_finite_inputs_raise(target, measured):
    """A NaN or inf target / measured is a ValueError."""
    with pytest.raises(ValueError):
        PidController(TUNED).update(target, measured, 0.02)


# --- anti-windup ------------------------------------------------------------------

def test_integral_contribution_is_bounded():
    """Feedforward opposite to the error keeps the output unsaturated; integral stays <= 1."""
    pid = PidController(PidGains(kp=0.0, ki=5.0, kd=0.0, kf=0.05, max_effort=1.0))
    for _ in range(200):
        effort = pid.update(-10.0, -30.0, 0.02)   # error +20, ff -0.5
    assert pid.integral_effort == pytest.approx(1.0)
    assert effort == pytest.approx(0.5)


@given(st.lists(st.tuples(st.floats(-40.0, 40.0), st.floats(-40.0, 40.0),
                          st.floats(0.0, 0.1)), min_size=1, max_size=50))
def test_output_and_integral_always_within_limits(steps):
    """Any sequence: |effort| <= max_effort and |integral| <= max_effort."""
    pid = PidController(PidGains(kp=0.3, ki=2.0, kd=0.01, kf=0.05, static_effort=0.05,
                                 max_effort=0.9, derivative_filter_tau_s=0.01))
    for target, measured, dt in steps:
        effort = pid.update(target, measured, dt)
        assert abs(effort) <= 0.9
        assert abs(pid.integral_effort) <= 0.9


# --- closed loop ------------------------------------------------------------------

@pytest.mark.parametrize('seed', range(4))
@pytest.mark.parametrize('target', [10.0, -6.0])
def test_closed_loop_settles_without_steady_state_error(seed, target):
    """First-order wheel with jittered dt: within 2 % before 1.5 s, exact at the end."""
    trace = simulate(PidController(TUNED), lambda t: target, 3.0, seed=seed)
    late = [(t, w) for t, w, _ in trace if t >= 1.5]
    assert all(abs(w - target) <= 0.02 * abs(target) for _, w in late)
    assert trace[-1][1] == pytest.approx(target, rel=1e-4)


def test_closed_loop_p_only_with_bad_feedforward_leaves_error():
    """Sanity of the plant: without the integrator the same loop keeps an offset."""
    gains = PidGains(kp=TUNED.kp, ki=0.0, kd=0.0, kf=TUNED.kf)
    trace = simulate(PidController(gains), lambda t: 10.0, 3.0)
    assert abs(trace[-1][1] - 10.0) > 0.1


WINDUP_HIGH = 30.0   # unreachable: K * max_effort = 20 rad/s
WINDUP_LOW = 10.0
WINDUP_SWITCH_S = 5.0


def windup_recovery(controller, seed=0):
    """
    Drive at an unreachable target for 5 s, then at 10 rad/s for 2 s.

    Return (trace after the switch with t relative to it, time until omega first
    drops to 1.1 x the new target).
    """
    def target_at(t):
        return WINDUP_HIGH if t < WINDUP_SWITCH_S else WINDUP_LOW
    trace = simulate(controller, target_at, WINDUP_SWITCH_S + 2.0, seed=seed)
    # Samples from the first step that saw the new target (its state is at the end).
    first = next(i for i, (t, _, _) in enumerate(trace) if t >= WINDUP_SWITCH_S)
    after = [(t - trace[first][0], w, u) for t, w, u in trace[first + 1:]]
    recovered = next((t for t, w, _ in after if w <= 1.1 * WINDUP_LOW), math.inf)
    return after, recovered


@pytest.mark.parametrize('kf', [0.05, 0.0])
@pytest.mark.parametrize('seed', range(3))
def test_anti_windup_recovers_quickly(kf, seed):
    """After 5 s saturated, a reachable target: off saturation fast, small overshoot."""
    gains = PidGains(kp=TUNED.kp, ki=TUNED.ki, kd=0.0, kf=kf)
    after, recovered = windup_recovery(PidController(gains), seed)
    assert after[0][2] < 1.0                          # off saturation on the next step
    assert recovered < 0.3
    assert all(w <= 1.1 * WINDUP_LOW for t, w, _ in after if t >= recovered)
    assert all(abs(w - WINDUP_LOW) <= 0.02 * WINDUP_LOW for t, w, _ in after if t >= 1.0)


@pytest.mark.parametrize('kf', [0.05, 0.0])
def test_naive_pi_winds_up_in_the_same_scenario(kf):
    """The same gains without clamping stay saturated for seconds: the test above means it."""
    gains = PidGains(kp=TUNED.kp, ki=TUNED.ki, kd=0.0, kf=kf)
    after, recovered = windup_recovery(NaivePi(gains))
    assert recovered > 1.5
    assert max(w for t, w, _ in after if t <= 1.0) > 1.5 * WINDUP_LOW


# --- stall detector ---------------------------------------------------------------

CONFIG = StallConfig(effort_threshold=0.6, velocity_threshold_rad_s=0.5, time_s=0.5)


@pytest.mark.parametrize('field, bad', [('effort_threshold', 0.0), ('effort_threshold', -1.0),
                                        ('velocity_threshold_rad_s', float('nan')),
                                        ('time_s', 0.0), ('time_s', -0.5),
                                        ('time_s', float('inf'))])
def test_stall_config_validation(field, bad):
    """Non-positive or non-finite fields raise ValueError naming the field."""
    with pytest.raises(ValueError, match=field):
        StallConfig(**{field: bad})


@pytest.mark.parametrize('dt, steps', [(0.1, 5), (0.02, 25), (0.125, 4)])
def test_stalls_after_time_s(dt, steps):
    """0.5 s of |effort| >= 0.6 at |omega| < 0.5: not stalled at step n-1, stalled at n."""
    detector = StallDetector(CONFIG)
    results = [detector.update(-0.6, 0.49, -3.0, dt) for _ in range(steps)]
    assert results == [False] * (steps - 1) + [True]
    assert detector.stalled


def test_no_stall_when_wheel_moves_or_effort_low():
    """High effort with motion, or low effort without motion at a low target, never stalls."""
    moving = StallDetector(CONFIG)
    weak = StallDetector(CONFIG)
    for _ in range(100):
        assert not moving.update(1.0, 0.5, 3.0, 0.02)
        assert not weak.update(0.59, 0.0, 2.9, 0.02)


def test_interruption_restarts_the_count():
    """4 stalled steps, 1 moving step, 4 stalled steps (dt 0.1, time 0.5): no stall."""
    detector = StallDetector(CONFIG)
    pattern = [0.0] * 4 + [2.0] + [0.0] * 4
    assert not any(detector.update(0.9, w, 3.0, 0.1) for w in pattern)
    assert detector.update(0.9, 0.0, 3.0, 0.1)      # 5th consecutive stalled step


def test_bad_dt_adds_no_time():
    """Steps with dt <= 0 do not count toward time_s."""
    detector = StallDetector(CONFIG)
    for _ in range(10):
        assert not detector.update(0.9, 0.0, 3.0, 0.0)
    assert detector.condition_time_s == 0.0


def test_latch_holds_until_reset():
    """Once stalled: stays so whatever the wheel and the target do, until reset."""
    detector = StallDetector(CONFIG)
    for _ in range(5):
        detector.update(0.9, 0.0, 3.0, 0.1)
    assert detector.stalled
    assert detector.update(0.0, 5.0, 3.0, 0.1)       # wheel spins freely: still latched
    assert detector.update(0.0, 0.0, -2.0, 0.1)      # another nonzero target: latched
    assert detector.update(0.0, 0.0, 0.0, 0.1)       # a zero target does not release it
    assert detector.stalled
    detector.reset()                                 # the operator's clear
    assert not detector.stalled
    assert detector.condition_time_s == 0.0
    results = [detector.update(0.9, 0.0, 3.0, 0.1) for _ in range(5)]
    assert results == [False] * 4 + [True]           # a full time_s again


def test_a_zero_target_restarts_the_count_before_the_latch():
    detector = StallDetector(CONFIG)
    for _ in range(4):
        assert not detector.update(0.9, 0.0, 3.0, 0.1)
    assert not detector.update(0.0, 0.0, 0.0, 0.1)
    assert detector.condition_time_s == 0.0
    assert [detector.update(0.9, 0.0, 3.0, 0.1) for _ in range(5)] == [False] * 4 + [True]


def test_stall_reset_and_nan():
    """reset() clears the latch; NaN inputs raise ValueError."""
    detector = StallDetector(CONFIG)
    for _ in range(5):
        detector.update(0.9, 0.0, 3.0, 0.1)
    detector.reset()
    assert not detector.stalled
    with pytest.raises(ValueError):
        detector.update(float('nan'), 0.0, 3.0, 0.1)


def test_stall_detected_in_closed_loop_with_blocked_wheel():
    """PID saturates against a blocked wheel (omega = 0): stall after 0.5 s at 50 Hz."""
    pid = PidController(TUNED)
    detector = StallDetector(StallConfig())
    stalled_at = None
    for step in range(1, 51):
        effort = pid.update(10.0, 0.0, NOMINAL_DT_S)
        if detector.update(effort, 0.0, 10.0, NOMINAL_DT_S) and stalled_at is None:
            stalled_at = step
    # Effort 0.45 + 0.5 + integral >= 0.95 >= 0.6 from the first step: 25 steps.
    assert stalled_at == 25


def test_stall_reports_fault_stalled():
    """A still wheel under high effort latches with fault 'stalled'; no fault before."""
    detector = StallDetector(CONFIG)
    for _ in range(4):
        detector.update(0.9, 0.2, 3.0, 0.1)
        assert detector.fault is None
    assert detector.update(0.9, -0.2, 3.0, 0.1)
    assert detector.fault == FAULT_STALLED == 'stalled'


# --- wrong direction (reversed encoder or motor) ----------------------------------

@pytest.mark.parametrize('effort, measured, target', [(0.9, -0.5, 3.0), (-0.6, 12.0, -3.0),
                                                      (1.0, -30.0, 0.5)])
def test_wheel_against_its_effort_latches_wrong_direction(effort, measured, target):
    """|effort| >= 0.6 with the wheel at >= 0.5 rad/s the other way for 0.5 s latches."""
    detector = StallDetector(CONFIG)
    results = [detector.update(effort, measured, target, 0.1) for _ in range(5)]
    assert results == [False] * 4 + [True]
    assert detector.stalled
    assert detector.fault == FAULT_WRONG_DIRECTION == 'wrong direction'
    assert detector.update(0.0, 0.0, target, 0.1)                # latched
    assert detector.update(0.0, measured, 0.0, 0.1)              # a stop does not clear
    detector.reset()                                             # the operator's clear
    assert detector.fault is None


def test_wrong_direction_needs_high_effort_and_the_time():
    """Gentle braking (|effort| < 0.6) against the motion, or a short episode, never latches."""
    gentle = StallDetector(CONFIG)
    interrupted = StallDetector(CONFIG)
    for step in range(100):
        assert not gentle.update(-0.59, 20.0, 3.0, 0.02)
        # 24 steps (0.48 s) against the effort, then one step following it.
        assert not interrupted.update(0.9, 2.0 if step % 25 == 24 else -5.0, 3.0, 0.02)


def test_still_then_reversed_counts_as_one_condition():
    """A wheel that is first still, then runs backwards, latches after time_s in total."""
    detector = StallDetector(CONFIG)
    speeds = [0.0, -0.3, -4.0, -9.0, -12.0]
    assert [detector.update(0.95, w, 3.0, 0.1) for w in speeds] == [False] * 4 + [True]
    assert detector.fault == FAULT_WRONG_DIRECTION   # 0.3 s of 0.5 s against the effort


def test_fault_is_the_one_that_held_longest():
    """3 of 5 steps still -> 'stalled'; the order does not matter."""
    detector = StallDetector(CONFIG)
    speeds = [-2.0, 0.0, 0.1, -2.0, 0.0]
    assert [detector.update(0.95, w, 3.0, 0.1) for w in speeds] == [False] * 4 + [True]
    assert detector.fault == FAULT_STALLED


# Wheel of board_model.MotorModel as configured in motor_params.yaml, with the node's gains.
MOTOR_NO_LOAD_RAD_S = 34.5
MOTOR_TAU_S = 0.08
MOTOR_DEAD_BAND = 0.03
MAX_WHEEL_SPEED_RAD_S = 28.0
NODE_GAINS = PidGains(kp=0.03, ki=0.3, kd=0.0, kf=1.0 / MOTOR_NO_LOAD_RAD_S,
                      static_effort=0.03, derivative_filter_tau_s=0.02)
MAX_DT_S = 0.025     # longest step of jittered_dts


def motor_step(omega: float, effort: float, dt_s: float) -> float:
    """Advance the board-model wheel exactly over dt_s (dead band, first order)."""
    drive = 0.0 if abs(effort) <= MOTOR_DEAD_BAND else effort
    steady = drive * MOTOR_NO_LOAD_RAD_S
    return steady + (omega - steady) * math.exp(-dt_s / MOTOR_TAU_S)


def run_wheel(target_at, duration_s, seed=0, encoder_sign=1.0, motor_sign=1.0, push=None):
    """
    Run PID + stall detector on the board-model wheel as velocity_controller does.

    The measurement is encoder_sign * omega, the wheel gets motor_sign * effort, and
    while push(t) is not None the wheel is held at that speed (an external force).
    A latched detector zeroes the effort. Return (detector, trace) with trace entries
    (t after the step, true omega, effort, latched, condition_time_s).
    """
    pid = PidController(NODE_GAINS)
    detector = StallDetector(StallConfig())
    dts = jittered_dts(seed)
    t, omega, trace = 0.0, 0.0, []
    while t < duration_s:
        dt = next(dts)
        target, measured = target_at(t), encoder_sign * omega
        effort = pid.update(target, measured, dt)
        latched = detector.update(effort, measured, target, dt)
        if latched:
            pid.reset()
            effort = 0.0
        omega = motor_step(omega, motor_sign * effort, dt)
        t += dt
        held = None if push is None else push(t)
        if held is not None:
            omega = held
        trace.append((t, omega, effort, latched, detector.condition_time_s))
    return detector, trace


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('target', [10.0, -10.0, 2.0])
@pytest.mark.parametrize('encoder_sign, motor_sign', [(-1.0, 1.0), (1.0, -1.0)])
def test_reversed_encoder_or_motor_latches_wrong_direction(seed, target, encoder_sign,
                                                           motor_sign):
    """
    Positive feedback (A/B swapped, or motor leads swapped) is stopped after time_s.

    The PID goes to full duty while the wheel races away the wrong way; the detector
    latches within time_s + one step of the effort first reaching the threshold (the
    first step for 10 rad/s; a few steps later for 2 rad/s) and names the fault.
    """
    detector, trace = run_wheel(lambda t: target, 2.0, seed, encoder_sign, motor_sign)
    first = next(i for i, (_, _, u, _, _) in enumerate(trace) if abs(u) >= 0.6)
    start = 0.0 if first == 0 else trace[first - 1][0]
    assert target != 10.0 or start == 0.0
    latched_at = next(t for t, _, _, latched, _ in trace if latched) - start
    assert CONFIG.time_s - 1e-9 <= latched_at <= CONFIG.time_s + MAX_DT_S
    assert detector.fault == FAULT_WRONG_DIRECTION
    before = [(w, u) for t, w, u, latched, _ in trace if not latched]
    # It really was a runaway: full duty, the wheel far beyond the target speed.
    assert abs(before[-1][1]) == pytest.approx(1.0)
    assert abs(before[-1][0]) > 0.8 * MOTOR_NO_LOAD_RAD_S
    # From then on no effort (the wheel coasts to a stop), until the target is 0.
    assert all(u == 0.0 for _, _, u, latched, _ in trace if latched)


def demanding_profile(t: float) -> float:
    """Full-speed reversals, hard decelerations and small targets (rad/s)."""
    for end_s, target in ((1.0, 20.0), (2.0, -20.0), (3.0, MAX_WHEEL_SPEED_RAD_S),
                          (3.5, 2.0), (4.5, -MAX_WHEEL_SPEED_RAD_S), (5.5, MAX_WHEEL_SPEED_RAD_S),
                          (6.0, -1.0), (6.5, 0.6)):
        if t < end_s:
            return target
    return 10.0


@pytest.mark.parametrize('seed', range(4))
def test_normal_operation_with_reversals_never_trips(seed):
    """
    Correct wiring: +20 -> -20, +-28 rad/s reversals and decelerations do not latch.

    Braking against the motion at full duty does meet the condition, but only until
    the wheel crosses zero, far shorter than time_s.
    """
    detector, trace = run_wheel(demanding_profile, 8.0, seed)
    assert not any(latched for _, _, _, latched, _ in trace)
    assert detector.fault is None
    worst = max(c for *_, c in trace)
    assert 0.0 < worst < 0.3 * CONFIG.time_s
    # And the wheel did follow: -20 reached before the next change, 10 at the end.
    assert [w for t, w, *_ in trace if t < 2.0][-1] == pytest.approx(-20.0, rel=0.02)
    assert trace[-1][1] == pytest.approx(10.0, rel=0.02)


def test_normal_reversal_never_trips_on_the_slow_test_plant():
    """The slower test plant (20 rad/s, 0.1 s) with TUNED gains: +20 -> -20 is fine too."""
    detector = StallDetector(StallConfig())
    pid = PidController(TUNED)
    omega, t, worst = 0.0, 0.0, 0.0
    dts = jittered_dts(7)
    while t < 4.0:
        dt = next(dts)
        target = 20.0 if t < 2.0 else -20.0
        effort = pid.update(target, omega, dt)
        assert not detector.update(effort, omega, target, dt)
        worst = max(worst, detector.condition_time_s)
        omega = plant_step(omega, effort, dt)
        t += dt
    assert 0.0 < worst < 0.5 * CONFIG.time_s


PUSH_SPEED_RAD_S = -8.0


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('push_s, trips', [(0.3, False), (0.7, True)])
def test_external_push_trips_only_if_longer_than_time_s(seed, push_s, trips):
    """
    Wheel held at -8 rad/s against a +10 rad/s target: 0.3 s is tolerated, 0.7 s is not.

    The PID saturates forward during the push, so the condition holds all along.
    """
    def push(t):
        return PUSH_SPEED_RAD_S if 1.0 <= t < 1.0 + push_s else None

    detector, trace = run_wheel(lambda t: 10.0, 3.0, seed, push=push)
    assert any(latched for *_, latched, _ in trace) == trips
    if trips:
        assert detector.fault == FAULT_WRONG_DIRECTION
    else:
        assert max(c for *_, c in trace) >= push_s - MAX_DT_S
        assert trace[-1][1] == pytest.approx(10.0, rel=0.02)


# --- absurd but finite measurements (NaN must never become full duty) -------------

def test_clamp_maps_nan_to_zero():
    """_clamp: NaN -> 0.0, +-inf -> +-limit, in-range values unchanged."""
    assert _clamp(float('nan'), 0.8) == 0.0
    assert _clamp(float('inf'), 0.8) == 0.8
    assert _clamp(-float('inf'), 0.8) == -0.8
    assert _clamp(0.3, 0.8) == 0.3


def test_nan_output_becomes_zero_not_full_duty():
    """An inf - inf output (kf * target = inf, kp * error = -inf) is NaN: effort 0.0."""
    pid = PidController(PidGains(kp=10.0, ki=0.0, kd=0.0, kf=10.0))
    assert pid.update(1e308, 1.7e308, 0.02) == 0.0


GLITCH_GAINS = [TUNED, PidGains(kp=0.05, ki=0.5, kd=0.01, kf=0.045, static_effort=0.02,
                                derivative_filter_tau_s=0.02)]
HUGE = 1.7e308


@pytest.mark.parametrize('gains', GLITCH_GAINS)
def test_huge_measurement_jumps_keep_the_state_finite(gains):
    """
    Measured 1.7e308 -> -1.7e308 overflows the rate to inf; 0 * inf must not poison.

    Efforts stay finite within the limit, the state finite, and once target and
    measured agree again the effort is the plain feedforward, not +max_effort.
    """
    pid = PidController(gains)
    steps = [(5.0, 5.0), (5.0, HUGE), (5.0, -HUGE), (5.0, HUGE), (5.0, -HUGE)]
    for target, measured in steps:
        effort = pid.update(target, measured, 0.02)
        assert math.isfinite(effort) and abs(effort) <= gains.max_effort
        assert math.isfinite(pid.integral_effort) and math.isfinite(pid.derivative_effort)
    expected = gains.kf * 5.0 + gains.static_effort
    for _ in range(3):
        assert pid.update(5.0, 5.0, 0.02) == pytest.approx(expected)


@pytest.mark.parametrize('gains', GLITCH_GAINS)
def test_huge_target_equal_to_measured_never_gives_full_forward(gains):
    """Target == measured == -1.7e308 right after +1.7e308: full reverse, never +max."""
    pid = PidController(gains)
    assert pid.update(HUGE, HUGE, 0.02) == gains.max_effort        # feedforward of 1.7e308
    for _ in range(3):
        assert pid.update(-HUGE, -HUGE, 0.02) == -gains.max_effort
        assert pid.update(HUGE, HUGE, 0.02) == gains.max_effort
    assert pid.update(-5.0, -5.0, 0.02) == pytest.approx(-5.0 * gains.kf - gains.static_effort)


def test_one_glitch_does_not_hold_the_output_saturated():
    """A single 1e300 rad/s sample with kd > 0: the D term is capped and decays in steps."""
    gains = GLITCH_GAINS[1]
    pid = PidController(gains)
    pid.update(5.0, 5.0, 0.02)
    pid.update(5.0, 1e300, 0.02)
    assert abs(pid.derivative_effort) <= 2.0 * gains.max_effort
    efforts = [pid.update(5.0, 5.0, 0.02) for _ in range(15)]
    assert efforts[-1] == pytest.approx(gains.kf * 5.0 + gains.static_effort, abs=1e-3)


FINITE = st.floats(allow_nan=False, allow_infinity=False)


@given(st.lists(st.tuples(FINITE, FINITE, st.floats(0.0, 0.1)), min_size=1, max_size=30))
def test_any_finite_inputs_give_finite_bounded_output(steps):
    """Any finite target, measured and dt: output finite within limits, state finite."""
    pid = PidController(GLITCH_GAINS[1])
    for target, measured, dt in steps:
        effort = pid.update(target, measured, dt)
        assert math.isfinite(effort) and abs(effort) <= 1.0
        assert math.isfinite(pid.integral_effort) and math.isfinite(pid.derivative_effort)


def test_integrator_holds_while_the_target_ramps():
    """
    Target rising 1 rad/s per 0.02 s step (50 rad/s^2 > 10): nothing is integrated.

    Once the target holds, the integral grows by ki * error * dt = 1.0 * 10 * 0.02 = 0.2.
    """
    pid = PidController(PidGains(kp=0.0, ki=1.0, kd=0.0, integral_freeze_rate_rad_s2=10.0))
    for k in range(1, 11):
        pid.update(float(k), 0.0, 0.02)
    assert pid.integral_effort == 0.0
    pid.update(10.0, 0.0, 0.02)
    assert pid.integral_effort == pytest.approx(0.2)


def test_integrator_freeze_removes_the_overshoot_of_a_delayed_measurement():
    """
    Holding the integrator during a ramp removes most of a delayed loop's overshoot.

    A first-order wheel (K 34.5 rad/s, tau 0.08 s) ramps to 5 rad/s at 37.5 rad/s^2 with
    the measurement 80 ms late (encoder window + transport), as on the robot.

    Integrating the delay-induced error during the ramp overshoots by about 67 %;
    holding the integrator leaves the proportional part's overshoot (about 25 %).
    """
    def peak(freeze_rate):
        gains = PidGains(kp=0.03, ki=0.3, kd=0.0, kf=1 / 34.5,
                         integral_freeze_rate_rad_s2=freeze_rate)
        pid, omega, history, dt = PidController(gains), 0.0, [0.0] * 4, 0.02
        highest = 0.0
        for step in range(150):
            target = min(5.0, 37.5 * dt * (step + 1))
            effort = pid.update(target, history[0], dt)
            omega = 34.5 * effort + (omega - 34.5 * effort) * math.exp(-dt / 0.08)
            history = history[1:] + [omega]
            highest = max(highest, omega)
        assert omega == pytest.approx(5.0, rel=0.01)  # settles either way
        return highest
    with_freeze, without = peak(10.0), peak(math.inf)
    assert with_freeze < 5.0 * 1.3
    assert without > with_freeze + 1.5


def test_a_wheel_asked_to_turn_that_does_not_latches_at_any_effort():
    """|target| >= 3 rad/s with |speed| < 0.5 rad/s for 0.5 s: stalled, even at duty 0.3."""
    detector = StallDetector(CONFIG)
    assert [detector.update(0.3, 0.0, -5.0, 0.1) for _ in range(5)] == [False] * 4 + [True]
    assert detector.fault == FAULT_STALLED
    for target, measured in ((2.9, 0.0), (5.0, 0.6), (5.0, -0.6)):
        gentle = StallDetector(CONFIG)
        # Below the target threshold, or turning (either way): never.
        assert not any(gentle.update(0.3, measured, target, 0.1) for _ in range(20))
