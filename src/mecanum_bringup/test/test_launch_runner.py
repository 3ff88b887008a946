"""Tests of the process supervisor with real processes (plain scripts, no ROS)."""

import io
import os
from pathlib import Path
import signal
import subprocess
import sys
import textwrap
import threading
import time

from mecanum_bringup.launch_runner import find_executable, Supervisor
from mecanum_bringup.system_description import NodeProcess, System
import pytest


def make_executable(prefix: Path, package: str, name: str, script: str) -> None:
    path = prefix / 'lib' / package / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text('#!/bin/bash\n' + textwrap.dedent(script))
    path.chmod(0o755)


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f'/proc/{pid}/stat') as stat:
        return stat.read().split()[2] != 'Z'


@pytest.fixture
def prefix(tmp_path):
    make_executable(tmp_path, 'demo', 'talker', """
        echo "talker args: $*"
        while true; do sleep 0.05; done
        """)
    make_executable(tmp_path, 'demo', 'quitter', """
        echo "quitting with 3"; exit 3
        """)
    make_executable(tmp_path, 'demo', 'stubborn', """
        trap 'echo ignoring SIGINT' INT
        sleep 1000 &
        echo "child $!"
        while true; do sleep 0.05; done
        """)
    return tmp_path


def environ(prefix):
    return dict(os.environ, AMENT_PREFIX_PATH=str(prefix))


def run_in_thread(supervisor):
    """Run the supervisor in a daemon thread, so a failing test cannot hang pytest."""
    result = {}
    thread = threading.Thread(target=lambda: result.setdefault('code', supervisor.run()),
                              daemon=True)
    thread.start()
    return thread, result


def wait_for(predicate, timeout=10.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return False


def test_find_executable(prefix):
    assert find_executable('demo', 'talker', environ(prefix)) == prefix / 'lib/demo/talker'
    with pytest.raises(FileNotFoundError, match='not found'):
        find_executable('demo', 'missing', environ(prefix))


def test_output_is_prefixed_and_shutdown_on_exit_returns_code(prefix):
    out = io.StringIO()
    system = System(nodes=[
        NodeProcess('demo', 'talker', name='talker_1', arguments=['--x'],
                    parameters=[('rate', 5)]),
        NodeProcess('demo', 'quitter', shutdown_on_exit=True)])
    supervisor = Supervisor(system, environ(prefix), out=out)
    code = supervisor.run()
    text = out.getvalue()
    assert code == 3
    assert '[talker_1] talker args: --x --ros-args -r __node:=talker_1 -p rate:=5' in text
    assert '[quitter] quitting with 3' in text
    assert 'quitter exited with code 3' in text
    assert all(node.process is None for node in supervisor.nodes)


def test_respawn_restarts_a_dead_node(prefix):
    out = io.StringIO()
    system = System(nodes=[NodeProcess('demo', 'talker', respawn=True, respawn_delay_s=0.2)])
    supervisor = Supervisor(system, environ(prefix), out=out)
    thread, _ = run_in_thread(supervisor)
    node = supervisor.nodes[0]
    try:
        assert wait_for(lambda: node.process is not None)
        first_pid = node.process.pid
        os.kill(first_pid, signal.SIGKILL)
        assert wait_for(lambda: node.starts == 2 and node.process is not None)
        assert node.process.pid != first_pid
    finally:
        supervisor.request_shutdown('test over')
        thread.join(timeout=10)
    assert 'respawning talker in 0.2 s' in out.getvalue()
    assert 'restarted talker (start 2, pid' in out.getvalue()


def test_stop_escalates_and_leaves_no_process(prefix):
    out = io.StringIO()
    system = System(nodes=[NodeProcess('demo', 'stubborn'), NodeProcess('demo', 'talker')])
    supervisor = Supervisor(system, environ(prefix), out=out, sigint_timeout_s=0.5,
                            sigterm_timeout_s=0.5)
    thread, result = run_in_thread(supervisor)
    try:
        assert wait_for(lambda: '[stubborn] child ' in out.getvalue()), out.getvalue()
        assert wait_for(lambda: all(n.process is not None for n in supervisor.nodes))
        pids = [n.process.pid for n in supervisor.nodes]
        grandchild = int(out.getvalue().split('[stubborn] child ')[1].split()[0])
    finally:
        started = time.monotonic()
        supervisor.request_shutdown('test')
        thread.join(timeout=10)
    assert not thread.is_alive()
    assert time.monotonic() - started < 3.0
    assert result['code'] == 0
    # The runner's own account (its output, written before it escalates), not the
    # child's echo of the trap, which a loaded machine may not schedule before SIGTERM.
    assert 'still running after SIGINT, sending SIGTERM to stubborn' in out.getvalue()
    for pid in pids + [grandchild]:
        assert not alive(pid), f'process {pid} survived shutdown'


def test_children_die_with_a_killed_runner(prefix, tmp_path):
    """SIGKILL the runner itself: PR_SET_PDEATHSIG still takes its nodes down."""
    launch = tmp_path / 'one.launch.yaml'
    launch.write_text('launch:\n- node: {pkg: demo, exec: talker, name: t}\n')
    runner = subprocess.Popen(
        [sys.executable, '-m', 'mecanum_bringup.launch_runner', str(launch)],
        env=environ(prefix), stdout=subprocess.PIPE, text=True)
    line = ''
    while 'started t (pid' not in line:
        line = runner.stdout.readline()
        assert line, 'runner ended before starting the node'
    node_pid = int(line.split('(pid ')[1].split(')')[0])
    runner.kill()
    runner.wait(timeout=10)
    assert wait_for(lambda: not alive(node_pid), timeout=5.0)


def test_a_runner_started_with_sigint_blocked_still_stops_on_ctrl_c(prefix, tmp_path):
    """A Ray worker starts its children with SIGINT blocked (the mask survives exec)."""
    launch = tmp_path / 'one.launch.yaml'
    launch.write_text('launch:\n- node: {pkg: demo, exec: talker, name: t}\n')
    runner = subprocess.Popen(
        [sys.executable, '-m', 'mecanum_bringup.launch_runner', str(launch)],
        env=environ(prefix), stdout=subprocess.PIPE, text=True,
        preexec_fn=lambda: signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}))
    try:
        line = ''
        while 'started t (pid' not in line:
            line = runner.stdout.readline()
            assert line, 'runner ended before starting the node'
        runner.send_signal(signal.SIGINT)
        rest = runner.communicate(timeout=10)[0]
    finally:
        runner.kill()
    assert '[runner] shutting down (received SIGINT)' in rest
    assert runner.returncode == 0


def test_runner_cli_reports_bad_files(tmp_path, capsys):
    from mecanum_bringup.launch_runner import main
    bad = tmp_path / 'bad.launch.yaml'
    bad.write_text('launch:\n- node: {pkg: demo}\n')
    assert main([str(bad)]) == 2
    assert 'missing "exec"' in capsys.readouterr().err


def test_the_start_line_says_whether_the_domain_is_shared():
    from mecanum_bringup.launch_runner import domain_words
    assert domain_words({}, False) == (
        'ROS_DOMAIN_ID unset: domain 0, shared with every ROS program in it on this '
        'machine (--isolated: a domain of its own)')
    assert domain_words({'ROS_DOMAIN_ID': '12'}, False).startswith(
        'ROS_DOMAIN_ID=12, shared with every ROS program')
    assert domain_words({'ROS_DOMAIN_ID': '57'}, True) == \
        'ROS_DOMAIN_ID=57 (leased: this system alone)'


RELOADER = """
    echo "reloader args: $* (MECANUM_RELOAD=$MECANUM_RELOAD)"
    while read -r word rest; do
      if [ "$word" = unload ]; then echo "reload: unloaded"; fi
      if [ "$word" = load ]; then echo "reloader args: $rest"; echo "reload: loaded"; fi
    done
    """


def launch_file(path: Path, executable: str, rate: int) -> Path:
    path.write_text(textwrap.dedent(f"""
        launch:
        - node: {{pkg: demo, exec: {executable}, name: r1, param: [{{name: rate, value: {rate}}}]}}
        """))
    return path


def test_a_reloadable_runner_unloads_then_loads_new_arguments_into_the_same_process(
        prefix, tmp_path):
    from mecanum_bringup.system_description import load_system
    make_executable(prefix, 'demo', 'reloader', RELOADER)
    out = io.StringIO()
    first = launch_file(tmp_path / 'a.launch.yaml', 'reloader', 7)
    supervisor = Supervisor(load_system(first, {}), environ(prefix), out=out, reloadable=True)
    thread, _ = run_in_thread(supervisor)
    try:
        assert wait_for(lambda: 'rate:=7 (MECANUM_RELOAD=stdin)' in out.getvalue())
        pid = supervisor.nodes[0].process.pid
        # A load before an unload is refused: the old nodes must be gone first.
        supervisor.commands.put(('load', {'launch_file': str(first)}))
        assert wait_for(lambda: 'reload refused: the processes were not unloaded' in
                        out.getvalue())
        supervisor.commands.put(('unload', None))
        assert wait_for(lambda: '[runner] unloaded' in out.getvalue())
        second = launch_file(tmp_path / 'b.launch.yaml', 'reloader', 8)
        supervisor.commands.put(('load', {'launch_file': str(second)}))
        assert wait_for(lambda: '[runner] loaded b.launch.yaml: r1' in out.getvalue())
        assert '[r1] reloader args: ["--ros-args", "-r", "__node:=r1", "-p", "rate:=8"]' \
            in out.getvalue()
        assert supervisor.nodes[0].process.pid == pid
        # Another executable cannot be loaded into the process: refused, it runs on.
        supervisor.commands.put(('unload', None))
        assert wait_for(lambda: out.getvalue().count('[runner] unloaded') == 2)
        other = launch_file(tmp_path / 'c.launch.yaml', 'talker', 9)
        supervisor.commands.put(('load', {'launch_file': str(other)}))
        assert wait_for(lambda: "reload refused: r1: executable differs ('talker')"
                        in out.getvalue())
        assert supervisor.nodes[0].process.pid == pid
    finally:
        supervisor.request_shutdown('test over')
        thread.join(timeout=10)


def test_an_unload_that_a_process_does_not_answer_is_reported(prefix, tmp_path):
    from mecanum_bringup import launch_runner
    from mecanum_bringup.system_description import load_system
    out = io.StringIO()
    path = launch_file(tmp_path / 'a.launch.yaml', 'talker', 7)   # reads no commands
    supervisor = Supervisor(load_system(path, {}), environ(prefix), out=out, reloadable=True)
    original = launch_runner.UNLOAD_TIMEOUT_S
    launch_runner.UNLOAD_TIMEOUT_S = 0.5
    thread, _ = run_in_thread(supervisor)
    try:
        assert wait_for(lambda: 'talker args' in out.getvalue())
        supervisor.commands.put(('unload', None))
        assert wait_for(lambda: 'reload failed: r1 did not answer within 0.5 s'
                        in out.getvalue())
    finally:
        launch_runner.UNLOAD_TIMEOUT_S = original
        supervisor.request_shutdown('test over')
        thread.join(timeout=10)


def test_reload_refusal_names_what_differs():
    from mecanum_bringup.launch_runner import reload_refusal
    running = [NodeProcess('demo', 'talker', name='a'), NodeProcess('demo', 'quitter')]
    assert reload_refusal(running, [
        NodeProcess('demo', 'talker', name='a', parameters=[('rate', 2)],
                    arguments=['x']),
        NodeProcess('demo', 'quitter', remappings=[('a', 'b')])]) is None
    assert reload_refusal(running, running[:1]) == 'other processes (a instead of a, quitter)'
    assert reload_refusal(running, [NodeProcess('demo', 'talker', name='a', respawn=True),
                                    running[1]]) == 'a: respawn differs (True)'
    assert reload_refusal(running, [running[0], NodeProcess(
        'demo', 'quitter', env={'X': '1'})]) == "quitter: env differs ({'X': '1'})"
