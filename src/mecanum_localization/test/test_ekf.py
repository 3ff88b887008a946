"""Hand-worked tests of mecanum_localization.ekf: model, update, gate, time handling."""

import math

from mecanum_control.angles import wrap_angle
from mecanum_localization.ekf import (
    _correct_kernel, _predict_kernel, _wrap, AX, AY, Measurement, PlanarEkf, predict_state,
    STATE_SIZE, transition_jacobian, VX, VY, VYAW, X, Y, YAW)
from mecanum_localization.ekf_config import parse_ekf_config
import numpy as np
import pytest

#: robot_localization's default process noise and initial covariance, planar.
DEFAULTS = parse_ekf_config({'two_d_mode': True})


def state(**values):
    """Return a state vector with the named entries set (x, y, yaw, vx, ...)."""
    vector = np.zeros(STATE_SIZE)
    names = {'x': X, 'y': Y, 'yaw': YAW, 'vx': VX, 'vy': VY, 'vyaw': VYAW, 'ax': AX, 'ay': AY}
    for name, value in values.items():
        vector[names[name]] = value
    return vector


def diagonal(**variances):
    """Return an 8x8 diagonal covariance: 1e-9 except the named variances."""
    return np.diag(state(**variances) + np.where(state(**variances) == 0, 1e-9, 0.0))


def started_filter(initial_covariance=None, process_noise=None, time_s=0.0, **kwargs):
    """Return a filter started (set_pose) at the origin at time_s."""
    ekf = PlanarEkf(np.zeros((8, 8)) if process_noise is None else process_noise,
                    np.eye(8) * 1e-9 if initial_covariance is None else initial_covariance,
                    **kwargs)
    ekf.set_pose(time_s, 0.0, 0.0, 0.0, np.eye(3) * 1e-9)
    return ekf


def assert_positive_definite(matrix):
    """Assert matrix is symmetric with all eigenvalues > 0."""
    assert np.array_equal(matrix, matrix.T)
    assert np.linalg.eigvalsh(matrix).min() > 0.0


# -- angles and the motion model ----------------------------------------------------------

def test_wrap_angle_is_in_minus_pi_inclusive_to_pi_exclusive():
    # mecanum_control.angles' convention, shared by every package: +pi is -pi.
    assert wrap_angle(math.pi) == -math.pi
    assert wrap_angle(-math.pi) == -math.pi
    assert wrap_angle(3 * math.pi) == -math.pi
    assert wrap_angle(1.5 * math.pi) == pytest.approx(-0.5 * math.pi)
    assert wrap_angle(-0.25) == -0.25


def test_compiled_wrap_agrees_with_wrap_angle():
    angles = [math.pi, -math.pi, 3 * math.pi, -3 * math.pi, 0.0, -0.25, 1.5 * math.pi,
              1e3, -1e3, math.nextafter(math.pi, 4.0), math.nextafter(-math.pi, -4.0)]
    angles += list(np.linspace(-20.0, 20.0, 401))
    for angle in angles:
        wrapped = _wrap(angle)
        assert -math.pi <= wrapped < math.pi
        assert wrapped == wrap_angle(angle)


def test_prediction_at_constant_velocity_heading_x():
    # vx 1 m/s, vy 0.5 m/s for 2 s facing +x: 2 m forward, 1 m left.
    predicted = predict_state(state(vx=1.0, vy=0.5), 2.0)
    assert predicted == pytest.approx(state(x=2.0, y=1.0, vx=1.0, vy=0.5))


def test_prediction_at_constant_velocity_heading_y():
    # Facing +y (yaw pi/2): body forward is world +y, body left is world -x.
    predicted = predict_state(state(yaw=math.pi / 2, vx=1.0, vy=0.5), 2.0)
    assert predicted == pytest.approx(state(x=-1.0, y=2.0, yaw=math.pi / 2, vx=1.0, vy=0.5))


def test_prediction_of_rotation_wraps_yaw():
    assert predict_state(state(vyaw=0.5), 2.0)[YAW] == pytest.approx(1.0)
    # 3 + 1 rad = 4 rad = 4 - 2 pi.
    assert predict_state(state(yaw=3.0, vyaw=1.0), 1.0)[YAW] == pytest.approx(4.0 - 2 * math.pi)


def test_prediction_with_constant_acceleration():
    # x = vx t + ax t^2 / 2 = 1 * 3 + 2 * 9 / 2 = 12; vx = 1 + 2 * 3 = 7.
    assert predict_state(state(vx=1.0, ax=2.0), 3.0) == pytest.approx(
        state(x=12.0, vx=7.0, ax=2.0))
    # y = ay t^2 / 2 = -1 * 4 / 2 = -2; vy = -2.
    assert predict_state(state(ay=-1.0), 2.0) == pytest.approx(state(y=-2.0, vy=-2.0, ay=-1.0))
    # Facing -x (yaw pi): a forward acceleration moves the robot towards -x.
    assert predict_state(state(yaw=math.pi, ax=2.0), 1.0)[[X, Y, VX]] == pytest.approx(
        [-1.0, 0.0, 2.0])


def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(1)
    for _ in range(20):
        x0 = rng.normal(size=STATE_SIZE)
        dt = rng.uniform(0.01, 0.5)
        numeric = np.zeros((STATE_SIZE, STATE_SIZE))
        for j in range(STATE_SIZE):
            step = np.zeros(STATE_SIZE)
            step[j] = 1e-6
            difference = predict_state(x0 + step, dt) - predict_state(x0 - step, dt)
            difference[YAW] = wrap_angle(difference[YAW])
            numeric[:, j] = difference / 2e-6
        assert transition_jacobian(x0, dt) == pytest.approx(numeric, abs=1e-7)


def test_predicted_covariance_by_hand():
    # Only vx uncertain (0.04 m^2/s^2), no process noise, 0.5 s at yaw 0:
    # var(x) = dt^2 var(vx) = 0.01, cov(x, vx) = dt var(vx) = 0.02.
    ekf = started_filter(initial_covariance=diagonal(vx=0.04))
    ekf.predict_to(0.5)
    assert ekf.covariance[X, X] == pytest.approx(0.01, abs=1e-8)
    assert ekf.covariance[X, VX] == pytest.approx(0.02, abs=1e-8)
    assert ekf.covariance[Y, Y] == pytest.approx(0.0, abs=1e-8)
    # Process noise is per second: Q dt is added.
    ekf = started_filter(process_noise=np.eye(8) * 0.1)
    ekf.predict_to(0.5)
    assert np.diag(ekf.covariance) == pytest.approx([0.05] * 8, abs=1e-8)


# -- update -----------------------------------------------------------------------------------

def test_first_measurement_initialises_what_it_measures():
    ekf = PlanarEkf(DEFAULTS.process_noise, DEFAULTS.initial_covariance)
    result = ekf.process(Measurement(5.0, [VX, VYAW], [0.3, -0.1], np.diag([0.01, 0.02])))
    assert result.status == 'initialized' and ekf.initialized and ekf.time_s == 5.0
    assert ekf.state == pytest.approx(state(vx=0.3, vyaw=-0.1))
    assert ekf.covariance[VX, VX] == 0.01 and ekf.covariance[VYAW, VYAW] == 0.02
    assert ekf.covariance[X, X] == 1e-9


def test_update_by_hand():
    # Prior vx = 0 with variance 1, measurement 2 with variance 1: gain 1/2,
    # posterior vx = 1 and variance 1/2.
    ekf = started_filter(initial_covariance=diagonal(vx=1.0))
    result = ekf.process(Measurement(0.0, [VX], [2.0], [[1.0]]))
    assert result.status == 'fused' and result.accepted
    assert ekf.state[VX] == pytest.approx(1.0)
    assert ekf.covariance[VX, VX] == pytest.approx(0.5)


def test_yaw_innovation_is_wrapped():
    # Estimate 3.0 rad, measurement -3.0 rad: the short way is +(2 pi - 6) rad, and with
    # equal variances the estimate moves half of it: 3 + (pi - 3) = pi, wrapped to -pi
    # (or a rounding error either side of the same heading).
    ekf = started_filter()
    ekf.set_pose(0.0, 0.0, 0.0, 3.0, np.diag([1e-9, 1e-9, 1.0]))
    ekf.process(Measurement(0.0, [YAW], [-3.0], [[1.0]]))
    assert abs(wrap_angle(ekf.state[YAW] - math.pi)) < 1e-12
    assert -math.pi <= ekf.state[YAW] < math.pi


def reference_update(state_vector, covariance, indices, values, noise, specific_force):
    """Return the textbook EKF update in numpy (the compiled kernel writes it out)."""
    size = len(indices)
    observation = np.zeros((size, STATE_SIZE))
    observation[range(size), indices] = 1.0
    predicted = state_vector[indices].copy()
    vx, vy, vyaw = state_vector[VX], state_vector[VY], state_vector[VYAW]
    for row, index in enumerate(indices):
        if specific_force and index == AX:
            predicted[row] -= vyaw * vy
            observation[row, VYAW], observation[row, VY] = -vy, -vyaw
        elif specific_force and index == AY:
            predicted[row] += vyaw * vx
            observation[row, VYAW], observation[row, VX] = vx, vyaw
    innovation = values - predicted
    for row, index in enumerate(indices):
        if index == YAW:
            innovation[row] = wrap_angle(innovation[row])
    innovation_covariance = observation @ covariance @ observation.T + noise
    distance = float(innovation @ np.linalg.solve(innovation_covariance, innovation))
    gain = covariance @ observation.T @ np.linalg.inv(innovation_covariance)
    updated = state_vector + gain @ innovation
    updated[YAW] = wrap_angle(updated[YAW])
    complement = np.eye(STATE_SIZE) - gain @ observation
    updated_covariance = complement @ covariance @ complement.T + gain @ noise @ gain.T
    return distance, updated, updated_covariance


def test_compiled_update_and_prediction_agree_with_numpy_algebra():
    rng = np.random.default_rng(7)
    for trial in range(200):
        state_vector = rng.normal(size=STATE_SIZE)
        state_vector[YAW] = rng.uniform(-math.pi, math.pi)
        root = rng.normal(size=(STATE_SIZE, STATE_SIZE))
        covariance = root @ root.T + 0.1 * np.eye(STATE_SIZE)
        size = int(rng.integers(1, STATE_SIZE + 1))
        indices = np.array(sorted(rng.choice(STATE_SIZE, size, replace=False)), dtype=np.int64)
        values = rng.normal(size=size)
        noise_root = rng.normal(size=(size, size))
        noise = noise_root @ noise_root.T + 0.01 * np.eye(size)
        specific_force = bool(trial % 2)
        status, distance, updated, updated_covariance = _correct_kernel(
            state_vector, covariance, indices, values, noise, specific_force, math.inf)
        expected = reference_update(state_vector, covariance, indices, values, noise,
                                    specific_force)
        assert status == 0
        assert distance == pytest.approx(expected[0], rel=1e-9)
        assert updated == pytest.approx(expected[1], rel=1e-9, abs=1e-9)
        assert updated_covariance == pytest.approx(expected[2], rel=1e-9, abs=1e-9)
        assert np.array_equal(updated_covariance, updated_covariance.T)

        dt = float(rng.uniform(0.0, 0.2))
        process_noise = np.diag(rng.uniform(0.0, 1.0, STATE_SIZE))
        predicted, predicted_covariance = _predict_kernel(state_vector, covariance,
                                                          process_noise, dt)
        jacobian = transition_jacobian(state_vector, dt)
        assert predicted == pytest.approx(predict_state(state_vector, dt))
        assert predicted_covariance == pytest.approx(
            jacobian @ covariance @ jacobian.T + process_noise * dt, rel=1e-9, abs=1e-12)


def test_mahalanobis_gate_rejects_outliers_and_passes_normal_measurements():
    # Prior vx variance 0.01 and measurement variance 0.01: S = 0.02, sigma = 0.1414.
    ekf = started_filter(initial_covariance=diagonal(vx=0.01))
    normal = ekf.process(Measurement(0.0, [VX], [0.05], [[0.01]], rejection_threshold=3.0))
    assert normal.status == 'fused'  # 0.05 / 0.1414 = 0.35 sigma
    before = ekf.state.copy()
    outlier = ekf.process(Measurement(0.1, [VX], [5.0], [[0.01]], rejection_threshold=3.0))
    assert outlier.status == 'gated' and 'Mahalanobis' in outlier.reason
    assert ekf.state[VX] == before[VX]
    # Without a threshold (default inf) the same outlier is fused.
    assert ekf.process(Measurement(0.2, [VX], [5.0], [[0.01]])).status == 'fused'


def test_non_finite_measurements_are_rejected_with_a_reason():
    ekf = started_filter(initial_covariance=diagonal(vx=1.0))
    before = (ekf.state.copy(), ekf.covariance.copy())
    nan_value = ekf.process(Measurement(0.1, [VX], [math.nan], [[1.0]]))
    inf_covariance = ekf.process(Measurement(0.1, [VX], [1.0], [[math.inf]]))
    nan_time = ekf.process(Measurement(math.nan, [VX], [1.0], [[1.0]]))
    assert (nan_value.status, inf_covariance.status, nan_time.status) == ('non_finite',) * 3
    assert 'value' in nan_value.reason and 'covariance' in inf_covariance.reason
    assert 'time' in nan_time.reason
    assert np.array_equal(ekf.state, before[0]) and np.array_equal(ekf.covariance, before[1])
    assert ekf.time_s == 0.0


def test_zero_and_negative_variances_are_raised_to_the_floor():
    for variance in (0.0, -1.0):
        ekf = started_filter(initial_covariance=diagonal(vx=1.0))
        assert ekf.process(Measurement(0.0, [VX], [2.0], [[variance]])).status == 'fused'
        # As if the variance were 1e-9: gain 1 / (1 + 1e-9), posterior variance ~1e-9.
        assert ekf.state[VX] == pytest.approx(2.0, abs=1e-8)
        assert ekf.covariance[VX, VX] == pytest.approx(1e-9, rel=1e-6)
        assert_positive_definite(ekf.covariance)


def test_inconsistent_measurement_covariance_is_rejected():
    ekf = started_filter()
    result = ekf.process(Measurement(0.0, [VX, VY], [0.0, 0.0], [[1e-9, 1.0], [1.0, 1e-9]]))
    assert result.status == 'singular'


def test_malformed_measurements_raise():
    with pytest.raises(ValueError, match='indices'):
        Measurement(0.0, [VX, VX], [1.0, 1.0], np.eye(2))
    with pytest.raises(ValueError, match='indices'):
        Measurement(0.0, [8], [1.0], [[1.0]])
    with pytest.raises(ValueError, match='2x2'):
        Measurement(0.0, [VX, VY], [1.0, 1.0], [[1.0]])
    with pytest.raises(ValueError, match='rejection_threshold'):
        Measurement(0.0, [VX], [1.0], [[1.0]], rejection_threshold=0.0)


# -- behaviour over time ----------------------------------------------------------------------

def test_constant_velocity_is_tracked_from_noisy_velocities():
    """
    10 s at vx 0.2, vy 0.1 m/s, measured (vx, vy, vyaw) at 50 Hz with sigma 0.03.

    Position is never measured: its error is the integral of the velocity error. The
    filter averages velocities with unit gain at steady state, so over T = 10 s with
    dt = 0.02 s the x error has about the variance of integrated raw noise,
    sigma^2 T dt, plus what the yaw error (integrated yaw-rate noise, variance
    sigma^2 dt t) does to the other axis's motion: v^2 sigma^2 dt T^3 / 3.
    """
    sigma, dt, duration, vx, vy = 0.03, 0.02, 10.0, 0.2, 0.1
    rng = np.random.default_rng(7)
    ekf = PlanarEkf(DEFAULTS.process_noise, DEFAULTS.initial_covariance)
    for k in range(int(round(duration / dt)) + 1):
        measured = np.array([vx, vy, 0.0]) + rng.normal(0.0, sigma, 3)
        result = ekf.process(Measurement(k * dt, [VX, VY, VYAW], measured,
                                         np.eye(3) * sigma ** 2))
        assert result.accepted
    integrated = sigma ** 2 * duration * dt
    heading = sigma ** 2 * dt * duration ** 3 / 3.0
    sigma_x = math.sqrt(integrated + vy ** 2 * heading)  # 0.0155 m
    sigma_y = math.sqrt(integrated + vx ** 2 * heading)  # 0.0205 m
    assert abs(ekf.state[X] - vx * duration) < 4 * sigma_x
    assert abs(ekf.state[Y] - vy * duration) < 4 * sigma_y
    # Velocities: within 4 standard deviations the filter claims (it is consistent:
    # the true motion has no acceleration, less than the model allows).
    for index, truth in ((VX, vx), (VY, vy), (VYAW, 0.0)):
        assert abs(ekf.state[index] - truth) < 4 * math.sqrt(ekf.covariance[index, index])
    assert abs(ekf.state[VX] - vx) < sigma and abs(ekf.state[VY] - vy) < sigma


def test_covariance_stays_symmetric_positive_definite_over_a_long_random_run():
    rng = np.random.default_rng(3)
    ekf = PlanarEkf(DEFAULTS.process_noise, DEFAULTS.initial_covariance)
    time_s = 0.0
    statuses = set()
    for _ in range(3000):
        time_s += rng.uniform(0.0, 0.05)
        size = rng.integers(1, STATE_SIZE + 1)
        indices = rng.choice(STATE_SIZE, size=size, replace=False)
        root = rng.normal(size=(size, size)) * rng.choice([1e-6, 1e-3, 0.1, 10.0])
        covariance = root @ root.T + np.eye(size) * rng.choice([0.0, 1e-9, 1e-4])
        values = rng.normal(size=size) * rng.choice([0.1, 1.0, 100.0])
        threshold = rng.choice([math.inf, 3.0, 10.0])
        statuses.add(ekf.process(Measurement(time_s, indices, values, covariance,
                                             threshold)).status)
        assert_positive_definite(ekf.covariance)
        assert np.all(np.isfinite(ekf.state)) and -math.pi <= ekf.state[YAW] < math.pi
    assert {'fused', 'gated'} <= statuses


def random_measurements(count, seed):
    """Measurements of two sensors (odometry twist at 50 Hz, IMU at 100 Hz), noisy."""
    rng = np.random.default_rng(seed)
    measurements = []
    for k in range(count):
        measurements.append(Measurement(
            0.02 * k, [VX, VY, VYAW], [0.2, 0.1, 0.3] + rng.normal(0.0, 0.03, 3),
            np.eye(3) * 1e-3, source='odom'))
        for half in (0.0, 0.01):
            measurements.append(Measurement(
                0.02 * k + half + 0.003, [VYAW, AX, AY],
                [0.3, 0.0, 0.0] + rng.normal(0.0, 0.05, 3), np.diag([2.5e-5, 2.5e-3, 2.5e-3]),
                rejection_threshold=5.0, source='imu'))
    return measurements


def test_out_of_order_measurements_give_the_in_order_estimate():
    measurements = random_measurements(100, seed=11)
    in_order = PlanarEkf(DEFAULTS.process_noise, DEFAULTS.initial_covariance)
    for measurement in sorted(measurements, key=lambda m: m.time_s):
        in_order.process(measurement)
    # Arrival order: each measurement delayed by up to 0.3 s (history is 1 s).
    rng = np.random.default_rng(12)
    arrival = [m.time_s + rng.uniform(0.0, 0.3) for m in measurements]
    lagged = PlanarEkf(DEFAULTS.process_noise, DEFAULTS.initial_covariance,
                       smooth_lagged_data=True, history_length_s=1.0)
    replayed = 0
    for _, measurement in sorted(zip(arrival, measurements), key=lambda pair: pair[0]):
        result = lagged.process(measurement)
        assert result.status in ('initialized', 'fused', 'gated'), result
        replayed += result.replayed
    assert replayed > 100  # there were many rewinds
    assert lagged.time_s == in_order.time_s
    assert lagged.state == pytest.approx(in_order.state, abs=1e-9)
    assert lagged.covariance == pytest.approx(in_order.covariance, abs=1e-9)


def test_equal_stamps_and_a_late_first_measurement():
    a = Measurement(1.0, [VX], [0.5], [[0.01]])
    b = Measurement(1.0, [VY], [0.2], [[0.01]])
    c = Measurement(0.5, [VYAW], [0.1], [[0.01]])
    in_order = PlanarEkf(DEFAULTS.process_noise, DEFAULTS.initial_covariance)
    for measurement in (c, a, b):
        in_order.process(measurement)
    lagged = PlanarEkf(DEFAULTS.process_noise, DEFAULTS.initial_covariance,
                       smooth_lagged_data=True, history_length_s=1.0)
    # c, older than a, becomes the first measurement: it initialises the replayed filter.
    assert [lagged.process(m).status for m in (a, b, c)] == ['initialized', 'fused',
                                                             'initialized']
    assert lagged.state == pytest.approx(in_order.state, abs=1e-12)
    assert lagged.covariance == pytest.approx(in_order.covariance, abs=1e-12)


def test_measurements_older_than_the_history_are_dropped():
    lagged = started_filter(smooth_lagged_data=True, history_length_s=0.5)
    lagged.process(Measurement(1.0, [VX], [0.1], [[0.01]]))
    before = lagged.state.copy()
    result = lagged.process(Measurement(0.4, [VX], [0.2], [[0.01]]))
    assert result.status == 'too_old' and 'history_length' in result.reason
    assert np.array_equal(lagged.state, before)
    assert lagged.process(Measurement(0.6, [VX], [0.2], [[0.01]])).status == 'fused'
    # Without smoothing a late measurement is dropped however small the lag.
    plain = started_filter(smooth_lagged_data=False, history_length_s=0.5)
    plain.process(Measurement(1.0, [VX], [0.1], [[0.01]]))
    assert plain.process(Measurement(0.99, [VX], [0.2], [[0.01]])).status == 'late'


def test_set_pose_and_reset():
    ekf = PlanarEkf(DEFAULTS.process_noise, DEFAULTS.initial_covariance,
                    smooth_lagged_data=True, history_length_s=1.0)
    ekf.process(Measurement(1.0, [VX, VY], [0.3, 0.1], np.eye(2) * 0.01))
    ekf.process(Measurement(2.0, [VX, VY], [0.3, 0.1], np.eye(2) * 0.01))
    pose_covariance = [[0.1, 0.01, 0.0], [0.01, 0.2, 0.0], [0.0, 0.0, 0.0]]
    ekf.set_pose(2.5, 1.0, -2.0, 4.0, pose_covariance)
    assert ekf.time_s == 2.5 and ekf.initialized
    assert ekf.state == pytest.approx(state(x=1.0, y=-2.0, yaw=4.0 - 2 * math.pi))
    expected = DEFAULTS.initial_covariance.copy()
    expected[:3, :3] = [[0.1, 0.01, 0.0], [0.01, 0.2, 0.0], [0.0, 0.0, 1e-9]]
    assert ekf.covariance == pytest.approx(expected)
    # Data from before the new pose cannot undo it.
    assert ekf.process(Measurement(2.2, [VX], [0.3], [[0.01]])).status == 'too_old'
    with pytest.raises(ValueError):
        ekf.set_pose(3.0, math.nan, 0.0, 0.0, np.eye(3))
    ekf.reset()
    assert not ekf.initialized and ekf.time_s is None
    assert np.array_equal(ekf.state, np.zeros(8))
    assert np.array_equal(ekf.covariance, DEFAULTS.initial_covariance)


def test_prediction_through_a_sensor_dropout_grows_covariance_without_diverging():
    ekf = PlanarEkf(DEFAULTS.process_noise, DEFAULTS.initial_covariance)
    for k in range(50):
        ekf.process(Measurement(0.02 * k, [VX, VY, VYAW], [0.2, 0.1, 0.0], np.eye(3) * 1e-3))
    x_before, variances = ekf.state[X], [ekf.covariance[X, X]]
    for k in range(1, 101):  # 3 s without data, predicted at 30 Hz
        ekf.predict_to(0.98 + k / 30.0)
        variances.append(ekf.covariance[X, X])
        assert np.all(np.isfinite(ekf.state)) and np.all(np.isfinite(ekf.covariance))
    assert np.all(np.diff(variances) > 0)
    # The velocity is kept: about 0.2 m/s * 3.33 s further.
    assert ekf.state[X] - x_before == pytest.approx(0.2 * 100 / 30.0, abs=0.01)
    assert ekf.process(Measurement(4.4, [VX], [0.2], [[1e-3]])).status == 'fused'


def test_accelerometer_on_a_turning_robot_measures_the_centripetal_term():
    """Strafing at 0.5 m/s while turning at 2 rad/s: the IMU reads ax = -wz vy = -1 m/s^2."""
    from mecanum_localization.ekf import AX, AY, Measurement, PlanarEkf, VX, VY, VYAW
    noise = np.diag([0.01, 0.01, 0.02, 0.05, 0.05, 0.1, 0.5, 0.5])
    for specific_force, expect_drift in ((True, False), (False, True)):
        ekf = PlanarEkf(noise, np.eye(8) * 1e-9, np.zeros(8), False, 1.0)
        ekf.process(Measurement(0.0, [VX, VY, VYAW], [0.0, 0.5, 2.0], np.eye(3) * 1e-6))
        for step in range(1, 101):  # 1 s of IMU at 100 Hz, no wheel odometry
            t = step * 0.01
            ekf.process(Measurement(t, [VYAW], [2.0], [[2.5e-5]]))
            ekf.process(Measurement(t, [AX, AY], [-1.0, 0.0], np.eye(2) * 0.0025,
                                    specific_force=specific_force))
        # The body-frame velocity is constant: (0, 0.5). Modelled right, it stays so;
        # taken as dv/dt (robot_localization's model) it drifts by about -1 m/s per s.
        drift = abs(ekf.state[VX])
        assert (drift > 0.3) == expect_drift, (specific_force, ekf.state[[VX, VY, AX, AY]])
        if not expect_drift:
            assert ekf.state[VY] == pytest.approx(0.5, abs=0.02)
            assert abs(ekf.state[AX]) < 0.05 and abs(ekf.state[AY]) < 0.05
