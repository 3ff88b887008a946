"""
board_check --calibrate: the numbers (worked by hand) and a whole run on a pty (no ROS).

The whole run plays a fresh robot on a stand: the firmware's own core (board_core) on
a real pty, over four wheels whose gearbox is 34:1 (1496 counts per turn, the config
says 30:1), FR's encoder wired backwards and RL's motor wired backwards. The person
turning the wheels by hand is the test (board_check.ask_user).
"""

import math
from pathlib import Path
import shutil
import threading
import time

from mecanum_control import board_check
from mecanum_control.board_calibration import (
    board_config_text, calibrate, CalibrationError, motor_params_text, unified_diff)
from mecanum_control.board_model import BoardModel, MotorModel
from mecanum_control.board_params import board_params
from mecanum_control.board_sim import PtyPort, SerialLine, SimulatedBoard
from mecanum_control.robot_config import default_config_path, load_robot_config
import pytest

REPO = Path(__file__).resolve().parents[3]
BOARD_CONFIG = REPO / 'firmware' / 'board_config.py'
ROBOT = load_robot_config(default_config_path())


# --- the numbers ----------------------------------------------------------------------


def test_counts_per_turn_gear_ratio_and_flips_worked_by_hand():
    """10 turns: 14960 counts = 1496 per turn (44 x 34); signs give the flips."""
    result = calibrate([14960, -14960, 14960, 14950], 10, [300, -300, -280, 310], 0.2, 44)
    assert result.counts_per_wheel_rev == (1496.0, 1496.0, 1496.0, 1495.0)
    assert result.gear_ratio == 34.0    # median 1496 / 44
    assert result.flip_encoder == (False, True, False, False)
    # FR's spin counted -300 with its encoder backwards: the wheel went forward.
    assert result.flip_motor == (False, False, True, False)
    assert result.warnings == ()
    assert 'RL: 1496.0 counts per wheel turn; flip the motor invert' in result.lines()


def test_a_wheel_far_from_the_others_is_named():
    """A miscounted turn (11 instead of 10) shows as FL 10 % off the median, alone."""
    result = calibrate([14520, 13200, 13200, 13200], 10, [300] * 4, 0.2, 44)
    assert len(result.warnings) == 1 and result.warnings[0].startswith(
        'FL counts 1452.0 per turn, +10.0 %')
    assert result.gear_ratio == 30.0


@pytest.mark.parametrize('hand, spins, message', [
    ([13200, 0, 13200, 13200], [300] * 4, 'no counts when turned by hand: FR'),
    ([13200] * 4, [300, 300, 0, 300], 'RL did not turn in its spin'),
    ([13200] * 4, [300, 300, 100, 300], 'RL did not turn in its spin'),   # < 0.1 turn
])
def test_a_wheel_that_did_not_count_or_turn_gives_no_calibration(hand, spins, message):
    with pytest.raises(CalibrationError, match=message):
        calibrate(hand, 10, spins, 0.2, 44)


def test_files_keep_every_other_line_and_flips_go_both_ways():
    """gear_ratio alone changes in the YAML; two flips give back the same file."""
    params = (default_config_path()).read_text()
    changed = motor_params_text(params, 34.0)
    diff = [line for line in unified_diff(params, changed, 'p').splitlines()
            if line[:1] in '+-' and not line.startswith(('+++', '---'))]
    assert diff == ['-    gear_ratio: 30.0', '+    gear_ratio: 34.0']
    wiring = BOARD_CONFIG.read_text()
    once = board_config_text(wiring, [False, True, False, False], [True, False, False, True])
    assert "{'pwm': 32, 'in1': 33, 'in2': 14, 'invert': False},   # FR" in once
    assert "{'a': 34, 'b': 35, 'invert': True},    # FL" in once
    assert board_config_text(once, [False, True, False, False],
                             [True, False, False, True]) == wiring
    with pytest.raises(CalibrationError, match='MOTORS has 3 wheel lines'):
        board_config_text(wiring.replace("    {'pwm': 4,", "    # {'pwm': 4,"),
                          [True] * 4, [True] * 4)


# --- a whole run on a pty --------------------------------------------------------------


class RobotOnAStand:
    """Four free wheels: a 34:1 gearbox, FR's encoder and RL's motor wired backwards."""

    COUNTS_PER_TURN = 44 * 34

    def __init__(self):
        self.model = BoardModel(
            geometry=ROBOT.geometry,
            motor=MotorModel(ROBOT.motor_no_load_speed_rad_s, ROBOT.motor_time_constant_s),
            rad_per_count=2 * math.pi / self.COUNTS_PER_TURN)
        self.encoder_sign = (1, -1, 1, 1)
        self.motor_sign = (1, 1, -1, 1)
        self.lock = threading.Lock()

    @property
    def time_us(self) -> int:
        return self.model.time_us

    @property
    def ticks(self):
        return tuple(s * t for s, t in zip(self.encoder_sign, self.model.ticks))

    def imu(self):
        return self.model.imu()

    @property
    def efforts(self):
        return self.model.efforts

    @efforts.setter
    def efforts(self, values):
        self.model.efforts = [s * e for s, e in zip(self.motor_sign, values)]

    def turn_by_hand(self, wheel: int, turns: float) -> None:
        """Turn a wheel forward by hand over 0.5 s (motors off)."""
        for _ in range(50):
            with self.lock:
                self.model.wheels[wheel].angle_rad += 2 * math.pi * turns / 50
            time.sleep(0.01)


@pytest.fixture
def stand(tmp_path):
    """Serve the robot's board (board_core) on a pty in real time, in a thread."""
    robot = RobotOnAStand()
    link = tmp_path / 'ttyESP32'
    line = SerialLine(PtyPort(link))
    board = SimulatedBoard(robot, board_params(ROBOT), line)
    line.plug()
    running = threading.Event()
    running.set()

    def loop():
        last = time.monotonic()
        while running.is_set():
            now = time.monotonic()
            with robot.lock:
                robot.model.step(now - last)
            last = now
            board.poll()
            time.sleep(0.002)
    thread = threading.Thread(target=loop, daemon=True)
    thread.start()
    yield robot, link
    running.clear()
    thread.join()
    line.port.unplug()


def test_calibrate_measures_a_fresh_robot_and_writes_both_files(
        stand, tmp_path, monkeypatch, capsys):
    robot, link = stand
    params = tmp_path / 'motor_params.yaml'
    shutil.copy(default_config_path(), params)
    wiring = tmp_path / 'board_config.py'
    shutil.copy(BOARD_CONFIG, wiring)
    asked = []

    def person(prompt: str) -> str:
        asked.append(prompt)
        if 'Write these changes' in prompt:
            return 'y'
        wheel = next(i for i, name in enumerate(board_check.WHEELS)
                     if prompt.strip().startswith(name + ':'))
        robot.turn_by_hand(wheel, 10)
        return ''
    monkeypatch.setattr(board_check, 'ask_user', person)
    code = board_check.main(['--port', str(link), '--calibrate', '--config', str(params),
                             '--board-config', str(wiring), '--spin-seconds', '0.5'])
    out = capsys.readouterr().out
    assert code == 0, out
    assert len(asked) == 5 and 'exactly 10 turns' in asked[0]
    # The diff was shown before the question; the files say what was measured.
    assert out.index('+    gear_ratio: 34.0') < out.index('wrote')
    assert load_robot_config(params).gear_ratio == 34.0
    text = wiring.read_text()
    assert "{'a': 36, 'b': 39, 'invert': False},   # FR" in text      # encoder flipped
    assert "{'pwm': 4, 'in1': 16, 'in2': 17, 'invert': True},     # RL" in text
    unchanged = [line for line in text.splitlines() if "'invert'" in line and (
        '# FR' not in line or "'pwm'" in line) and ('# RL' not in line or "'a'" in line)]
    assert all(line in BOARD_CONFIG.read_text() for line in unchanged)


def test_calibrate_writes_nothing_without_a_yes(stand, tmp_path, monkeypatch, capsys):
    robot, link = stand
    params = tmp_path / 'motor_params.yaml'
    shutil.copy(default_config_path(), params)
    wiring = tmp_path / 'board_config.py'
    shutil.copy(BOARD_CONFIG, wiring)

    def person(prompt: str) -> str:
        if 'Write these changes' in prompt:
            return ''
        robot.turn_by_hand(board_check.WHEELS.index(prompt.split(':')[0].strip()), 10)
        return ''
    monkeypatch.setattr(board_check, 'ask_user', person)
    assert board_check.main(['--port', str(link), '--calibrate', '--config', str(params),
                             '--board-config', str(wiring), '--spin-seconds', '0.5']) == 0
    assert 'nothing written' in capsys.readouterr().out
    assert params.read_text() == default_config_path().read_text()
    assert wiring.read_text() == BOARD_CONFIG.read_text()


def test_calibrate_refuses_without_a_terminal():
    """Piped stdin: nobody can turn the wheels; a clear error, not a hang."""
    import subprocess
    import sys
    result = subprocess.run(
        [sys.executable, '-m', 'mecanum_control.board_check', '--port', '/dev/null',
         '--calibrate'], stdin=subprocess.DEVNULL, capture_output=True, text=True,
        timeout=60)
    assert result.returncode == 2 and 'run it at a terminal' in result.stderr
