"""
Suite-wide pytest hooks for ``make test``'s parallel run (pytest-xdist).

``make test`` runs ``--dist loadfile``: each test file runs on one worker, so a module
fixture (the demo's tour) runs once. Order: files with tests marked ``long`` (a minute
or more) start first, so that no long test starts last and finishes alone; tests
marked ``alone`` come last (see below).

Tests marked ``alone`` run with no other test beside them. Most tests do not care:
lockstep simulations wait for the stack, test clocks step on after the test process,
unit tests measure nothing in time. A few measure the wall clock on purpose (a CPU hog
the test starts itself, the board emulator's real-time link), or are not yet independent
of the machine's load (the demo's tour, see tests/test_demo.py); they are marked
``@pytest.mark.alone`` and take a machine-wide exclusive lock of this run, which every
other test of the run shares. A waiting ``alone`` test holds the turnstile, so no new
test starts until it had its turn (the lock prefers the writer). Without xdist every
test runs alone anyway, and no lock is taken.

Started with SIGINT and SIGQUIT ignored (``make test &`` in a script: a shell without
job control starts background commands so), every process the tests start would
inherit that, and Ctrl-C, which most integration tests send to stop a system, would
reach no program that does not handle it itself (launch respawned nodes that had
stopped and never ended). The suite restores both to their defaults at start.
"""

import contextlib
import fcntl
import json
import multiprocessing
import os
from pathlib import Path
import signal
import tempfile
import time
import uuid

import pytest

if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
if signal.getsignal(signal.SIGQUIT) == signal.SIG_IGN:
    signal.signal(signal.SIGQUIT, signal.SIG_DFL)


@contextlib.contextmanager
def _locked(path: Path, operation: int):
    """Hold flock(operation) on path (created when missing) inside the block."""
    with open(path, 'a') as handle:
        fcntl.flock(handle, operation)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


@contextlib.contextmanager
def run_exclusively(run_id: str, alone: bool):
    """
    One test of run run_id: exclusive when alone, else shared with other non-alone tests.

    A writer-preferring reader-writer lock of two flock files: the turnstile (held by a
    waiting alone test, passed through by the others) and the room.
    """
    base = _lock_base(run_id)
    turnstile, room = base.with_suffix('.turnstile'), base.with_suffix('.room')
    if alone:
        with _locked(turnstile, fcntl.LOCK_EX), _locked(room, fcntl.LOCK_EX):
            yield
    else:
        with _locked(turnstile, fcntl.LOCK_EX):
            pass
        with _locked(room, fcntl.LOCK_SH):
            yield


def _lock_base(run_id: str) -> Path:
    """Return the path (without suffix) of run run_id's lock files."""
    return Path(tempfile.gettempdir()) / f'mecanum_pytest_{run_id}'


def pytest_configure(config):
    """Declare the markers; on the xdist controller, name the run (for its lock files)."""
    config.addinivalue_line(
        'markers', 'alone: measures the wall clock or needs a quiet machine; runs by itself')
    config.addinivalue_line(
        'markers', 'long: runs for a minute or more; started first')
    if getattr(config.option, 'numprocesses', None) and not config.option.testrunuid:
        config.option.testrunuid = uuid.uuid4().hex
    # New processes by forkserver, not fork: a test process runs rclpy's and DDS's threads,
    # and a child forked from it (ament_flake8's checker pool) once died in the garbage
    # collector (segmentation fault) and hung its worker.
    multiprocessing.set_start_method('forkserver', force=True)


def pytest_collection_modifyitems(config, items):
    """Long tests first, alone tests last, the rest in between in their own order."""
    def rank(item) -> int:
        if item.get_closest_marker('alone'):
            return 2
        return 0 if item.get_closest_marker('long') else 1
    items.sort(key=rank)


def pytest_unconfigure(config):
    """On the xdist controller, remove the run's lock files."""
    if not hasattr(config, 'workerinput') and getattr(config.option, 'testrunuid', None):
        for suffix in ('.turnstile', '.room'):
            _lock_base(config.option.testrunuid).with_suffix(suffix).unlink(missing_ok=True)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Run the test inside the run's lock when xdist runs tests in parallel."""
    workerinput = getattr(item.config, 'workerinput', None)
    if workerinput is None:
        yield
        return
    alone = item.get_closest_marker('alone') is not None
    asked = time.time()
    with run_exclusively(workerinput['testrunuid'], alone):
        with _timeline_entry(item, workerinput, asked, alone):
            yield


#: A file to which each test appends one JSON line (when set): its worker, when it asked
#: to run, started and ended (wall s) and the CPU seconds of the processes it started
#: and waited for. tools/test_timeline.py reads it (where a suite's time goes).
TIMELINE_VARIABLE = 'MECANUM_TEST_TIMELINE'


@contextlib.contextmanager
def _timeline_entry(item, workerinput: dict, asked: float, alone: bool):
    """Append item's line to $MECANUM_TEST_TIMELINE after it ran (nothing when unset)."""
    path = os.environ.get(TIMELINE_VARIABLE)
    if not path:
        yield
        return
    start, times = time.time(), os.times()
    try:
        yield
    finally:
        after = os.times()
        entry = {'test': item.nodeid, 'worker': workerinput.get('workerid'),
                 'alone': alone, 'asked': asked, 'start': start, 'end': time.time(),
                 'cpu_s': after.user + after.system - times.user - times.system,
                 'children_cpu_s': (after.children_user + after.children_system
                                    - times.children_user - times.children_system)}
        with open(path, 'a') as handle:
            handle.write(json.dumps(entry) + '\n')
