"""
Reload: a node process that ends its nodes and makes new ones without ending (no rclpy).

A warm stack (the scenario and sweep runners run one scenario after the other on the
same processes): instead of starting every process anew for each run (an interpreter,
its imports, a DDS participant and its discovery: most of a system's start), the launch
runner tells each of its processes on standard input

* ``unload``: close and destroy every node of the process (its ``close()`` first, as on
  Ctrl-C), then answer ``reload: unloaded`` on standard output;
* ``load ARGS``: ARGS is a JSON list, the process's new command-line arguments (what
  follows the executable): make the nodes anew from them, then answer ``reload: loaded``
  (or ``reload: failed: WHY`` and exit 2, as a process that failed to start).

New nodes are new objects: no state of the last run (filters, costmaps, plans, latches,
PID integrators, the simulation) survives in them; only the process, its imports and its
DDS participant do. The launch runner unloads every process before it loads any, so no
new node ever meets a node of the last run (nor its /clock). A process takes reload
commands only when started with ``MECANUM_RELOAD=stdin`` in its environment (the launch
runner's ``--reloadable``); otherwise standard input is not read.
"""

import json
import os
import queue
import sys
import threading
from typing import IO, List, Optional

#: Environment variable: 'stdin' makes a node process take reload commands there.
RELOAD_VARIABLE = 'MECANUM_RELOAD'
#: The answers a process prints (one line each, on standard output).
UNLOADED_LINE = 'reload: unloaded'
LOADED_LINE = 'reload: loaded'
FAILED_PREFIX = 'reload: failed: '


class ReloadError(ValueError):
    """A reload command that cannot be carried out (says why)."""


def parse_command(line: str):
    """
    Return ('unload', None) or ('load', [arguments]) for one command line.

    Raises ReloadError for anything else (an unknown word, arguments that are not a
    JSON list of strings).
    """
    word, _, rest = line.strip().partition(' ')
    if word == 'unload' and not rest.strip():
        return 'unload', None
    if word == 'load':
        try:
            arguments = json.loads(rest)
        except json.JSONDecodeError as error:
            raise ReloadError(f'load: the arguments are not JSON: {error}') from None
        if not isinstance(arguments, list) or not all(isinstance(a, str) for a in arguments):
            raise ReloadError(f'load: expected a JSON list of strings, got {rest.strip()!r}')
        return 'load', arguments
    raise ReloadError(f'unknown reload command {line.strip()!r} (unload, load ARGS)')


def load_command(arguments: List[str]) -> str:
    """Return the command line that loads a process with arguments."""
    return 'load ' + json.dumps(list(arguments)) + '\n'


class ReloadChannel:
    """
    Reload commands arriving on a stream (standard input), read by a daemon thread.

    ``unload_requested`` is set by an ``unload``; :meth:`next_load` waits for the ``load``
    that follows. The end of the stream (the launch runner gone) counts as an unload
    with no load after it: the process then ends.
    """

    def __init__(self, stream: Optional[IO[str]] = None):
        """Start reading stream (default: standard input)."""
        self.unload_requested = threading.Event()
        self._loads: 'queue.Queue[Optional[List[str]]]' = queue.Queue()
        self.errors: List[str] = []
        self._stream = stream if stream is not None else sys.stdin
        threading.Thread(target=self._read, name='reload_channel', daemon=True).start()

    def _read(self) -> None:
        for line in self._stream:
            if not line.strip():
                continue
            try:
                word, arguments = parse_command(line)
            except ReloadError as error:
                self.errors.append(str(error))
                print(f'{FAILED_PREFIX}{error}', flush=True)
                continue
            if word == 'unload':
                self.unload_requested.set()
            else:
                self._loads.put(arguments)
        self._loads.put(None)
        self.unload_requested.set()

    def next_load(self, stop: threading.Event, poll_s: float = 0.2) -> Optional[List[str]]:
        """
        Wait for the next ``load``; return its arguments (None: stop set or stream ended).

        Clears ``unload_requested`` first: the load starts a new round.
        """
        self.unload_requested.clear()
        while not stop.is_set():
            try:
                return self._loads.get(timeout=poll_s)
            except queue.Empty:
                continue
        return None


def reload_channel() -> Optional[ReloadChannel]:
    """Return the process's channel when MECANUM_RELOAD=stdin, else None."""
    if os.environ.get(RELOAD_VARIABLE, '') != 'stdin':
        return None
    return ReloadChannel()


def say(line: str) -> None:
    """Print an answer line for the launch runner (flushed at once)."""
    print(line, flush=True)


class EitherEvent:
    """is_set() of two events together (a stop that also ends on an unload)."""

    def __init__(self, first: threading.Event, second: Optional[threading.Event]):
        """Combine first and second (None: first alone)."""
        self.first, self.second = first, second

    def is_set(self) -> bool:
        """Tell whether either event is set."""
        return self.first.is_set() or (self.second is not None and self.second.is_set())
