"""
The test suite's own hygiene: what its tests start cannot reach later tests.

Integration tests stop the systems they start with Ctrl-C, and lease a ROS domain that
the next test may lease again: a process a test leaves running would talk into that
test's graph.
"""

import signal
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.integration


def test_the_suite_passes_on_default_ctrl_c_and_sigquit_to_what_it_starts():
    # conftest.py restores them when the suite itself was started with them ignored.
    assert signal.getsignal(signal.SIGINT) != signal.SIG_IGN
    assert signal.getsignal(signal.SIGQUIT) == signal.SIG_DFL
    probe = subprocess.run([sys.executable, '-c', 'import signal; print(signal.getsignal('
                            'signal.SIGINT) is signal.default_int_handler, '
                            'signal.getsignal(signal.SIGQUIT) == signal.SIG_DFL)'],
                           capture_output=True, text=True, timeout=30)
    assert probe.stdout.split() == ['True', 'True'], probe.stdout


def test_a_tests_leftover_processes_die_even_when_they_ignore_ctrl_c(marked_env):
    # The marked_env fixture calls kill_leftovers at every test's end, whatever its
    # outcome; here a leftover that ignores SIGINT and SIGTERM, with a child of its own.
    code = ('import signal, subprocess, sys, time\n'
            'signal.signal(signal.SIGINT, signal.SIG_IGN)\n'
            'signal.signal(signal.SIGTERM, signal.SIG_IGN)\n'
            'subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])\n'
            'print("up", flush=True)\n'
            'time.sleep(600)\n')
    process = subprocess.Popen([sys.executable, '-c', code], env=marked_env.env,
                               stdout=subprocess.PIPE, text=True, start_new_session=True)
    try:
        assert process.stdout.readline().strip() == 'up'
        # Both, the child too (CI once listed the parent alone at first: wait for it).
        deadline = time.monotonic() + 10.0
        while len(left := marked_env.leftovers()) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert process.pid in left and len(left) == 2, left
        assert sorted(marked_env.kill_leftovers()) == sorted(left)
        assert process.wait(timeout=10) == -signal.SIGKILL
        deadline = time.monotonic() + 10.0    # the child: reaped by init, gone from /proc
        while marked_env.leftovers() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert marked_env.leftovers() == []
    finally:
        if process.poll() is None:
            process.kill()
