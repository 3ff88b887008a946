"""Control nodes refuse bad parameters with one clear line and exit code 2, no traceback."""

from pathlib import Path
import re
import subprocess

from mecanum_control.robot_config import default_config_path, load_robot_config
import pytest

pytestmark = pytest.mark.integration

CASES = [
    ('motor_controller', '/**:\n  ros__parameters:\n    wheel_radius_m: -0.04\n',
     'robot parameter wheel_radius_m must be finite and > 0'),
    ('encoder_reader', '/**:\n  ros__parameters:\n    wheel_radius_m: [oops\n',
     "cannot start: .*Couldn't parse params file"),
    ('hardware_interface', '/**:\n  ros__parameters:\n    wheel_radius_m: abc\n',
     "Trying to set parameter 'wheel_radius_m' to 'abc' of type 'STRING'"),
    ('velocity_controller', 'velocity_controller:\n  ros__parameters:\n    kp: -1.0\n',
     'PidGains.kp must be a finite number >= 0'),
    ('hardware_interface', 'hardware_interface:\n  ros__parameters:\n    command_rate_hz: 2.0\n',
     'command_rate_hz 2.0 is too slow for the board timeout of '
     f'{load_robot_config(default_config_path()).board_command_timeout_ms} ms'),
]


@pytest.mark.parametrize('executable, params, message', CASES)
def test_bad_parameters_stop_the_node_with_a_clear_message(ros_env, tmp_path, executable,
                                                             params, message):
    """Each case: the node exits 2, prints the reason at FATAL level and no traceback."""
    params_file = tmp_path / 'params.yaml'
    params_file.write_text(params)
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_control', executable, '--ros-args', '--params-file',
         str(params_file)], env=ros_env, capture_output=True, text=True, timeout=60,
        cwd=str(Path(__file__).resolve().parents[1]))
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert 'Traceback' not in output
    assert re.search(r'\[FATAL\].*' + message, output), output
