"""
Integration: the simulated robot with its description and EKF (mecanum_bringup simulation).

simulation.launch.yaml starts the physics simulator, the control stack, the robot
description and the EKF as separate processes on the simulator's /clock, in lockstep
(simulated time waits for the stack), in the test's own ROS domain. On a slippery floor
(friction 0.1) the wheels slip and wheel odometry loses its heading; the EKF, which
takes the yaw rate from the IMU, must keep it.
"""

import math
import threading
import time

from geometry_msgs.msg import Twist
from mecanum_control.robot_config import default_config_path, load_robot_config
from mecanum_localization.trajectory_error import trajectory_error
from nav_msgs.msg import Odometry
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile
from tf2_msgs.msg import TFMessage

pytestmark = pytest.mark.integration

CONFIG = load_robot_config(default_config_path())


def track(messages, since_s):
    """Return (times s, poses (N, 3)) of odometry messages stamped at or after since_s."""
    rows = []
    for msg in messages:
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        if stamp >= since_s:
            q = msg.pose.pose.orientation
            rows.append((stamp, msg.pose.pose.position.x, msg.pose.pose.position.y,
                         2.0 * math.atan2(q.z, q.w)))
    rows = np.array(rows)
    return rows[:, 0], rows[:, 1:]


def stamp_s(msg):
    """Return a message's header stamp in seconds."""
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def test_frames_are_complete_and_the_ekf_keeps_the_heading_when_wheels_slip(
        start_system, test_node, tmp_path):
    system = start_system('mecanum_bringup', 'simulation.launch.yaml',
                          'floor_friction_coefficient:=0.1', 'lockstep:=true',
                          f'board_port:={tmp_path / "ttySIM"}',
                          f'estop_latch_file:={tmp_path / "estop"}')
    static = []
    latched = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    test_node.node.create_subscription(TFMessage, '/tf_static', static.append, latched)
    truth = test_node.record(Odometry, 'ground_truth/odom')
    wheel_odom = test_node.record(Odometry, 'odom')
    filtered = test_node.record(Odometry, 'odometry/filtered')
    system.wait_for_line(r'\[hardware_interface\].*IMU calibrated at rest', timeout=60)
    system.wait_for_line(r'\[ekf_filter_node\].*EKF started')
    # Both sensors fused (the IMU waits for its mount on /tf_static, which discovery may
    # deliver seconds late: driving before that would test wheel odometry alone).
    system.wait_for_line(r'\[ekf_filter_node\].*odom0 odom: first message taken in')
    system.wait_for_line(r'\[ekf_filter_node\].*imu0 imu/data_raw: first message taken in')
    filtered.wait_for(lambda m: True)

    # The description alone publishes the mounts, once each, as configured.
    transforms = [t for m in static for t in m.transforms]
    pairs = [(t.header.frame_id, t.child_frame_id) for t in transforms]
    for pair in [('base_link', 'base_footprint'), ('base_link', 'laser'),
                 ('base_link', 'imu_link')]:
        assert pairs.count(pair) == 1, pairs
    laser = transforms[pairs.index(('base_link', 'laser'))].transform.translation
    assert (laser.x, laser.y, laser.z) == pytest.approx(
        (CONFIG.lidar_mount_x_m, CONFIG.lidar_mount_y_m, CONFIG.lidar_mount_z_m))

    # Strafe at 0.4 m/s while turning at 2 rad/s (a 0.2 m circle), then stop: the
    # centripetal and ramp accelerations exceed what a 0.1 floor holds, so wheels slip.
    start_s = stamp_s(truth.latest())
    publisher = test_node.node.create_publisher(Twist, 'cmd_vel', 10)
    stop = threading.Event()

    def drive():
        cmd = Twist()
        cmd.linear.y, cmd.angular.z = 0.4, 2.0
        while not stop.is_set():
            publisher.publish(cmd)
            time.sleep(0.05)
    driver = threading.Thread(target=drive, daemon=True)
    driver.start()
    truth.wait_for_new(lambda m: stamp_s(m) > start_s + 6.0, timeout=60)
    stop.set()
    driver.join()
    publisher.publish(Twist())
    truth.wait_for_new(lambda m: stamp_s(m) > start_s + 8.0, timeout=30)

    truth_t, truth_poses = track(truth.since(0.0), start_s)
    errors = {}
    for name, recorder in (('odom', wheel_odom), ('ekf', filtered)):
        times, poses = track(recorder.since(0.0), start_s)
        errors[name] = trajectory_error(truth_t, truth_poses, times, poses)
    print({name: (round(math.degrees(e.final_yaw_rad), 2), round(e.final_position_m, 3))
           for name, e in errors.items()})
    # Wheel odometry is fooled by the slip; the IMU's yaw rate keeps the EKF's heading.
    assert errors['ekf'].final_yaw_rad < math.radians(5.0)
    assert errors['ekf'].final_yaw_rad < 0.5 * errors['odom'].final_yaw_rad
    # Position: a sanity bound (the wheels' slipping velocities still feed it; over a
    # 0.2 m circle the heading error hardly shows in position).
    assert errors['ekf'].final_position_m < 0.25
