"""
Integration: the READMEs' shell examples, run as written.

A README block whose lines end in `# shell N` is a walk-through in several shells: the
commands of every shell but the last keep running (nodes, `ros2 topic echo`), the last
shell's commands run one after the other and must succeed. The commands are read from
the README itself, so an example that stops working (a renamed executable, a topic
that nobody answers, a lost message) fails here. They run with the real `ros2` that
make setup builds (the test process has tools/env.sh's environment, as each shell has
after `source tools/env.sh`), in a leased ROS domain.
"""

from pathlib import Path
import re
import shlex
import subprocess
import time

import pytest
from std_msgs.msg import String
from tests.conftest import (
    SEED_POSITION as POSITION, SEED_SHORTFALL_M, settled_seed_position, TerminalProcess)

pytestmark = [pytest.mark.integration, pytest.mark.usefixtures('needs_ros2')]

REPO = Path(__file__).resolve().parents[1]
SHELL_LINE = re.compile(r'^(?P<command>.+?)\s+# shell (?P<shell>\d+)\b')


def shell_commands(readme: Path, heading: str) -> dict:
    """Return {shell number: [argv, ...]} of the first bash block after heading."""
    text = readme.read_text(encoding='utf-8')
    section = text[text.index(heading):]
    block = re.search(r'```bash\n(.*?)```', section, re.S).group(1)
    shells = {}
    for line in block.splitlines():
        match = SHELL_LINE.match(line)
        assert match, f'{readme}: a line without "# shell N": {line!r}'
        shells.setdefault(int(match['shell']), []).append(shlex.split(match['command']))
    return shells


def test_shell_commands_reads_a_walk_through(tmp_path):
    readme = tmp_path / 'README.md'
    readme.write_text('# x\n## Other\n```bash\nno shell\n```\n## Example\n\n```bash\n'
                      'ros2 run a b      # shell 1\n'
                      'ros2 topic pub --once /t std_msgs/msg/String "{data: \'x y\'}"  '
                      '# shell 2: sends\n'
                      'ros2 topic echo --once /u   # shell 2\n```\n')
    assert shell_commands(readme, '## Example') == {
        1: [['ros2', 'run', 'a', 'b']],
        2: [['ros2', 'topic', 'pub', '--once', '/t', 'std_msgs/msg/String', "{data: 'x y'}"],
            ['ros2', 'topic', 'echo', '--once', '/u']]}


class WalkThrough:
    """The shells of one README block, started in order."""

    def __init__(self, env, test_node):
        self.env = env
        self.test_node = test_node
        self.background = []

    def start(self, argv: list) -> TerminalProcess:
        """Start a command that keeps running; return once it is ready for the next."""
        process = TerminalProcess(argv, self.env, cwd=REPO)
        self.background.append(process)
        if argv[1:3] == ['topic', 'echo']:
            # A user starts the next shell once echo runs; here: once it has subscribed.
            topic = argv[3] if argv[3] != '--once' else argv[4]
            deadline = time.monotonic() + 30
            while self.test_node.node.count_subscribers(topic) == 0:
                assert process.process.poll() is None, process.output()
                assert time.monotonic() < deadline, f'{argv}: no subscription'
                time.sleep(0.05)
        return process

    def run(self, argv: list) -> str:
        """Run a command to its end; it must succeed; return its output."""
        result = subprocess.run(argv, env=self.env, cwd=REPO, capture_output=True, text=True,
                                timeout=60)
        assert result.returncode == 0, f'{shlex.join(argv)}:\n{result.stdout}{result.stderr}'
        return result.stdout

    def play(self, shells: dict) -> list:
        """Start every shell but the last, run the last's commands; return their outputs."""
        *first, last = sorted(shells)
        for shell in first:
            (argv,) = shells[shell]
            self.start(argv)
        return [self.run(argv) for argv in shells[last]]

    def outputs(self) -> str:
        """Return every running command's output so far (for a failure's message)."""
        return '\n'.join(f'--- {shlex.join(process.process.args)}:\n{process.output()}'
                         for process in self.background)

    def stop(self) -> None:
        """Ctrl-C every running command; nodes must exit 0 (ros2cli's own commands: 2)."""
        codes = [(process.process.args, process.stop(), process.output())
                 for process in self.background]
        # ros2cli ends a command interrupted by Ctrl-C with exit code 2 (SIGINT), upstream.
        assert all(code == (2 if args[1] == 'topic' else 0) for args, code, _ in codes), codes


@pytest.fixture
def walk_through(ros_env, test_node):
    """Yield a WalkThrough in the test's ROS domain; stop its commands at the end."""
    shells = WalkThrough(ros_env, test_node)
    yield shells
    for process in shells.background:
        process.close()


def test_the_seed_walk_through_of_the_readme(walk_through, test_node):
    status = test_node.record(String, 'robot_status')
    shells = shell_commands(REPO / 'README.md', "## The seed tutorial's walk-through")
    started = time.monotonic()
    outputs = walk_through.play(shells)
    assert POSITION.search(outputs[-1]), outputs
    x, y, theta = settled_seed_position(status, started, moved_m=0.1)
    assert 0.4 - SEED_SHORTFALL_M < x <= 0.45 and y == 0.0 and theta == 0.0, (x, y, theta)
    walk_through.stop()


def test_the_robot_controller_readme_example(walk_through, test_node):
    status = test_node.record(String, 'robot_status')
    shells = shell_commands(REPO / 'src/robot_controller/README.md', '## Example')
    walk_through.play(shells)
    echo = walk_through.background[-1]
    # 'accepted: strafe left 0.5 m' comes at once: it may go out before robot_controller's
    # publisher has matched the echo (DDS discovery runs both ways; only the echo's side
    # is seen here); 'done' comes 2.5 s later.
    try:
        echo.wait_for_output(r"data: 'done: strafe left'", timeout=30)
    except AssertionError as error:   # once in CI: nothing at all (the command lost?)
        raise AssertionError(f'{error}\n{walk_through.outputs()}') from None
    x, y, theta = settled_seed_position(status, time.monotonic(), moved_m=0.1)
    assert x == 0.0 and 0.5 - SEED_SHORTFALL_M < y <= 0.55 and theta == 0.0, (x, y, theta)
    walk_through.stop()
