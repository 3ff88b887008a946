"""Tests of mecanum_control.imu_calibration: IMU biases measured while the robot rests."""

import math

from mecanum_control.imu_calibration import ImuRestCalibrator
import pytest

GYRO_BIAS = (0.001, -0.002, 0.003)
ACCEL_BIAS = (0.02, -0.01)
GRAVITY = 9.81


def feed(calibrator, start_s, duration_s, ticks=(0, 0, 0, 0), driven=False, gyro_z=0.0,
         moving=False, rate_hz=100.0):
    """Feed encoder reports and IMU samples at rate_hz; return the last corrected sample."""
    result = None
    steps = int(round(duration_s * rate_hz))
    for i in range(steps):
        now = start_s + i / rate_hz
        current = tuple(t + i + 1 for t in ticks) if moving else ticks
        calibrator.on_ticks(current, driven, now)
        accel = (ACCEL_BIAS[0], ACCEL_BIAS[1], GRAVITY)
        gyro = (GYRO_BIAS[0], GYRO_BIAS[1], GYRO_BIAS[2] + gyro_z)
        result = calibrator.on_sample(accel, gyro, now)
    return result


def test_biases_are_measured_after_the_rest_time_and_removed():
    calibrator = ImuRestCalibrator(rest_time_s=1.0, min_samples=50)
    # Samples at t = 0.00 .. 1.48 s: the rest counts from t = 1.00, so 49 < 50 samples.
    feed(calibrator, 0.0, 1.49)
    assert not calibrator.calibrated
    assert calibrator.gyro_bias == (0.0, 0.0, 0.0)
    accel, gyro = feed(calibrator, 1.49, 0.5)
    assert calibrator.calibrated
    assert calibrator.gyro_bias == pytest.approx(GYRO_BIAS, abs=1e-12)
    assert calibrator.accel_bias == pytest.approx((*ACCEL_BIAS, 0.0), abs=1e-12)
    assert gyro == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    # Level floor: x and y read zero at rest; z keeps gravity.
    assert accel == pytest.approx((0.0, 0.0, GRAVITY), abs=1e-12)


def test_no_calibration_while_the_wheels_turn():
    calibrator = ImuRestCalibrator(rest_time_s=1.0, min_samples=10)
    feed(calibrator, 0.0, 5.0, moving=True, gyro_z=0.5)
    assert not calibrator.calibrated
    assert calibrator.rest_samples() == 0


def test_no_calibration_while_a_motor_is_driven_even_if_stalled():
    calibrator = ImuRestCalibrator(rest_time_s=1.0, min_samples=10)
    feed(calibrator, 0.0, 5.0, driven=True)
    assert not calibrator.calibrated


def test_a_silent_encoder_is_no_proof_of_rest():
    calibrator = ImuRestCalibrator(rest_time_s=1.0, min_samples=10, encoder_timeout_s=0.25)
    calibrator.on_ticks((0, 0, 0, 0), False, 0.0)
    for i in range(300):  # IMU samples for 3 s, no encoder report after t = 0
        calibrator.on_sample((0.0, 0.0, GRAVITY), GYRO_BIAS, i / 100.0)
    assert not calibrator.calibrated


def test_motion_during_settling_restarts_the_rest():
    calibrator = ImuRestCalibrator(rest_time_s=1.0, min_samples=10)
    feed(calibrator, 0.0, 0.8)
    feed(calibrator, 0.8, 0.1, moving=True, gyro_z=1.0)  # the robot turns briefly
    feed(calibrator, 0.9, 0.95)  # rests 0.95 s < 1 s since the last motion
    assert not calibrator.calibrated
    feed(calibrator, 1.85, 0.2)
    assert calibrator.calibrated
    # Only samples taken at rest count: the turn's 1 rad/s never enters the estimate.
    assert calibrator.gyro_bias[2] == pytest.approx(GYRO_BIAS[2], abs=1e-12)


def test_a_later_rest_follows_a_drifting_bias():
    calibrator = ImuRestCalibrator(rest_time_s=0.5, min_samples=10)
    feed(calibrator, 0.0, 1.0)
    assert calibrator.gyro_bias[2] == pytest.approx(GYRO_BIAS[2])
    feed(calibrator, 1.0, 2.0, moving=True, gyro_z=0.3)
    # The bias has drifted by +0.004 rad/s by the next rest.
    feed(calibrator, 3.0, 1.0, gyro_z=0.004)
    assert calibrator.calibrations == 2
    assert calibrator.gyro_bias[2] == pytest.approx(GYRO_BIAS[2] + 0.004, abs=1e-12)


def test_a_turn_the_encoders_have_not_seen_yet_ends_the_rest():
    calibrator = ImuRestCalibrator(rest_time_s=0.5, min_samples=10)
    feed(calibrator, 0.0, 1.0)
    # Pushed by hand: the gyro sees 0.2 rad/s before any encoder counts.
    calibrator.on_ticks((0, 0, 0, 0), False, 1.0)
    _, gyro = calibrator.on_sample((0.0, 0.0, GRAVITY),
                                   (GYRO_BIAS[0], GYRO_BIAS[1], GYRO_BIAS[2] + 0.2), 1.0)
    assert calibrator.rest_samples() == 0
    assert calibrator.gyro_bias[2] == pytest.approx(GYRO_BIAS[2], abs=1e-12)
    assert gyro[2] == pytest.approx(0.2, abs=1e-12)


def test_a_large_uncalibrated_bias_is_still_measured():
    calibrator = ImuRestCalibrator(rest_time_s=0.5, min_samples=10)
    for i in range(100):  # MPU-6050-like untrimmed bias of 0.3 rad/s (17 deg/s)
        calibrator.on_ticks((0, 0, 0, 0), False, i / 100.0)
        calibrator.on_sample((0.0, 0.0, GRAVITY), (0.0, 0.0, 0.3), i / 100.0)
    assert calibrator.gyro_bias[2] == pytest.approx(0.3, abs=1e-12)


def test_while_moving_the_last_bias_is_removed():
    calibrator = ImuRestCalibrator(rest_time_s=0.5, min_samples=10)
    feed(calibrator, 0.0, 1.0)
    _, gyro = feed(calibrator, 1.0, 1.0, moving=True, gyro_z=0.7)
    assert gyro[2] == pytest.approx(0.7, abs=1e-12)


def test_non_finite_samples_are_not_averaged():
    calibrator = ImuRestCalibrator(rest_time_s=0.5, min_samples=10)
    feed(calibrator, 0.0, 0.6)
    calibrator.on_ticks((0, 0, 0, 0), False, 0.6)
    accel, gyro = calibrator.on_sample((0.0, 0.0, GRAVITY), (math.nan, 0.0, 0.0), 0.6)
    assert math.isnan(gyro[0])  # passed through for the consumer to reject
    feed(calibrator, 0.61, 0.5)
    assert all(math.isfinite(b) for b in calibrator.gyro_bias)
    assert calibrator.gyro_bias == pytest.approx(GYRO_BIAS, abs=1e-12)


@pytest.mark.parametrize('kwargs', [
    {'rest_time_s': 0.0}, {'rest_time_s': math.nan}, {'encoder_timeout_s': -1.0},
    {'min_samples': 0}])
def test_bad_settings_are_rejected(kwargs):
    with pytest.raises(ValueError):
        ImuRestCalibrator(**kwargs)
