"""
simulator_node: the physics simulator of the robot in a world, the source of /clock.

The robot is driven at wheel level, like the real one: the node serves a simulated
ESP32 on a pseudo-terminal (``board_port``, a symlink) speaking the control
package's serial protocol, so hardware_interface, velocity_controller,
encoder_reader and motor_controller run unchanged on top (launch them with
``use_sim_time`` and hardware_interface's ``link_clock: ros``).

Publishes ``/clock`` (rosgraph_msgs/Clock, every ``clock_period_s`` of simulated
time), ``scan`` (sensor_msgs/LaserScan in ``laser_frame_id``, REP-117: +inf no
return), ``ground_truth/odom`` (nav_msgs/Odometry of base_link in the simulator's
``world_frame_id``; for evaluation only, never for the robot's own software) and
``ground_truth/moving_obstacles`` (geometry_msgs/PoseArray: the walking people's centres,
in the world order, with the ground truth while subscribed; evaluation only),
``simulation/collisions`` (std_msgs/UInt32, transient local: the number of
collisions so far) and, with ``publish_laser_tf`` (true), ``/tf_static`` base_link ->
laser as mounted (until the robot description publishes it).
Leaving the world's authorised test zone is logged as an error.
The IMU and the wheel encoders reach ROS through the board, as on the robot.

Faults (issue 31; robot_simulation.faults, robot_simulation.fault_injection): each
message on ``simulator/faults`` (std_msgs/String; reliable, transient local, depth 50:
messages published before the simulator started are taken too) is a JSON object
``{"kind": ..., "onset_s": ..., "duration_s": ..., <params>}`` (parse_fault's mapping,
onset_s ABSOLUTE in simulated seconds, duration_s null or left out: to the end) or a
non-empty JSON list of them. A message is taken whole or not at all: bad JSON, a bad
fault or a 'runner' kind (node_frozen, node_killed, estop) is logged as an error with
the reason and ignored. Each fault is injected where it arises while it acts (logged
``fault lidar_blinded on at 12.0 s for 3 s`` and ``fault lidar_blinded off at 15.0 s``;
a kidnap ``fault kidnap (...) at 12.0 s: the robot moved from ... to ...`` or, when it
would land on an obstacle, an error ``... refused: ...``). ``simulator/active_faults``
(std_msgs/String, reliable, transient local, depth 1) holds the JSON object
``{"time_s", "active": [faults], "started": [...], "ended": [...], "instants": [fault +
"applied", "outcome"]}`` of the last change (``active`` empty at start). While a serial
line fault acts (or delayed bytes are on their way), and after it until a command
comes through again, lockstep does not wait for the board's command, which the line may
lose or delay: the processes' /clock_ack still hold time. The same while the board
sends nothing (``board: firmware`` booting, or reset by its watchdog).

Parameters: ``world`` (name of an installed world or a path; 'apartment'), ``seed``
(0), ``real_time_factor`` (1.0; 0 runs as fast as possible), ``physics_rate_hz``
(200), ``clock_period_s`` (0.02: every node on sim time wakes for each /clock
message, 0.3-0.7 ms of rclpy each, so a 200 Hz clock cost a 13-node stack about half a
core; the fastest timers of the stack run at 50 Hz, once per clock step),
``ground_truth_rate_hz`` (50), lidar
``lidar_beams`` (360), ``lidar_range_max_m`` (12.0), ``lidar_rate_hz`` (10.0),
``lidar_noise_stddev_m`` (0.01), IMU ``imu_gyro_noise_stddev_rad_s`` (0.005),
``imu_accel_noise_stddev_m_s2`` (0.05), ``sensor_noise_scale`` (1.0: multiplies those
three noise levels, 0 = noiseless; scenario sweeps vary it),
``floor_friction_coefficient`` (0: the robot's wheel_friction_coefficient; lower makes
the wheels slip), ``board`` ('core': the firmware's core in this process; 'firmware':
firmware/main.py as flashed, under MicroPython's unix port, stepped with the physics:
robot_simulation.firmware_board; its resets are logged as errors), and the robot
parameters of motor_params.yaml (including the lidar's mount pose). The simulator
never uses sim time itself (it makes it).

Lockstep (``lockstep``, false): simulated time waits for the stack, as PX4's SITL
lockstep does (robot_simulation.lockstep): after each /clock the simulator steps on only
once the board has received a command (MOTOR_EFFORTS) after it and every process on
simulated time has answered it on ``/clock_ack`` (std_msgs/Header; mecanum_control
node_main does it), so a loaded machine slows the run down instead of changing it. A
process that says it is alive on ``/clock_alive`` (once a second) is waited for while
it is busy, up to ``lockstep_give_up_s``. A /clock a process has not answered for
CLOCK_RESEND_S of wall time is published again: a process restarted under the same name
(a respawn) missed it, says it is alive, and would otherwise be waited for until
``lockstep_give_up_s``; the others take the same time again and answer again. A
process named on ``simulator/process_down`` (std_msgs/String: its /clock_ack name; the
scenario runner sends it as it freezes or kills the process) is waited for no longer at
once, so that simulated time runs on while it is down, as wall time would on a robot
(the board neither, until that process answers again: the commands may stop with it).
``real_time_factor`` is then an upper bound (0: as fast as the stack answers). A part
silent for ``lockstep_timeout_s`` wall seconds (10.0; a killed or frozen process) is
waited for no longer, and time runs at real time at most until it answers again; no
board command for ``lockstep_give_up_s`` (60.0) ends the simulator with an error that
names it (exit code 1).
"""

import json
import math
from pathlib import Path
import select
import sys
import threading
import time
from typing import Optional

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose, PoseArray, TransformStamped
from mecanum_control.angles import quaternion_from_yaw
from mecanum_control.board_sim import PtyPort, SerialLine
from mecanum_control.firmware_tree import FirmwareUnavailable
from mecanum_control.messages import planar_odometry
from mecanum_control.node_main import (
    make_executor, release_executor, run_node, signals_deferred)
from mecanum_control.node_reload import EitherEvent
from mecanum_control.parameters import declare_number, declare_robot_config, positive
from mecanum_control.runtime_parameters import read_only_parameters
from nav_msgs.msg import Odometry
import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from robot_simulation.fault_injection import FaultChange, parse_fault_message
from robot_simulation.faults import FaultError
from robot_simulation.lockstep import (
    BOARD, Lockstep, LockstepConfig, LockstepError, PROCESS_DOWN_TOPIC)
from robot_simulation.sensors import ImuConfig, LidarConfig
from robot_simulation.simulator import Simulation, SimulatorConfig
from robot_simulation.world import find_world, load_world
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Header, String, UInt32
from tf2_msgs.msg import TFMessage


#: Wall seconds between two services of ROS callbacks (parameter services) in the
#: stepping loop: spinning costs a wake-up, and nothing here is latency-critical.
SPIN_PERIOD_S = 0.05
#: Lockstep: longest wall time between two looks at the gate's timeouts (s).
GATE_CHECK_S = 0.005
#: Lockstep: longest wait for /clock_ack messages before a look at the serial line (s).
ACK_WAIT_S = 0.001
#: Lockstep: wall seconds before an unanswered /clock is published again (a respawned
#: process missed it). Others take it again harmlessly: the same time, no timer due.
CLOCK_RESEND_S = 1.0


def stamp(time_s: float) -> Time:
    """builtin_interfaces/Time of a simulated time in seconds."""
    sec, nanosec = divmod(int(round(time_s * 1e9)), 10 ** 9)
    return Time(sec=sec, nanosec=nanosec)


class SimulatorNode(Node):
    """Steps the simulation and publishes what its sensors see."""

    #: It drives its own loop (run()), not an executor's spin: never in a node container.
    composable = False

    def __init__(self, **node_options):
        super().__init__('simulator', **node_options)
        if self.get_parameter('use_sim_time').value:
            raise ValueError('the simulator makes /clock: do not set use_sim_time on it')
        robot = declare_robot_config(self)
        declare = self.declare_parameter
        world_path = find_world(str(declare('world', 'apartment').value))
        self.world = load_world(world_path)
        number = lambda name, default: declare_number(self, name, default)  # noqa: E731
        self.real_time_factor = number('real_time_factor', 1.0)
        if not (math.isfinite(self.real_time_factor) and self.real_time_factor >= 0.0):
            raise ValueError(f'real_time_factor must be >= 0 (0: as fast as possible), got '
                             f'{self.real_time_factor}')
        self.clock_period_s = positive('clock_period_s', number('clock_period_s', 0.02))
        self.lockstep = None
        if bool(declare('lockstep', False).value):
            self.lockstep = Lockstep(LockstepConfig(
                timeout_s=number('lockstep_timeout_s', 10.0),
                give_up_s=number('lockstep_give_up_s', 60.0)))
        ground_truth_rate_hz = positive('ground_truth_rate_hz',
                                        number('ground_truth_rate_hz', 50.0))
        noise_scale = number('sensor_noise_scale', 1.0)
        if not (math.isfinite(noise_scale) and noise_scale >= 0.0):
            raise ValueError(f'sensor_noise_scale must be >= 0 (0: noiseless sensors), got '
                             f'{noise_scale}')
        lidar = LidarConfig(
            beams=int(declare('lidar_beams', 360).value),
            range_max_m=number('lidar_range_max_m', 12.0),
            rate_hz=number('lidar_rate_hz', 10.0),
            noise_stddev_m=noise_scale * number('lidar_noise_stddev_m', 0.01),
            mount_x_m=robot.lidar_mount_x_m, mount_y_m=robot.lidar_mount_y_m,
            mount_yaw_rad=robot.lidar_mount_yaw_rad)
        imu = ImuConfig(
            gyro_noise_stddev_rad_s=noise_scale * number('imu_gyro_noise_stddev_rad_s', 0.005),
            accel_noise_stddev_m_s2=noise_scale * number('imu_accel_noise_stddev_m_s2', 0.05))
        seed = int(declare('seed', 0).value)
        if seed < 0:
            raise ValueError(f'parameter seed must be >= 0, got {seed}')
        config = SimulatorConfig(
            physics_rate_hz=number('physics_rate_hz', 200.0), lidar=lidar, imu=imu, seed=seed,
            floor_friction_coefficient=number('floor_friction_coefficient', 0.0),
            board=str(declare('board', 'core').value))
        self.laser_frame_id = str(declare('laser_frame_id', 'laser').value)
        self.world_frame_id = str(declare('world_frame_id', 'world').value)
        self.base_frame_id = str(declare('base_frame_id', 'base_link').value)
        board_port = str(declare('board_port', '').value)

        try:
            self.sim = Simulation(self.world, robot, config)
        except FirmwareUnavailable as error:
            raise ValueError(f'board firmware: {error}') from None
        self._board_events = 0
        self.link = None   # the simulated board's serial line
        if board_port:
            self.link = SerialLine(PtyPort(Path(board_port)), seed=config.seed + 2)
            try:
                self.sim.board.attach(self.link)
            except OSError as error:
                raise ValueError(f'cannot create the board port {board_port}: {error}') from None
        self.scan_period_s = 1.0 / lidar.rate_hz
        self.truth_period_s = 1.0 / ground_truth_rate_hz
        self._next = {'clock': 0.0, 'scan': 0.0, 'truth': 0.0}
        self._reported_collisions = 0
        self._reported_zone_exits = 0

        self.clock_pub = self.create_publisher(Clock, '/clock', 10)
        self._clock_published = False
        self._commands_seen = 0
        self._board_was_unreliable = False
        if self.lockstep is not None:
            if self.link is None:
                raise ValueError('lockstep needs the board link (board_port): the board '
                                 "command is the stack's answer to each /clock")
            reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
            self.ack_sub = self.create_subscription(Header, '/clock_ack', self.on_clock_ack,
                                                    reliable)
            self.alive_sub = self.create_subscription(
                Header, '/clock_alive', self.on_clock_alive, reliable)
            self.down_sub = self.create_subscription(
                String, PROCESS_DOWN_TOPIC, self.on_process_down, reliable)
        self.scan_pub = self.create_publisher(LaserScan, 'scan', 10)
        self.truth_pub = self.create_publisher(Odometry, 'ground_truth/odom', 10)
        self.movers_pub = self.create_publisher(PoseArray, 'ground_truth/moving_obstacles', 10)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.collision_pub = self.create_publisher(UInt32, 'simulation/collisions', latched)
        self.collision_pub.publish(UInt32(data=0))
        control = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.faults_sub = self.create_subscription(String, 'simulator/faults', self.on_faults,
                                                   control)
        self.active_faults_pub = self.create_publisher(String, 'simulator/active_faults',
                                                       latched)
        self.active_faults_pub.publish(String(data=json.dumps(FaultChange(0.0).report())))
        if bool(declare('publish_laser_tf', True).value):
            # Until the robot description publishes it: base_link -> laser, as mounted.
            self.static_tf_pub = self.create_publisher(TFMessage, '/tf_static', latched)
            mount = TransformStamped()
            mount.header.frame_id = self.base_frame_id
            mount.child_frame_id = self.laser_frame_id
            mount.transform.translation.x = lidar.mount_x_m
            mount.transform.translation.y = lidar.mount_y_m
            mount.transform.translation.z = robot.lidar_mount_z_m
            r = mount.transform.rotation
            r.x, r.y, r.z, r.w = quaternion_from_yaw(lidar.mount_yaw_rad)
            self.static_tf_pub.publish(TFMessage(transforms=[mount]))
        x, y, yaw = self.world.robot_start
        mode = '' if self.lockstep is None else (
            ' (at most), lockstep' if self.real_time_factor else ', lockstep')
        where = f'board on {board_port}' if board_port else 'no board link'
        if config.board == 'firmware':
            where += ' (firmware/main.py as flashed, MicroPython unix port, in lockstep)'
        self.get_logger().info(
            f'Simulating world {self.world.name!r} ({world_path}), robot at ({x:.2f}, '
            f'{y:.2f}, {math.degrees(yaw):.0f} deg), physics {config.physics_rate_hz:.0f} Hz, '
            f'real-time factor {self.real_time_factor or "max"}{mode}, {where}')
        read_only_parameters(self)

    def on_clock_ack(self, msg: Header) -> None:
        """Take a process's answer to a /clock (lockstep)."""
        self.lockstep.ack(msg.frame_id, msg.stamp.sec + msg.stamp.nanosec * 1e-9,
                          time.monotonic())

    def on_clock_alive(self, msg: Header) -> None:
        """Take a process's sign of life (lockstep: a busy process is waited for)."""
        self.lockstep.alive(msg.frame_id, time.monotonic())

    def on_process_down(self, msg: String) -> None:
        """Take a process as gone now (lockstep): the scenario runner froze or killed it."""
        self.lockstep.down(msg.data, 'stopped or killed, says the scenario runner')

    def on_faults(self, msg: String) -> None:
        """Schedule the faults of a control message (a bad one is logged and ignored)."""
        try:
            faults = parse_fault_message(msg.data)
        except (FaultError, TypeError, ValueError) as error:
            self.get_logger().error(f'fault message ignored: {error}')
            return
        for fault in faults:
            note = self.sim.add_fault(fault)
            if note is None:
                self.get_logger().info(f'fault {fault.describe()} scheduled (now '
                                       f'{self.sim.time_s:.3f} s)')
            else:
                self.get_logger().warning(note)

    def report_faults(self) -> None:
        """Log the fault changes of the last step and publish the faults acting."""
        changes, self.sim.fault_changes = self.sim.fault_changes, []
        for change in changes:
            for level, text in change.log_lines():
                if level == 'error':   # rclpy: one severity per call site
                    self.get_logger().error(text)
                else:
                    self.get_logger().info(text)
            self.active_faults_pub.publish(String(data=json.dumps(change.report())))

    def advance(self) -> None:
        """One physics step (the board's loop runs in it), then everything due now."""
        sim = self.sim
        sim.step()
        if sim.fault_changes:
            self.report_faults()
        events = sim.board.events
        if len(events) != self._board_events:   # the firmware's resets (board firmware)
            for at_s, text in events[self._board_events:]:
                self.get_logger().error(f'{text} (at {at_s:.3f} s)')
            self._board_events = len(events)
        now = sim.time_s
        if now + 1e-9 >= self._next['clock']:
            self._next['clock'] += self.clock_period_s
            self.clock_pub.publish(Clock(clock=stamp(now)))
            self._clock_published = True
        if now + 1e-9 >= self._next['truth']:
            self._next['truth'] += self.truth_period_s
            self.publish_ground_truth(now)
        if now + 1e-9 >= self._next['scan']:
            self._next['scan'] += self.scan_period_s
            self.publish_scan(now)
        if sim.left_test_zone_count != self._reported_zone_exits:
            self._reported_zone_exits = sim.left_test_zone_count
            state = sim.physics.state
            self.get_logger().error(
                f'The robot left the authorised test zone at ({state.x:.2f}, {state.y:.2f}) '
                f'(exit #{sim.left_test_zone_count})')
        if sim.collision_count != self._reported_collisions:
            self._reported_collisions = sim.collision_count
            state = sim.physics.state
            self.get_logger().warning(
                f'Collision #{sim.collision_count} at ({state.x:.2f}, {state.y:.2f})')
            self.collision_pub.publish(UInt32(data=sim.collision_count))

    def publish_scan(self, now: float) -> None:
        """Publish one lidar scan (as the lidar's faults leave it: maybe none)."""
        ranges = self.sim.lidar_output()
        if ranges is None:
            return
        lidar = self.sim.lidar
        config = lidar.config
        msg = LaserScan()
        msg.header.stamp = stamp(now + self.sim.faults.effects.scan_stamp_offset_s)
        msg.header.frame_id = self.laser_frame_id
        msg.angle_min = float(config.angle_min_rad)
        msg.angle_increment = float(lidar.angle_increment_rad)
        msg.angle_max = float(lidar.last_beam_angle_rad)
        msg.time_increment = 0.0  # every beam is cast from the same pose (no sweep skew)
        msg.scan_time = float(lidar.scan_time_s)
        msg.range_min = float(config.range_min_m)
        msg.range_max = float(config.range_max_m)
        msg.ranges = ranges.tolist()
        self.scan_pub.publish(msg)

    def publish_ground_truth(self, now: float) -> None:
        """Publish the true pose and body twist (evaluation only)."""
        state = self.sim.physics.state
        msg = planar_odometry(stamp(now), self.world_frame_id, self.base_frame_id,
                              (state.x, state.y, state.yaw), (state.vx, state.vy, state.wz))
        self.truth_pub.publish(msg)
        if self.sim.world.moving_obstacles and self.movers_pub.get_subscription_count() > 0:
            movers = PoseArray()
            movers.header = msg.header
            for x, y, _ in self.sim.moving_circles():
                pose = Pose()
                pose.position.x, pose.position.y = float(x), float(y)
                movers.poses.append(pose)
            self.movers_pub.publish(movers)

    def run(self, until: Optional[threading.Event] = None) -> None:
        """
        Step, paced to real_time_factor, serving ROS callbacks every SPIN_PERIOD_S.

        Until Ctrl-C/SIGTERM (KeyboardInterrupt) or until is set (returns: a reload).
        """
        executor = make_executor(self.context)
        executor.add_node(self)
        start = next_spin = time.monotonic()
        start_sim_s = self.sim.time_s
        factor = self._pace_factor()
        # Ctrl-C or SIGTERM: the step in progress ends, then KeyboardInterrupt.
        with signals_deferred() as interrupted:
            stop = EitherEvent(interrupted, until)
            try:
                while rclpy.ok() and not stop.is_set():
                    self.advance()
                    if self.lockstep is not None and self._clock_published:
                        self._clock_published = False
                        self._take_board_commands()   # those before this /clock answer none
                        self.lockstep.published(self.sim.time_s, time.monotonic())
                        if self._board_unreliable():
                            # A serial fault may lose or delay the command: the wire answers.
                            self.lockstep.board_command(time.monotonic())
                        if self.wait_for_stack(executor, stop):
                            next_spin = time.monotonic() + SPIN_PERIOD_S
                        # else nobody owed an answer (none known yet, or the board
                        # alone before it answers): spin on SPIN_PERIOD_S as without
                        # lockstep, or no process's first /clock_ack is ever taken.
                    now = time.monotonic()
                    if now >= next_spin:  # parameter services; spinning every step costs 3x
                        executor.spin_once(timeout_sec=0.0)
                        next_spin = now + SPIN_PERIOD_S
                    if self._pace_factor() != factor:   # lockstep engaged or a part gone
                        factor = self._pace_factor()
                        start, start_sim_s = now, self.sim.time_s
                    if factor > 0.0:
                        wait = start + (self.sim.time_s - start_sim_s) / factor - now
                        if wait > 0.0:
                            time.sleep(wait)
                        elif wait < -0.25:
                            # Stalled (load, debugger, lockstep): do not race to catch up,
                            # which would flood the control stack with /clock; carry on.
                            start, start_sim_s = now, self.sim.time_s
                            if self.lockstep is None:
                                self.get_logger().warning(
                                    f'Simulation fell {-wait:.2f} s behind real_time_factor '
                                    f'{self.real_time_factor}; continuing from now',
                                    throttle_duration_sec=10.0)
            finally:
                release_executor(executor)   # while signals are deferred
                executor = None

    def _pace_factor(self) -> float:
        """Return the real-time factor to pace at (0: none); at most 1 while unlocked."""
        if self.lockstep is not None and self.lockstep.free_running:
            return min(self.real_time_factor, 1.0) if self.real_time_factor > 0.0 else 1.0
        return self.real_time_factor

    def _take_board_commands(self) -> float:
        """Tell lockstep about the board commands received since the last call; return now."""
        now = time.monotonic()
        commands = self.sim.board.commands_received
        if commands != self._commands_seen:
            self._commands_seen = commands
            self.lockstep.board_command(now)
            if self._board_was_unreliable and not self._board_unreliable_now():
                self._board_was_unreliable = False   # a command came through a clean line
        return now

    def _board_unreliable(self) -> bool:
        """
        Tell whether the board's command cannot gate simulated time (lockstep).

        True while a serial fault acts or delayed bytes are on their way, or the board
        sends nothing (the flashed firmware booting or reset: the host stops commanding
        a silent board), and after that until a command comes through the clean line
        (hardware_interface may have lost the link meanwhile: it reconnects on simulated
        time). Never before the board first answered.
        """
        if self._board_unreliable_now():
            self._board_was_unreliable = True
        return self._board_was_unreliable and self._commands_seen > 0

    def _board_unreliable_now(self) -> bool:
        """Tell whether a serial fault acts or the board is silent (booting, reset)."""
        return self.link.faulty or not self.sim.board.reporting

    def wait_for_stack(self, executor, stop) -> bool:
        """
        Lockstep: return once the stack has answered the /clock just published.

        Takes the board's commands from the serial line and the /clock_ack messages
        meanwhile; raises LockstepError when the board has stopped answering for good.
        Returns whether it spun the executor (nobody owed an answer: it did not).
        """
        gate, link, board = self.lockstep, self.link, self.sim.board
        resend_at = time.monotonic() + CLOCK_RESEND_S
        spun = False
        while not stop.is_set():
            board.receive()
            now = self._take_board_commands()
            missing = gate.waiting_for(now)
            for event in gate.events():
                # rclpy: one severity per call site.
                if 'not answered' in event:
                    self.get_logger().warning(event)
                else:
                    self.get_logger().info(event)
            if not missing:
                return spun
            spun = True
            if now >= resend_at and missing != [BOARD]:
                # A respawned process subscribed after this /clock went out.
                resend_at = now + CLOCK_RESEND_S
                self.clock_pub.publish(Clock(clock=stamp(self.sim.time_s)))
            # Block on what is missing instead of polling both: the processes answer
            # /clock as soon as they take it, the board's command comes after the control
            # chain has run, so most of the wait is for the serial line alone.
            if missing == [BOARD] and link.port.plugged:
                select.select([link.port.master], [], [], GATE_CHECK_S)
                executor.spin_once(timeout_sec=0.0)  # what else came (acks of parts back)
            else:
                executor.spin_once(
                    timeout_sec=ACK_WAIT_S if BOARD in missing else GATE_CHECK_S)
        return spun

    def close(self) -> None:
        """Unplug the simulated board (removes its link); stop its firmware."""
        if self.link is not None and self.link.port.plugged:
            self.link.port.unplug()
        sim = getattr(self, 'sim', None)
        if sim is not None:
            sim.close()


def main(args=None) -> int:
    """Run the simulator until Ctrl-C or SIGTERM."""
    return run_node(SimulatorNode, 'simulator', args, spin=_run)


def _run(node: SimulatorNode, until: Optional[threading.Event] = None) -> None:
    """Run the simulation; a stack that stopped answering ends it with an error."""
    try:
        node.run(until)
    except LockstepError as error:
        node.get_logger().fatal(str(error))
        raise SystemExit(1) from None


if __name__ == '__main__':
    sys.exit(main())
