"""
Integration: Ctrl-C and SIGTERM stop a node cleanly even in the middle of a callback.

A real node process (mecanum_control.node_main.run_node, rclpy's EventsExecutor) whose
timer callback takes 0.3 s, so the signal lands inside a callback run by the C++
executor: the node must finish that callback, run its close() and exit 0, without a
traceback (a KeyboardInterrupt raised inside such a callback came out of spin_once as
"RuntimeError: Unable to convert call argument"). A second SIGINT while the node closes
(Ctrl-C in a terminal under ros2 launch: the terminal's, then launch's) does not cut the
close short.
"""

import signal
import subprocess
import sys
import textwrap
import time

import pytest

pytestmark = pytest.mark.integration

NODE = textwrap.dedent('''
    import sys
    import time

    from mecanum_control.node_main import run_node
    from rclpy.node import Node


    class SlowCallbacks(Node):
        def __init__(self, **node_options):
            super().__init__('slow_callbacks', **node_options)
            self.calls = 0
            self.create_timer(0.01, self.on_timer)

        def on_timer(self):
            self.calls += 1
            if self.calls == 2:
                print('busy', flush=True)
            time.sleep(0.3)

        def close(self):
            print('closing', flush=True)
            seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 0.0
            if len(sys.argv) > 2 and sys.argv[2] == 'holding_the_gil':
                # A call stuck in C code that holds the GIL (PyDLL does not release it).
                import ctypes
                ctypes.PyDLL(None).sleep(int(seconds))
            else:
                time.sleep(seconds)
            print(f'closed after {self.calls} callbacks', flush=True)


    sys.exit(run_node(SlowCallbacks, 'slow_callbacks'))
''')


@pytest.mark.parametrize('signal_number', [signal.SIGINT, signal.SIGTERM])
def test_a_signal_during_a_callback_closes_the_node_cleanly(ros_env, tmp_path, signal_number):
    script = tmp_path / 'slow_node.py'
    script.write_text(NODE)
    process = subprocess.Popen([sys.executable, str(script)], env=ros_env, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert process.stdout.readline().strip() == 'busy'
        process.send_signal(signal_number)   # during the 0.3 s callback
        stdout, stderr = process.communicate(timeout=15)
    finally:
        if process.poll() is None:
            process.kill()
    print(stdout, stderr)
    assert process.returncode == 0
    assert 'closed after' in stdout
    assert 'Traceback' not in stderr
    assert 'Exception in' not in stderr


def test_a_second_ctrl_c_while_closing_does_not_cut_the_close_short(ros_env, tmp_path):
    script = tmp_path / 'slow_node.py'
    script.write_text(NODE)
    process = subprocess.Popen([sys.executable, str(script), '0.5'], env=ros_env, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert process.stdout.readline().strip() == 'busy'
        process.send_signal(signal.SIGINT)
        assert process.stdout.readline().strip() == 'closing'
        process.send_signal(signal.SIGINT)       # during the 0.5 s close
        stdout, stderr = process.communicate(timeout=15)
    finally:
        if process.poll() is None:
            process.kill()
    print(stdout, stderr)
    assert process.returncode == 0
    assert 'closed after' in stdout
    assert 'Traceback' not in stderr


def test_a_close_that_hangs_is_left_after_the_close_timeout(ros_env, tmp_path):
    """A close stuck for 30 s: the process leaves after CLOSE_TIMEOUT_S (3 s), saying so."""
    from mecanum_control.node_main import CLOSE_TIMEOUT_S
    script = tmp_path / 'slow_node.py'
    script.write_text(NODE)
    process = subprocess.Popen([sys.executable, str(script), '30'], env=ros_env, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert process.stdout.readline().strip() == 'busy'
        process.send_signal(signal.SIGINT)
        assert process.stdout.readline().strip() == 'closing'
        stdout, stderr = process.communicate(timeout=CLOSE_TIMEOUT_S + 10)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0
    assert 'closed after' not in stdout                  # left during the hang
    assert f'closing took more than {CLOSE_TIMEOUT_S:g} s' in stderr


def test_a_close_stuck_in_c_code_holding_the_gil_is_ended_with_its_stacks(ros_env, tmp_path):
    """
    The watchdog thread cannot run while a C call holds the GIL: faulthandler ends it.

    CI saw motor_controller wait in rclpy's destroy_node (inside rcl) with its watchdog
    thread never woken, until the test's SIGQUIT 4.5 s after Ctrl-C.
    """
    from mecanum_control.node_main import CLOSE_STUCK_GRACE_S, CLOSE_TIMEOUT_S
    script = tmp_path / 'slow_node.py'
    script.write_text(NODE)
    process = subprocess.Popen([sys.executable, str(script), '30', 'holding_the_gil'],
                               env=ros_env, text=True, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE)
    try:
        assert process.stdout.readline().strip() == 'busy'
        process.send_signal(signal.SIGINT)
        assert process.stdout.readline().strip() == 'closing'
        stdout, stderr = process.communicate(timeout=CLOSE_TIMEOUT_S + CLOSE_STUCK_GRACE_S
                                             + 10)
    finally:
        if process.poll() is None:
            process.kill()
    print(stderr)
    assert process.returncode == 1
    assert 'closed after' not in stdout
    assert f'Timeout (0:00:0{CLOSE_TIMEOUT_S + CLOSE_STUCK_GRACE_S:.0f})!' in stderr
    assert 'in close' in stderr                        # where it was stuck


#: A node spun by spin_waking with an executor whose teardown gets a second Ctrl-C, as
#: launch's SIGINT after the terminal's: it must come while signals are still deferred.
TEARDOWN_NODE = textwrap.dedent('''
    import os
    import signal
    import sys
    import threading

    from mecanum_control.node_main import run_node, spin_waking
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node


    class SecondCtrlCInTeardown(SingleThreadedExecutor):
        def shutdown(self, timeout_sec=None):
            print('teardown', flush=True)
            os.kill(os.getpid(), signal.SIGINT)   # handled here if not deferred
            result = super().shutdown(timeout_sec)
            print('torn down', flush=True)
            return result


    def spin(node):
        threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT)).start()
        spin_waking(node, executor=SecondCtrlCInTeardown(context=node.context))


    sys.exit(run_node(lambda: Node('teardown_node'), 'teardown_node', spin=spin))
''')


def test_the_executor_is_torn_down_while_signals_are_deferred(ros_env, tmp_path):
    # The EventsExecutor left to garbage collection got launch's second SIGINT inside
    # its C++ destructor under the real launch: abort, exit -6 ("process has died").
    script = tmp_path / 'teardown_node.py'
    script.write_text(TEARDOWN_NODE)
    result = subprocess.run([sys.executable, str(script)], env=ros_env, text=True,
                            capture_output=True, timeout=60)
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.split() == ['teardown', 'torn', 'down'], result.stdout
    assert 'Traceback' not in result.stderr, result.stderr


@pytest.mark.parametrize('inherited', [signal.SIG_DFL, signal.SIG_IGN])
def test_sigquit_prints_where_a_node_is_stuck_even_inside_a_callback(ros_env, tmp_path,
                                                                     inherited):
    # The SIGINT and SIGTERM handlers are Python: a process stuck in C code never runs
    # them. SIGQUIT is answered by faulthandler's C handler: every thread's stack, then
    # the default action (quit), so a stuck node says where it waits. Also when started
    # with SIGQUIT ignored (`cmd &` in a script without job control ignores SIGINT and
    # SIGQUIT): chained to an inherited SIG_IGN, the dump left the process running.
    script = tmp_path / 'slow_node.py'
    script.write_text(NODE)
    process = subprocess.Popen([sys.executable, str(script)], env=ros_env, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               preexec_fn=lambda: signal.signal(signal.SIGQUIT, inherited))
    try:
        assert process.stdout.readline().strip() == 'busy'
        process.send_signal(signal.SIGQUIT)    # inside time.sleep (C) in the callback
        _stdout, stderr = process.communicate(timeout=15)
    finally:
        if process.poll() is None:
            process.kill()
    print(stderr)
    assert process.returncode == -signal.SIGQUIT
    assert 'Current thread' in stderr
    assert 'in on_timer' in stderr


LEAVING_NODE = textwrap.dedent('''
    import atexit
    import concurrent.futures
    import sys
    import threading
    import time

    from mecanum_control.node_main import run_node
    from rclpy.node import Node


    class Leaving(Node):
        def __init__(self, **node_options):
            super().__init__('leaving', **node_options)
            self.create_timer(0.05, lambda: print('spinning', flush=True))

        def close(self):
            def write_late():
                time.sleep(0.3)
                with open(sys.argv[1], 'w') as handle:
                    handle.write('written')
            threading.Thread(target=write_late).start()     # not a daemon
            # A thread pool's idle worker (not a daemon either): told to end at exit.
            self.pool = concurrent.futures.ThreadPoolExecutor(1)
            self.pool.submit(lambda: None).result()
            atexit.register(lambda: print('exit function ran'))
            print('unflushed line', end='')


    sys.exit(run_node(Leaving, 'leaving'))
''')


def test_a_node_process_leaves_without_teardown_but_loses_nothing(ros_env, tmp_path):
    """
    node_main.leave_process: the process ends without the interpreter's teardown.

    What the teardown would have done that matters still happens: a thread that is not a
    daemon is joined (an idle thread pool's worker told to end first, or the process would
    hang), exit functions run, buffered output is flushed, and the exit code is 0.
    """
    script = tmp_path / 'leaving_node.py'
    script.write_text(LEAVING_NODE)
    late_file = tmp_path / 'late.txt'
    process = subprocess.Popen([sys.executable, str(script), str(late_file)], env=ros_env,
                               text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert process.stdout.readline().strip() == 'spinning'
        process.send_signal(signal.SIGINT)
        stdout, stderr = process.communicate(timeout=15)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0, stderr
    assert late_file.read_text() == 'written'
    assert 'unflushed lineexit function ran' in stdout
    assert 'Traceback' not in stderr


PUBLISHING_NODE = textwrap.dedent('''
    import ctypes
    import sys

    from mecanum_control import node_main
    from rclpy.node import Node
    from std_msgs.msg import String


    class Publishing(Node):
        def __init__(self, **node_options):
            super().__init__('publishing', **node_options)
            self.publisher = self.create_publisher(String, 'leaving_topic', 10)
            self.timer = self.create_timer(0.05, self.on_timer)

        def on_timer(self):
            self.timer.cancel()
            print('spinning', flush=True)


    if sys.argv[1:] == ['participant_end_hangs']:
        # As Fast DDS's deadlock in destroy_participant: a C call that never returns
        # (without the GIL, as release_participant makes it).
        node_main.finalize_rcl_node = lambda pointer: ctypes.CDLL(None).sleep(600)
    sys.exit(node_main.run_node(Publishing, 'publishing'))
''')


def graph_until(predicate, timeout_s: float) -> bool:
    """Wait until predicate() holds (a graph change reaches a peer in a moment)."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def test_a_node_process_ends_its_participant_last_and_leaves_the_graph(
        ros_env, tmp_path, test_node):
    """
    node_main.hold_participant / release_participant: a hidden node holds the participant.

    The real node's destroy leaves the participant alone; release_participant ends it
    at the end: a peer sees the node, its publisher and the hidden node leave (the
    participant said goodbye: had it not, the hidden node would stay until its lease
    ran out, 20 s).
    """
    script = tmp_path / 'publishing_node.py'
    script.write_text(PUBLISHING_NODE)
    graph = test_node.node

    def names():
        return {name for name, _ in graph.get_node_names_and_namespaces()}

    process = subprocess.Popen([sys.executable, str(script)], env=ros_env, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    holder = f'_publishing_participant_{process.pid}'
    try:
        assert process.stdout.readline().strip() == 'spinning'
        assert graph_until(lambda: {'publishing', holder} <= names()
                           and graph.get_publishers_info_by_topic('/leaving_topic'), 20.0), (
            f'the node, its publisher and {holder} never reached the graph: {names()}')
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=15)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0, stderr
    assert 'WARN' not in stderr, stderr
    assert graph_until(lambda: not {'publishing', holder} & names()
                       and not graph.get_publishers_info_by_topic('/leaving_topic'), 10.0), (
        f'left in the graph after the process ended: {names()}')


def test_a_participant_whose_end_hangs_is_left_with_a_warning(ros_env, tmp_path):
    """
    A participant's destruction stuck in C code (Fast DDS's deadlock) ends the process.

    release_participant runs it without the GIL, so the close watchdog's thread says
    where the close was stuck and leaves with exit 0 (the node had closed), instead of
    faulthandler's exit 1 and stack dump.
    """
    script = tmp_path / 'publishing_node.py'
    script.write_text(PUBLISHING_NODE)
    process = subprocess.Popen([sys.executable, str(script), 'participant_end_hangs'],
                               env=ros_env, text=True, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE)
    try:
        assert process.stdout.readline().strip() == 'spinning'
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0, stderr
    assert "stuck in the DDS participant's destruction" in stderr, stderr
    assert 'Traceback' not in stderr and 'Fatal Python error' not in stderr, stderr


CONTAINER = textwrap.dedent('''
    import sys
    import time

    from mecanum_bringup import node_container
    from rclpy.node import Node


    class HangingClose(Node):
        def __init__(self, **node_options):
            super().__init__('hanging_close', **node_options)
            self.timer = self.create_timer(0.05, self.on_timer)

        def on_timer(self):
            self.timer.cancel()
            print('up', flush=True)     # spinning: the container's close path is next

        def close(self):
            print('closing', flush=True)
            time.sleep(30.0)


    node_container.node_class = lambda package, executable: HangingClose
    sys.exit(node_container.main(
        ['[{"label": "hanging_close", "package": "p", "executable": "e"}]']))
''')


def test_a_container_whose_close_hangs_is_left_after_the_close_timeout(ros_env, tmp_path):
    """
    node_container ends as run_node does: a close stuck for 30 s is left after CLOSE_TIMEOUT_S.

    Its own close once had no watchdog: a container stuck in DDS at its end stayed
    running, orphaned, after its launch runner had gone (test_sweeps' Ray run).
    """
    from mecanum_control.node_main import CLOSE_TIMEOUT_S
    script = tmp_path / 'container.py'
    script.write_text(CONTAINER)
    process = subprocess.Popen([sys.executable, str(script)], env=ros_env, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert process.stdout.readline().strip() == 'up'
        process.send_signal(signal.SIGTERM)
        assert process.stdout.readline().strip() == 'closing'
        stdout, stderr = process.communicate(timeout=CLOSE_TIMEOUT_S + 10)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0, stderr
    assert f'closing took more than {CLOSE_TIMEOUT_S:g} s' in stderr
