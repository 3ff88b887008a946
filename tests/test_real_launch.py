"""
Integration: every installed ``.launch.py`` starts its whole system under the real ROS 2 launch.

The robot's Raspberry Pi runs ``ros2 launch`` from an apt ROS 2 Jazzy install; the pip
setup has no ``launch`` package and runs the same ``.launch.yaml`` files with
mecanum_bringup's launch_runner, which once accepted what the real launch rejects (a
quoted ``respawn_delay``, ``use_sim_time`` passed as the string 'true'). So these tests
use the upstream Jazzy launch, launch_yaml, launch_xml and launch_ros that make setup
built (tools/ros2_upstream.py), or, without them, build them (the sources in
``shared/vendor`` beside the repository or in a folder above it, or
``$MECANUM_LAUNCH_VENDOR``; the tests skip, saying so, where they are absent) into a
prefix under build/ with colcon, and run each launch file
through the real LaunchService (tests/real_launch/run_launch_file.py) with its default
arguments, in a ROS domain of its own:

* it loads (no error from the real frontend);
* every node that the pip runner's reading of the same file (system_description)
  lists is started, and every named node appears in the ROS graph (it got through its
  parameters);
* no process exits until the test stops the launch with SIGINT (Ctrl-C), and then
  every process ends by itself within launch's 5 s (no escalation to SIGTERM), exits
  0, no ERROR line is printed, and nothing is left running.
"""

import fcntl
import hashlib
import importlib.util
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import tarfile
import threading
import time

from mecanum_bringup.system_description import load_system
import pytest

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
TARBALL_FOLDER = Path('shared') / 'vendor'


def vendor_folder() -> Path:
    """Return $MECANUM_LAUNCH_VENDOR, else the first shared/vendor beside the repo or above."""
    if os.environ.get('MECANUM_LAUNCH_VENDOR'):
        return Path(os.environ['MECANUM_LAUNCH_VENDOR'])
    for folder in REPO.parents:
        if (folder / TARBALL_FOLDER).is_dir():
            return folder / TARBALL_FOLDER
    return REPO.parent / TARBALL_FOLDER


VENDOR = vendor_folder()
TARBALLS = ('ros2-launch-jazzy-3.4.3.tar.gz', 'ros2-launch_yaml-jazzy-3.4.3.tar.gz',
            'ros2-launch_xml-jazzy-3.4.3.tar.gz', 'ros2-launch_ros-jazzy-0.26.6.tar.gz')
DRIVER = REPO / 'tests' / 'real_launch' / 'run_launch_file.py'
LAUNCH_FILES = sorted(REPO.glob('src/*/launch/*.launch.py'))
#: Launch arguments for a file (by package/file name) beyond its defaults.
LAUNCH_ARGUMENTS = {
    # The keyboard node opens in `terminal` (xterm by default): a pty instead here.
    'mecanum_control/teleop.launch.py': [
        f'terminal:={sys.executable} {REPO / "tests" / "real_launch" / "in_a_pty.py"}'],
}
#: More runs of a file with other arguments: (package/file, arguments).
EXTRA_RUNS = [
    # The simulated robot on the firmware as flashed (main.py under MicroPython): it
    # boots through its 2 s REPL window, which must not read as an error.
    ('robot_simulation/simulation.launch.py', ['board:=firmware']),
]
#: Executables that start no ROS node (the emulated ESP32 board on its pty).
NOT_ROS_NODES = {'board_emulator'}
#: Wall seconds for a whole system to start and every named node to join the graph.
START_TIMEOUT_S = 90.0
#: Wall seconds every process must then stay up (a parameter error kills at start-up).
STAY_UP_S = 3.0
#: Wall seconds after Ctrl-C after which a process that has not ended counts as stuck
#: (launch escalates to SIGTERM at 5 s).
STUCK_AFTER_SIGINT_S = 4.5


def build_real_launch() -> Path:
    """Build the vendor's launch packages into build/real_launch/<digest>; return the prefix."""
    missing = [name for name in TARBALLS if not (VENDOR / name).is_file()]
    if missing:
        pytest.skip(f'the ROS 2 Jazzy launch sources are not here ({VENDOR}: no '
                    f'{", ".join(missing)}); set MECANUM_LAUNCH_VENDOR to their folder')
    digest = hashlib.sha256(b''.join((VENDOR / n).read_bytes() for n in TARBALLS)).hexdigest()
    base = REPO / 'build' / 'real_launch'
    base.mkdir(parents=True, exist_ok=True)
    prefix = base / digest[:16]
    with open(base / 'lock', 'a') as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (prefix / 'built').exists():
            source = prefix / 'src'
            source.mkdir(parents=True, exist_ok=True)
            for name in TARBALLS:
                with tarfile.open(VENDOR / name) as archive:
                    archive.extractall(source, filter='data')
            result = subprocess.run(
                [sys.executable, '-m', 'colcon', '--log-base', str(prefix / 'log'), 'build',
                 '--merge-install', '--base-paths', str(source),
                 '--build-base', str(prefix / 'build'), '--install-base', str(prefix / 'install'),
                 '--event-handlers', 'console_cohesion-', 'summary-'],
                capture_output=True, text=True, timeout=600)
            assert result.returncode == 0, result.stdout + result.stderr
            (prefix / 'built').touch()
    return prefix / 'install'


@pytest.fixture(scope='module')
def real_launch_env():
    """
    Return os.environ with the real launch packages on PYTHONPATH and the ament index.

    make setup builds them into .venv/ros2cli (tools/ros2_upstream.py), which the
    environment has on its paths (tools/env.sh): then they are used as they are;
    otherwise they are built here from the vendor's tarballs.
    """
    if all(importlib.util.find_spec(name) is not None
           for name in ('launch', 'launch_yaml', 'launch_ros')):
        return dict(os.environ)
    install = build_real_launch()
    site = next(install.glob('lib/python3*/site-packages'))
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(site), env.get('PYTHONPATH')]))
    env['AMENT_PREFIX_PATH'] = os.pathsep.join(
        filter(None, [str(install), env.get('AMENT_PREFIX_PATH')]))
    return env


def installed(launch_file: Path) -> Path:
    """Return the installed copy of a source launch file (as ros2 launch finds it)."""
    package = launch_file.parents[1].name
    return REPO / 'install' / package / 'share' / package / 'launch' / launch_file.name


class LaunchOutput:
    """The driver's event lines (START name pid, EXIT name code), read in a thread."""

    def __init__(self, process: subprocess.Popen):
        self.lines = []
        self._condition = threading.Condition()
        self._thread = threading.Thread(target=self._read, args=(process,), daemon=True)
        self._thread.start()

    def _read(self, process) -> None:
        for line in process.stdout:
            with self._condition:
                self.lines.append(line.rstrip('\n'))
                self._condition.notify_all()

    def events(self, kind: str):
        """Return (name, value) of every event line of a kind (START or EXIT)."""
        with self._condition:
            return [tuple(line.split()[1:3]) for line in self.lines
                    if line.startswith(kind + ' ') and len(line.split()) == 3]

    def wait(self, predicate, timeout_s: float) -> bool:
        """Wait until predicate() is true (re-checked at each new line and every 0.1 s)."""
        deadline = time.monotonic() + timeout_s
        with self._condition:
            while not predicate():
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._condition.wait(min(left, 0.1))
        return True


def graph_names(test_node) -> set:
    """Return the full names of the nodes in the test's ROS graph."""
    return {(ns.rstrip('/') + '/' + name) for name, ns
            in test_node.node.get_node_names_and_namespaces()}


def file_id(launch_file: Path) -> str:
    """Return 'package/file.launch.py'."""
    return f'{launch_file.parents[1].name}/{launch_file.name}'


RUNS = [pytest.param(path, LAUNCH_ARGUMENTS.get(file_id(path), []), id=file_id(path))
        for path in LAUNCH_FILES] + [
    pytest.param(REPO / 'src' / name.split('/')[0] / 'launch' / name.split('/')[1],
                 arguments, id=f'{name} {" ".join(arguments)}')
    for name, arguments in EXTRA_RUNS]


def dump_the_stacks_of_stuck_processes(output: LaunchOutput) -> None:
    """
    SIGQUIT the processes still running STUCK_AFTER_SIGINT_S after Ctrl-C.

    Each process prints every thread's Python stack (node_main registers faulthandler
    for SIGQUIT) to its stderr, which launch shows, then quits: the test fails and its
    report says where the process waited, which its SIGINT and SIGTERM handlers, not
    reached while it is stuck in C code, never could.
    """
    def all_ended():
        return len(output.events('EXIT')) >= len(output.events('START'))

    if output.wait(all_ended, STUCK_AFTER_SIGINT_S):
        return
    ended = {name for name, _ in output.events('EXIT')}
    for name, pid in output.events('START'):
        if name not in ended:
            try:
                os.kill(int(pid), signal.SIGQUIT)
            except ProcessLookupError:
                pass
    output.wait(all_ended, 5.0)


@pytest.mark.parametrize('launch_file, arguments', RUNS)
def test_the_real_launch_starts_the_whole_system(launch_file, arguments, real_launch_env,
                                                 ros_env, marked_env, test_node):
    path = installed(launch_file)
    assert path.exists(), f'{path} is not installed: run colcon build (make setup)'
    system = load_system(path, dict(argument.split(':=', 1) for argument in arguments))
    # launch names a process after its command's first word: the launch-prefix's, if any.
    executables = sorted(Path((node.launch_prefix or [node.executable])[0]).name
                         for node in system.nodes)
    named = {'/' + '/'.join(filter(None, [node.namespace.strip('/') if node.namespace
                                          else '', node.name]))
             for node in system.nodes if node.name and node.executable not in NOT_ROS_NODES}
    env = dict(real_launch_env, ROS_DOMAIN_ID=ros_env['ROS_DOMAIN_ID'],
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', **{
                   key: value for key, value in marked_env.env.items()
                   if key not in real_launch_env})
    # A process group of its own: Ctrl-C in a terminal reaches launch and every process it
    # started (launch then sends them no SIGINT of its own: it waits, then escalates).
    process = subprocess.Popen([sys.executable, str(DRIVER), str(path), *arguments], env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    errors = []
    threading.Thread(target=lambda: errors.extend(process.stderr), daemon=True).start()
    output = LaunchOutput(process)

    def report() -> str:
        """Return the driver's event lines and the end of the launch's output, as of now."""
        return '\n'.join(output.lines) + '\n' + ''.join(errors[-80:])

    try:
        def started():
            names = sorted(re.sub(r'-\d+$', '', name) for name, _ in output.events('START'))
            return names == executables

        def all_up():
            return (started() and named <= graph_names(test_node)) or bool(
                output.events('EXIT')) or process.poll() is not None

        output.wait(all_up, START_TIMEOUT_S)
        assert process.poll() is None, f'the launch ended by itself:\n{report()}'
        assert output.events('EXIT') == [], f'a process died:\n{report()}'
        assert started(), f'expected {executables}:\n{report()}'
        assert named <= graph_names(test_node), (
            f'not in the graph: {sorted(named - graph_names(test_node))}\n{report()}')
        output.wait(lambda: bool(output.events('EXIT')), STAY_UP_S)
        assert output.events('EXIT') == [], f'a process died:\n{report()}'
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGINT)     # Ctrl-C
            dump_the_stacks_of_stuck_processes(output)
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    assert process.returncode == 0, report()
    launch_log = ''.join(errors)
    assert 'Traceback' not in launch_log, report()
    # Ctrl-C ends every process by itself, in launch's 5 s: no escalation to SIGTERM,
    # no process that died, no ERROR line; each exits 0.
    assert 'SIGTERM' not in launch_log and 'process has died' not in launch_log, report()
    assert '[ERROR]' not in launch_log, report()
    assert sorted({code for _, code in output.events('EXIT')}) == ['0'], report()
    assert marked_env.leftovers() == []
