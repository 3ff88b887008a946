"""Hand-worked tests of mecanum_control.wheel_odometry (counter wrap, gaps, resets, pose)."""

import math

from mecanum_control.angles import angle_difference
from mecanum_control.kinematics import inverse_kinematics, MecanumGeometry
from mecanum_control.wheel_odometry import (
    EncoderSample, SampleResult, WheelOdometry, wrapped_delta)
import numpy
import pytest

# r = 0.05 m, lx = 0.10 m, ly = 0.15 m: lx + ly = 0.25 m.
GEOMETRY = MecanumGeometry(wheel_radius_m=0.05, half_wheelbase_m=0.10, half_track_m=0.15)
# 1000 counts per wheel turn: one count is 2 pi / 1000 = 0.0062831853 rad.
RAD_PER_COUNT = 2.0 * math.pi / 1000.0
MAX_WHEEL_SPEED = 20.0  # rad/s
PERIOD_US = 20_000      # one sample every 20 ms
PERIOD_S = 0.02
# 40 counts per 20 ms sample: 40 * 2 pi / 1000 = 0.08 pi rad per sample = 4 pi rad/s per wheel,
# i.e. 0.05 m * 4 pi = 0.2 pi m/s of wheel rim speed; in 50 samples (1 s) 0.2 pi m.
N = 40


def int32(value):
    """Wrap an integer to the signed 32-bit range, as the board's counters do."""
    return (value + 2**31) % 2**32 - 2**31


def u32(value):
    """Wrap an integer to the unsigned 32-bit range (sequence and board clock)."""
    return value % 2**32


def make_odometry(rad_per_count=RAD_PER_COUNT, **kwargs):
    """Return a WheelOdometry for the test geometry."""
    return WheelOdometry(GEOMETRY, rad_per_count, MAX_WHEEL_SPEED, **kwargs)


def constant_rate_samples(per_sample, count, seq0=100, time0_us=1_000_000,
                          ticks0=(0, 0, 0, 0)):
    """
    Return count + 1 samples with each counter advancing by per_sample[i] per sample.

    The first sample is the baseline; sequence and clock advance by 1 and 20 ms.
    """
    return [EncoderSample(u32(seq0 + k), u32(time0_us + k * PERIOD_US),
                          tuple(int32(t + k * d) for t, d in zip(ticks0, per_sample)))
            for k in range(count + 1)]


def feed(odometry, samples):
    """Give the samples to the odometry in order; return the list of results."""
    return [odometry.update(sample) for sample in samples]


def shifted(sample, seq=0, time_us=0, ticks=(0, 0, 0, 0)):
    """Return the sample with its sequence, clock and counters moved by the given amounts."""
    return EncoderSample(u32(sample.sequence + seq), u32(sample.board_time_us + time_us),
                         tuple(int32(t + d) for t, d in zip(sample.ticks, ticks)))


# ------------------------------------------------------------------ wrapped_delta


@pytest.mark.parametrize('previous, current, expected', [
    (0, 0, 0),
    (10, 13, 3),
    (13, 10, -3),
    (2147483647, -2147483648, 1),     # int32 counter wraps forwards: +1
    (-2147483648, 2147483647, -1),    # and backwards: -1
    (2147483640, -2147483640, 16),    # 7 up to the top, 1 to wrap, 8 more
    (-5, 5, 10),
    (4294967295, 5, 6),               # u32 clock wraps: 2^32 - 1 -> 5 is +6
    (5, 4294967295, -6),
    (0, 2**31 - 1, 2**31 - 1),        # the largest forward step
    (2**31 - 1, 0, -(2**31 - 1)),
])
def test_wrapped_delta_hand_cases(previous, current, expected):
    """Signed differences modulo 2^32 (int32 counters and u32 clocks alike)."""
    assert wrapped_delta(previous, current) == expected


def test_wrapped_delta_explicit_modulus():
    """The modulus can be given: 2^32 explicitly, or a small one worked by hand."""
    assert wrapped_delta(4294967295, 5, modulus=2**32) == 6
    assert wrapped_delta(15, 1, modulus=16) == 2     # 15 -> 0 -> 1
    assert wrapped_delta(1, 15, modulus=16) == -2
    assert wrapped_delta(65535, 0, modulus=2**16) == 1


@pytest.mark.filterwarnings('error')
def test_wrapped_delta_accepts_numpy_ints():
    """Numpy int32/uint32 (as in ROS messages) give the same answer, with no overflow."""
    assert wrapped_delta(numpy.int32(2147483647), numpy.int32(-2147483648)) == 1
    assert wrapped_delta(numpy.int32(-2147483648), numpy.int32(2147483647)) == -1
    assert wrapped_delta(numpy.uint32(4294967295), numpy.uint32(5)) == 6
    assert wrapped_delta(numpy.uint32(5), numpy.uint32(4294967295)) == -6
    result = wrapped_delta(numpy.int32(-2147483648), numpy.int32(2147483647))
    assert type(result) is int


# ------------------------------------------------------------- basic motion


def test_first_sample_is_the_baseline():
    """The first sample sets the baseline: status 'first', nothing moves."""
    odometry = make_odometry()
    result = odometry.update(EncoderSample(7, 123, (1000, -5, 2**31 - 1, -2**31)))
    assert result == SampleResult('first')
    assert not result.accepted
    assert odometry.pose == (0.0, 0.0, 0.0)
    assert odometry.wheel_positions_rad == [0.0] * 4


def test_straight_line():
    """
    All four wheels advance 40 counts per 20 ms for 50 samples: straight ahead.

    x = 50 samples * 40 counts * (2 pi / 1000) rad * 0.05 m = 2000 * 0.0062831853 * 0.05
      = 0.2 pi = 0.6283185 m; wheel angle 2000 counts = 4 pi rad;
    wheel speed 40 * 0.0062831853 / 0.02 = 4 pi = 12.566 rad/s; vx = 0.05 * 4 pi = 0.2 pi m/s.
    """
    odometry = make_odometry()
    results = feed(odometry, constant_rate_samples((N, N, N, N), 50))
    assert results[0].status == 'first'
    assert all(result == SampleResult('ok') for result in results[1:])
    x, y, yaw = odometry.pose
    assert x == pytest.approx(0.2 * math.pi, abs=1e-12)
    assert y == pytest.approx(0.0, abs=1e-12)
    assert yaw == pytest.approx(0.0, abs=1e-12)
    assert odometry.wheel_positions_rad == pytest.approx([4 * math.pi] * 4, abs=1e-12)
    assert odometry.wheel_velocities_rad_s == pytest.approx([4 * math.pi] * 4, abs=1e-9)
    vx, vy, wz = odometry.twist
    assert vx == pytest.approx(0.2 * math.pi, abs=1e-9)
    assert vy == pytest.approx(0.0, abs=1e-12)
    assert wz == pytest.approx(0.0, abs=1e-12)
    assert odometry.lost_samples == 0 and odometry.rejected_samples == 0


def test_straight_line_backwards():
    """-40 counts per sample on all wheels for 25 samples: x = -25 * 40 * rad * r = -0.1 pi."""
    odometry = make_odometry()
    feed(odometry, constant_rate_samples((-N, -N, -N, -N), 25))
    assert odometry.pose == pytest.approx((-0.1 * math.pi, 0.0, 0.0), abs=1e-12)
    assert odometry.twist == pytest.approx((-0.2 * math.pi, 0.0, 0.0), abs=1e-9)


def test_strafe_left():
    """
    Strafe left (+y): FL and RR turn backwards, FR and RL forwards (X rollers).

    Counters (-40, +40, +40, -40) per sample for 50 samples: y = 0.2 pi m as in the
    straight line, x = 0, yaw = 0; vy = 0.2 pi m/s.
    """
    odometry = make_odometry()
    feed(odometry, constant_rate_samples((-N, N, N, -N), 50))
    x, y, yaw = odometry.pose
    assert x == pytest.approx(0.0, abs=1e-12)
    assert y == pytest.approx(0.2 * math.pi, abs=1e-12)
    assert yaw == pytest.approx(0.0, abs=1e-12)
    assert odometry.twist == pytest.approx((0.0, 0.2 * math.pi, 0.0), abs=1e-9)
    four_pi = 4 * math.pi
    assert odometry.wheel_velocities_rad_s == pytest.approx(
        [-four_pi, four_pi, four_pi, -four_pi], abs=1e-9)


def test_strafe_right():
    """Counters (+40, -40, -40, +40) strafe right: y = -0.2 pi m after 50 samples."""
    odometry = make_odometry()
    feed(odometry, constant_rate_samples((N, -N, -N, N), 50))
    assert odometry.pose == pytest.approx((0.0, -0.2 * math.pi, 0.0), abs=1e-12)


def test_rotate_left_in_place():
    """
    Counters (-40, +40, -40, +40): right wheels forward, left back, turning left (+yaw).

    Per sample each wheel turns 0.08 pi rad = 0.004 pi m of rim travel; yaw per sample
    = 0.004 pi / (lx + ly) = 0.004 pi / 0.25 = 0.016 pi rad. After 25 samples 0.4 pi;
    wz = 0.016 pi / 0.02 s = 0.8 pi rad/s.
    """
    odometry = make_odometry()
    feed(odometry, constant_rate_samples((-N, N, -N, N), 25))
    x, y, yaw = odometry.pose
    assert x == pytest.approx(0.0, abs=1e-12)
    assert y == pytest.approx(0.0, abs=1e-12)
    assert yaw == pytest.approx(0.4 * math.pi, abs=1e-12)
    assert odometry.twist == pytest.approx((0.0, 0.0, 0.8 * math.pi), abs=1e-9)


def test_rotation_yaw_wraps():
    """75 samples of left turn: 75 * 0.016 pi = 1.2 pi, reported as 1.2 pi - 2 pi = -0.8 pi."""
    odometry = make_odometry()
    feed(odometry, constant_rate_samples((-N, N, -N, N), 75))
    assert odometry.pose == pytest.approx((0.0, 0.0, -0.8 * math.pi), abs=1e-12)


def test_rotate_right_in_place():
    """Counters (+40, -40, +40, -40) turn right: yaw = -0.4 pi after 25 samples."""
    odometry = make_odometry()
    feed(odometry, constant_rate_samples((N, -N, N, -N), 25))
    assert odometry.pose == pytest.approx((0.0, 0.0, -0.4 * math.pi), abs=1e-12)
    assert odometry.twist == pytest.approx((0.0, 0.0, -0.8 * math.pi), abs=1e-9)


def test_forward_after_quarter_turn_goes_along_odom_y():
    """
    Turn left by exactly 0.5 pi, then drive forward: the motion is along odom +y.

    The turn is 125 samples of (-8, +8, -8, +8) counts: each 8 counts turn the robot by
    8 * 0.0062831853 * 0.05 / 0.25 = 0.0032 pi rad, and 125 * 0.0032 pi = 0.4 pi... so
    instead use 25 samples of 40 (0.4 pi) plus 25 samples of 10 counts (0.1 pi): 0.5 pi.
    Then 50 samples of 40 counts forward move 0.2 pi m along +y.
    """
    odometry = make_odometry()
    turn1 = constant_rate_samples((-N, N, -N, N), 25)
    turn2 = constant_rate_samples((-10, 10, -10, 10), 25, seq0=125, time0_us=1_500_000,
                                  ticks0=turn1[-1].ticks)[1:]
    forward = constant_rate_samples((N, N, N, N), 50, seq0=150, time0_us=2_000_000,
                                    ticks0=turn2[-1].ticks)[1:]
    results = feed(odometry, turn1 + turn2 + forward)
    assert all(result.status == 'ok' for result in results[1:])
    x, y, yaw = odometry.pose
    assert yaw == pytest.approx(0.5 * math.pi, abs=1e-12)
    assert x == pytest.approx(0.0, abs=1e-12)
    assert y == pytest.approx(0.2 * math.pi, abs=1e-12)
    # The twist stays in the body frame (REP-105 child frame base_link): forward is +x.
    assert odometry.twist == pytest.approx((0.2 * math.pi, 0.0, 0.0), abs=1e-9)


# ------------------------------------------------------------------- circle


def circle_samples(rad_per_count, vx, wz, count):
    """
    Return count + 1 samples of the constant twist (vx, 0, wz), from ideal wheel angles.

    Wheel speeds come from inverse_kinematics; each wheel angle at t = k * 20 ms is
    quantised to counts with floor, as a quadrature decoder does.
    """
    speeds = inverse_kinematics(GEOMETRY, vx, 0.0, wz)
    samples = []
    for k in range(count + 1):
        t = k * PERIOD_S
        ticks = tuple(int32(math.floor(speed * t / rad_per_count)) for speed in speeds)
        samples.append(EncoderSample(k, k * PERIOD_US, ticks))
    return samples


def angle_error(a, b):
    """Return the absolute difference of two angles, modulo 2 pi."""
    return abs(angle_difference(a, b))


# Bounds on the error from count quantisation on the circle below (R = 0.3 / (pi/3) m,
# 1.8 m travelled, 2 pi turned). Each wheel angle is at most 1 count (c rad) behind the ideal
# one and the counters are absolute, so errors do not accumulate:
# - yaw: yaw is linear in the wheel angles, r / (4 (lx + ly)) * (sum of +-errors) < r c / 0.25;
#   for c = 2 pi / 1000: 0.05 * 0.0062832 / 0.25 = 1.26e-3 rad.
# - position: the translation error of the wheel sum is < r c = 3.1e-4 m at any time; summed
#   by parts along the path it stays below r c (2 + 2 pi) = 2.6e-3 m, plus heading error
#   times distance 1.26e-3 * 1.8 = 2.3e-3 m: about 4.9e-3 m in all.
# With c = 2 pi / 1e6 the bounds are 1000 times smaller (1.3e-6 rad, 4.9e-6 m). Euler
# integration (heading held over each step) would be 3 mm off at the quarter and half circle,
# so the fine encoder checks that the pose is integrated exactly along arcs.
CIRCLE_CASES = [
    pytest.param(2 * math.pi / 1000, 5e-3, 1.3e-3, id='1000-counts'),
    pytest.param(2 * math.pi / 1e6, 1e-5, 2e-6, id='1e6-counts'),
]


@pytest.mark.parametrize('rad_per_count, position_tolerance, yaw_tolerance', CIRCLE_CASES)
def test_full_circle_returns_to_start(rad_per_count, position_tolerance, yaw_tolerance):
    """
    Drive a full circle with vx = 0.3 m/s and wz = pi/3 rad/s.

    One turn takes 2 pi / (pi/3) = 6 s = 300 samples. The radius is
    R = vx / wz = 0.9 / pi = 0.2864789 m; from the origin heading +x and turning left the
    pose is (R sin(wz t), R (1 - cos(wz t)), wz t): (R, R, pi/2) after 1.5 s,
    (0, 2R, pi) after 3 s, (0, 0, 0) after 6 s.
    """
    odometry = make_odometry(rad_per_count)
    radius = 0.9 / math.pi
    expected = {75: (radius, radius, math.pi / 2), 150: (0.0, 2 * radius, math.pi),
                225: (-radius, radius, -math.pi / 2), 300: (0.0, 0.0, 0.0)}
    for k, sample in enumerate(circle_samples(rad_per_count, 0.3, math.pi / 3, 300)):
        result = odometry.update(sample)
        assert result.status == ('first' if k == 0 else 'ok')
        if k in expected:
            x, y, yaw = odometry.pose
            ex, ey, eyaw = expected[k]
            assert x == pytest.approx(ex, abs=position_tolerance), k
            assert y == pytest.approx(ey, abs=position_tolerance), k
            assert angle_error(yaw, eyaw) < yaw_tolerance, k
    # Twist of the last window: vx = 0.3 m/s, wz = pi/3, with the window's count error
    # (one count over >= 60 ms is 0.0063 / 0.06 = 0.105 rad/s on a wheel, 5.2e-3 m/s).
    vx, vy, wz = odometry.twist
    assert vx == pytest.approx(0.3, abs=6e-3)
    assert vy == pytest.approx(0.0, abs=6e-3)
    assert wz == pytest.approx(math.pi / 3, abs=2.2e-2)


# --------------------------------------------------------------- wrap-around


def test_counter_and_clock_wrap_mid_motion_changes_nothing():
    """
    Counters start near the int32 limits and wrap; clock and sequence wrap at 2^32.

    FL starts 500 below 2^31 - 1 going up 30 per sample (wraps at sample 17), FR starts
    500 above -2^31 going down 25 per sample (wraps at sample 21), the clock wraps at
    sample 10 and the sequence at sample 5. The result is exactly that of a run from 0.
    """
    per_sample = (30, -25, 40, -35)
    count = 60
    reference = make_odometry()
    feed(reference, constant_rate_samples(per_sample, count, seq0=0, time0_us=0))

    wrapping = make_odometry()
    samples = constant_rate_samples(
        per_sample, count, seq0=2**32 - 5, time0_us=2**32 - 10 * PERIOD_US + 7,
        ticks0=(2**31 - 1 - 500, -2**31 + 500, 2**31 - 1 - 10, -2**31 + 5))
    # The wraps really happen where the docstring says.
    assert samples[16].ticks[0] == 2**31 - 21 and samples[17].ticks[0] == -2**31 + 9
    assert samples[20].ticks[1] == -2**31 and samples[21].ticks[1] == 2**31 - 25
    assert samples[9].board_time_us == 2**32 - PERIOD_US + 7
    assert samples[10].board_time_us == 7
    assert samples[4].sequence == 2**32 - 1 and samples[5].sequence == 0
    results = feed(wrapping, samples)
    assert all(result.status == 'ok' for result in results[1:])
    assert wrapping.pose == reference.pose
    assert wrapping.wheel_positions_rad == reference.wheel_positions_rad
    assert wrapping.wheel_velocities_rad_s == reference.wheel_velocities_rad_s
    assert wrapping.twist == reference.twist
    # Hand check of one wheel: FL moved 60 * 30 = 1800 counts = 3.6 pi rad.
    assert wrapping.wheel_positions_rad[0] == pytest.approx(3.6 * math.pi, abs=1e-12)


@pytest.mark.filterwarnings('error')
def test_numpy_sample_fields_wrap_like_ints():
    """Samples made of numpy uint32 / int32 (as from the ROS message) give the same result."""
    samples = constant_rate_samples((N, -N, N, -N), 30, seq0=2**32 - 3,
                                    time0_us=2**32 - 5 * PERIOD_US,
                                    ticks0=(2**31 - 100, -2**31 + 100, 0, 0))
    as_numpy = [EncoderSample(numpy.uint32(s.sequence), numpy.uint32(s.board_time_us),
                              tuple(numpy.int32(t) for t in s.ticks)) for s in samples]
    plain = make_odometry()
    feed(plain, samples)
    numpy_odometry = make_odometry()
    results = feed(numpy_odometry, as_numpy)
    assert all(result.status == 'ok' for result in results[1:])
    assert numpy_odometry.pose == plain.pose
    assert numpy_odometry.wheel_positions_rad == plain.wheel_positions_rad


# ------------------------------------------------------------ lost samples


def test_every_other_sample_lost_gives_the_same_pose():
    """
    Dropping every other sample loses no distance: the absolute counters cover the gap.

    50 steps, only even samples arrive: 25 updates each with 1 lost sample.
    """
    full = make_odometry()
    samples = constant_rate_samples((N, N, N, N), 50)
    feed(full, samples)
    sparse = make_odometry()
    results = feed(sparse, samples[::2])
    assert all(result == SampleResult('gap', lost=1) for result in results[1:])
    assert all(result.accepted for result in results[1:])
    assert sparse.lost_samples == 25
    assert sparse.pose == pytest.approx(full.pose, abs=1e-9)
    assert sparse.pose[0] == pytest.approx(0.2 * math.pi, abs=1e-9)
    assert sparse.wheel_positions_rad == pytest.approx(full.wheel_positions_rad, abs=1e-12)
    assert sparse.wheel_velocities_rad_s == pytest.approx([4 * math.pi] * 4, abs=1e-9)


def test_rotation_with_lost_samples_keeps_the_angle():
    """A left turn with every third sample lost ends at the same yaw, 0.4 pi after 25 steps."""
    samples = constant_rate_samples((-N, N, -N, N), 25)
    odometry = make_odometry()
    kept = [sample for k, sample in enumerate(samples) if k % 3 != 2]
    feed(odometry, kept)
    assert odometry.pose == pytest.approx((0.0, 0.0, 0.4 * math.pi), abs=1e-9)
    assert odometry.lost_samples == 8   # samples 2, 5, ..., 23: 8 of them


def test_burst_of_lost_samples():
    """Samples 11..20 lost: sample 21 reports a gap of 10, and the distance is kept."""
    samples = constant_rate_samples((N, N, N, N), 50)
    odometry = make_odometry()
    results = feed(odometry, samples[:11] + samples[21:])
    assert results[11] == SampleResult('gap', lost=10)
    assert all(result.status == 'ok' for result in results[12:])
    assert odometry.lost_samples == 10
    assert odometry.pose == pytest.approx((0.2 * math.pi, 0.0, 0.0), abs=1e-9)


# ------------------------------------------------------- duplicate and stale


def test_duplicate_is_dropped():
    """A repeated sequence number is dropped, even with other counters; pose unchanged."""
    samples = constant_rate_samples((N, N, N, N), 20)
    odometry = make_odometry()
    feed(odometry, samples[:11])
    pose = odometry.pose
    positions = list(odometry.wheel_positions_rad)
    for duplicate in (samples[10], shifted(samples[10], ticks=(5, 5, 5, 5))):
        result = odometry.update(duplicate)
        assert result.status == 'duplicate'
        assert not result.accepted
        assert odometry.pose == pose
        assert odometry.wheel_positions_rad == positions
    assert odometry.rejected_samples == 2
    feed(odometry, samples[11:])
    # 20 accepted steps of 40 counts: x = 20 * 40 * 0.0062831853 * 0.05 = 0.08 pi.
    assert odometry.pose == pytest.approx((0.08 * math.pi, 0.0, 0.0), abs=1e-12)


def test_stale_sample_is_dropped():
    """An older sequence number (a late sample) is dropped and later samples continue."""
    samples = constant_rate_samples((N, N, N, N), 20)
    odometry = make_odometry()
    feed(odometry, samples[:11])
    pose = odometry.pose
    for old in (samples[9], samples[3]):
        result = odometry.update(old)
        assert result.status == 'stale'
        assert not result.accepted
        assert odometry.pose == pose
    assert odometry.rejected_samples == 2
    results = feed(odometry, samples[11:])
    assert all(result.status == 'ok' for result in results)
    assert odometry.pose == pytest.approx((0.08 * math.pi, 0.0, 0.0), abs=1e-12)


def test_sample_whose_clock_does_not_advance_is_stale():
    """A newer sequence number with the same board time cannot be used (dt = 0)."""
    samples = constant_rate_samples((N, N, N, N), 5)
    odometry = make_odometry()
    feed(odometry, samples)
    result = odometry.update(shifted(samples[-1], seq=1, ticks=(N, N, N, N)))
    assert result.status == 'stale'
    assert odometry.pose == pytest.approx((0.02 * math.pi, 0.0, 0.0), abs=1e-12)


# ------------------------------------------------------------------ board reset


def assert_reset_then_continue(odometry, restart_seq0):
    """
    Feed a board restart (clock back to 3 ms, counters back to 0) and 50 more samples.

    Check the reset keeps the pose and the motion after it adds to the held pose.
    """
    pose = odometry.pose
    positions = list(odometry.wheel_positions_rad)
    after = constant_rate_samples((N, N, N, N), 50, seq0=restart_seq0, time0_us=3_000)
    result = odometry.update(after[0])
    assert result.status == 'reset'
    assert not result.accepted
    assert odometry.resets == 1
    assert odometry.pose == pose                      # no jump
    assert odometry.wheel_positions_rad == positions  # joint angles do not jump either
    assert odometry.wheel_velocities_rad_s == [0.0] * 4
    assert odometry.twist == (0.0, 0.0, 0.0)
    results = feed(odometry, after[1:])
    assert all(result.status == 'ok' for result in results)
    # 0.2 pi m before the reset and 0.2 pi m after it.
    assert odometry.pose == pytest.approx((0.4 * math.pi, 0.0, 0.0), abs=1e-12)
    assert odometry.wheel_positions_rad == pytest.approx([8 * math.pi] * 4, abs=1e-12)
    assert odometry.twist == pytest.approx((0.2 * math.pi, 0.0, 0.0), abs=1e-9)


def test_board_reset_sequence_and_clock_back():
    """The board restarts: sequence 150 -> 0, clock 2 s -> 3 ms, counters 2000 -> 0."""
    odometry = make_odometry()
    feed(odometry, constant_rate_samples((N, N, N, N), 50, seq0=100, time0_us=1_000_000))
    assert_reset_then_continue(odometry, restart_seq0=0)


def test_board_reset_after_long_run_sequence_back_far():
    """After 100000 samples the sequence falls back by far more than 1000: a reset."""
    odometry = make_odometry()
    feed(odometry, constant_rate_samples((N, N, N, N), 50, seq0=100_000,
                                         time0_us=2_000_000_000))
    assert_reset_then_continue(odometry, restart_seq0=0)


def test_board_reset_with_host_sequence_continuing():
    """
    A restart seen through hardware_interface: the clock goes back, the sequence goes on.

    hardware_interface unwraps the board's 16-bit frame counter into WheelTicks.sequence
    and, when the board clock goes back (restart), keeps counting from its last value, so
    the odometry sees sequence 151 after 150 with the clock back at 3 ms. That must be a
    reset too; otherwise every later sample would look stale until the new clock passes the
    old one.
    """
    odometry = make_odometry()
    feed(odometry, constant_rate_samples((N, N, N, N), 50, seq0=100, time0_us=1_000_000))
    assert_reset_then_continue(odometry, restart_seq0=151)


# ------------------------------------------------------------------- glitches


def test_glitch_threshold_is_twice_max_speed_plus_margin():
    """
    The largest accepted step is 2 * 20 rad/s * 0.02 s / (2 pi / 1000) + 8 counts.

    0.8 / 0.0062831853 = 127.32 counts, + 8 = 135.32: a step of 135 counts passes,
    136 (or -136) is a glitch.
    """
    for step, status in ((135, 'ok'), (-135, 'ok'), (136, 'glitch'), (-136, 'glitch')):
        odometry = make_odometry()
        samples = constant_rate_samples((0, step, 0, 0), 1)
        assert [result.status for result in feed(odometry, samples)] == ['first', status]


def test_glitch_on_a_gap_scales_with_elapsed_time():
    """After one lost sample (40 ms) 270 counts are plausible: 2 * 127.32 + 8 = 262.6 < 270..."""
    odometry = make_odometry()
    samples = constant_rate_samples((0, 131, 0, 0), 2)  # 262 counts over 40 ms
    results = feed(odometry, [samples[0], samples[2]])
    assert results[1] == SampleResult('gap', lost=1)
    odometry = make_odometry()
    samples = constant_rate_samples((0, 132, 0, 0), 2)  # 264 counts > 262.65
    results = feed(odometry, [samples[0], samples[2]])
    assert results[1].status == 'glitch'


def test_restart_after_a_long_uptime_is_a_glitch_not_motion():
    """
    A board restarted after a long uptime moves nothing.

    After 40 min its u32 clock has wrapped, so the clock seems to jump forward ~1295 s
    while the counters drop from ~5e6 back near 0. Travel is bounded over at most 1 s:
    2 * 20 rad/s * 1 s / (2 pi / 1000) + 8 = 6374 counts, far below a 5e6-count drop,
    so the pose must not move.
    """
    odometry = make_odometry()
    start = (5_000_000, 5_000_000, 5_000_000, 5_000_000)
    feed(odometry, constant_rate_samples((0, 0, 0, 0), 3, ticks0=start))
    pose = odometry.pose
    restarted = EncoderSample(104, 1_060_000 + 1_295_000_000, (12, 12, 12, 12))
    assert odometry.update(restarted).status == 'glitch'
    assert odometry.pose == pose


def test_long_gap_with_plausible_travel_keeps_the_distance():
    """
    A long link gap keeps the distance travelled in it.

    3 s during which the wheels turned 1000 counts (one turn, 0.1 pi m): within the
    6374-count bound, so the distance is kept (counters are absolute).
    """
    odometry = make_odometry()
    feed(odometry, constant_rate_samples((0, 0, 0, 0), 1))
    result = odometry.update(EncoderSample(252, 1_020_000 + 3_000_000, (1000, 1000, 1000, 1000)))
    assert result.status == 'gap' and result.lost == 150
    assert odometry.pose[0] == pytest.approx(1000 * RAD_PER_COUNT * 0.05)


def glitch_run(persistent):
    """
    Straight line; at sample 11 FL jumps by +100000 counts (100 turns in 20 ms).

    With persistent=True the jump stays in FL's counter (an offset); otherwise sample 12
    is back to normal (one corrupt reading). Returns the odometry and all results.
    """
    samples = constant_rate_samples((N, N, N, N), 20)
    jump = (100_000, 0, 0, 0)
    samples[11] = shifted(samples[11], ticks=jump)
    if persistent:
        samples[12:] = [shifted(sample, ticks=jump) for sample in samples[12:]]
    odometry = make_odometry()
    results = feed(odometry, samples[:11])
    pose, positions = odometry.pose, list(odometry.wheel_positions_rad)
    velocities = list(odometry.wheel_velocities_rad_s)
    results.append(odometry.update(samples[11]))
    assert results[11].status == 'glitch'
    assert not results[11].accepted
    assert odometry.pose == pose
    assert odometry.wheel_positions_rad == positions
    # The module keeps the last velocities across a glitch (it re-baselines keeping state).
    assert odometry.wheel_velocities_rad_s == velocities
    results.extend(feed(odometry, samples[12:]))
    return odometry, results


def test_persistent_counter_jump_rebaselines_at_the_glitch():
    """
    The module re-baselines at the glitch sample: a lasting offset costs one step only.

    Accepted steps 1..10 and 12..20 (19 of 20): x = 19 * 40 * 0.0062831853 * 0.05
    = 0.076 pi m; the 20 ms of the glitch step are not counted.
    """
    odometry, results = glitch_run(persistent=True)
    assert [result.status for result in results[12:]] == ['ok'] * 9
    assert odometry.rejected_samples == 1
    assert odometry.pose == pytest.approx((0.076 * math.pi, 0.0, 0.0), abs=1e-12)
    assert odometry.wheel_positions_rad == pytest.approx([19 * N * RAD_PER_COUNT] * 4,
                                                         abs=1e-12)
    assert odometry.wheel_velocities_rad_s == pytest.approx([4 * math.pi] * 4, abs=1e-9)


def test_single_corrupt_reading_costs_two_steps():
    """
    A one-off corrupt reading is rejected twice: the glitch, then the return to normal.

    Because the baseline moved to the corrupt sample, sample 12 (back to normal) is
    100000 counts behind it and is a glitch too; it becomes the baseline. Accepted steps
    1..10 and 13..20 (18 of 20): x = 18 * 40 * 0.0062831853 * 0.05 = 0.072 pi m.
    """
    odometry, results = glitch_run(persistent=False)
    assert results[12].status == 'glitch'
    assert [result.status for result in results[13:]] == ['ok'] * 8
    assert odometry.rejected_samples == 2
    assert odometry.pose == pytest.approx((0.072 * math.pi, 0.0, 0.0), abs=1e-12)


# --------------------------------------------------------------- windowed velocity


def speed_samples(speed, count, start_tick=0):
    """Return count + 1 samples of all wheels at a constant speed (rad/s), floor-quantised."""
    return [EncoderSample(k, k * PERIOD_US,
                          (int32(start_tick + math.floor(speed * k * PERIOD_S / RAD_PER_COUNT)),)
                          * 4)
            for k in range(count + 1)]


def test_windowed_velocity_is_within_one_count_per_window():
    """
    At 10 rad/s (31.83 counts per 20 ms) the window estimate is within 1 count per window.

    The window is at least 0.06 s, so the error is below 0.0062831853 / 0.06 = 0.1047 rad/s
    (and 0.05 * 0.1047 = 5.2e-3 m/s on vx). A single 20 ms step (window 0) reads 31 or 32
    counts: 9.74 or 10.05 rad/s, an error of up to 0.26 rad/s.
    """
    samples = speed_samples(10.0, 100)
    windowed = make_odometry(velocity_window_s=0.06)
    single_step = make_odometry(velocity_window_s=0.0)
    worst_windowed = worst_single = 0.0
    for k, sample in enumerate(samples):
        windowed.update(sample)
        single_step.update(sample)
        if k >= 3:  # the window has filled
            for velocity in windowed.wheel_velocities_rad_s:
                worst_windowed = max(worst_windowed, abs(velocity - 10.0))
            assert windowed.twist[0] == pytest.approx(0.5, abs=5.3e-3)
            worst_single = max(worst_single, abs(single_step.wheel_velocities_rad_s[0] - 10.0))
    assert worst_windowed < 0.1048
    assert worst_single > 0.2   # the window is what buys the accuracy


def test_velocity_returns_to_zero_after_stop():
    """
    After the wheels stop, the window empties of motion within 0.06 s + one sample.

    Moving 10 rad/s for 50 samples, then counters frozen: one sample later the window still
    holds motion (velocity > 0); four samples (80 ms) later velocity and twist are exactly 0.
    """
    moving = speed_samples(10.0, 50)
    last = moving[-1]
    stopped = [EncoderSample(last.sequence + k, last.board_time_us + k * PERIOD_US, last.ticks)
               for k in range(1, 11)]
    odometry = make_odometry(velocity_window_s=0.06)
    feed(odometry, moving)
    odometry.update(stopped[0])
    assert all(v > 1.0 for v in odometry.wheel_velocities_rad_s)
    feed(odometry, stopped[1:4])
    assert odometry.wheel_velocities_rad_s == [0.0] * 4
    assert odometry.twist == (0.0, 0.0, 0.0)
    feed(odometry, stopped[4:])
    assert odometry.wheel_velocities_rad_s == [0.0] * 4


# ------------------------------------------------------------------ misc API


def test_reset_pose_keeps_counting():
    """reset_pose sets (and wraps) the pose; the wheels keep integrating from there."""
    samples = constant_rate_samples((N, N, N, N), 20)
    odometry = make_odometry()
    feed(odometry, samples[:11])
    odometry.reset_pose(1.0, 2.0, 0.5 * math.pi + 2 * math.pi)
    assert odometry.pose == pytest.approx((1.0, 2.0, 0.5 * math.pi), abs=1e-12)
    feed(odometry, samples[11:])
    # 10 steps forward while facing +y: 10 * 40 * 0.0062831853 * 0.05 = 0.04 pi m along y.
    assert odometry.pose == pytest.approx((1.0, 2.0 + 0.04 * math.pi, 0.5 * math.pi),
                                          abs=1e-12)
    with pytest.raises(ValueError):
        odometry.reset_pose(float('nan'), 0.0, 0.0)


def test_wrong_number_of_counters_is_an_error():
    """A sample must carry exactly four counters."""
    odometry = make_odometry()
    with pytest.raises(ValueError):
        odometry.update(EncoderSample(0, 0, (0, 0, 0)))


@pytest.mark.parametrize('kwargs', [
    {'rad_per_count': 0.0, 'max_wheel_speed_rad_s': 20.0},
    {'rad_per_count': RAD_PER_COUNT, 'max_wheel_speed_rad_s': 0.0},
    {'rad_per_count': RAD_PER_COUNT, 'max_wheel_speed_rad_s': 20.0, 'velocity_window_s': -0.1},
])
def test_invalid_construction_is_rejected(kwargs):
    """Non-positive resolution or speed limit, or a negative window, are rejected."""
    with pytest.raises(ValueError):
        WheelOdometry(GEOMETRY, **kwargs)


def test_sample_result_accepted():
    """Only 'ok' and 'gap' samples move the odometry."""
    accepted = {status: SampleResult(status).accepted
                for status in ('first', 'ok', 'gap', 'duplicate', 'stale', 'reset', 'glitch')}
    assert accepted == {'first': False, 'ok': True, 'gap': True, 'duplicate': False,
                        'stale': False, 'reset': False, 'glitch': False}
