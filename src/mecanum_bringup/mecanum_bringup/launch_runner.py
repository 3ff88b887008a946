"""
Run a system description without ``ros2 launch``: the pip-setup launcher.

Usage (``./mecanum launch`` wraps this)::

    python -m mecanum_bringup.launch_runner PACKAGE FILE [name:=value ...]
    python -m mecanum_bringup.launch_runner PATH/TO/FILE.launch.yaml [name:=value ...]

Each node runs as its own process in its own process group, started with the
same ``--ros-args`` command line ``launch_ros`` would build; with ``--compose``,
groups of nodes share a process instead (:mod:`mecanum_bringup.composition`). Its output lines
are prefixed with ``[node_name]``. Nodes marked ``respawn`` are restarted after
``respawn_delay``; a node marked ``on_exit: shutdown`` stops the whole system
when it exits (the runner then exits with that node's code). On Ctrl-C or
SIGTERM every node gets SIGINT, then SIGTERM, then SIGKILL, so the system is
down within about five seconds, and children die with the runner even if it is
killed (PR_SET_PDEATHSIG), leaving no orphan processes.

With ``--reloadable`` (the scenario and sweep runners' warm stacks) the runner takes
commands on standard input, one line each: ``unload`` (every process closes its nodes
and keeps running, idle; ``[runner] unloaded``) and ``load {"launch_file": PATH,
"compose": BOOL, "composition": PATH or null}`` (every process makes its nodes anew
from that system's command lines; ``[runner] loaded``). A system whose processes differ
from the running ones (other executables, environment, prefix, respawn) is refused
(``[runner] reload refused: WHY``), as is a load while a process has been restarted;
a process that does not answer is reported (``[runner] reload failed: WHY``). Either
way the caller stops the runner and starts the new system cold. See
:mod:`mecanum_control.node_reload` for the processes' side.
"""

import argparse
import ctypes
import json
import os
from pathlib import Path
import queue
import signal
import subprocess
import sys
import threading
import time
from typing import Dict, List, Mapping, Optional, TextIO

from mecanum_bringup.composition import compose, load_composition
from mecanum_bringup.isolation import isolated_environment, lease_domain_id
from mecanum_bringup.system_description import (
    default_find_package_share, description_file, load_system, NodeProcess,
    parse_launch_arguments, System, SystemDescriptionError)
from mecanum_control import node_reload

_PR_SET_PDEATHSIG = 1
# Loaded here, not in the forked child: dynamic loading between fork and exec can
# deadlock when other threads (the output readers) held the loader lock.
_LIBC = ctypes.CDLL(None, use_errno=True)


def find_executable(package: str, executable: str, environ: Mapping[str, str]) -> Path:
    """Find ``lib/PACKAGE/EXECUTABLE`` in the ament prefixes, as ``ros2 run`` does."""
    for prefix in environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if not prefix:
            continue
        candidate = Path(prefix) / 'lib' / package / executable
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return candidate
    raise FileNotFoundError(
        f'executable {executable!r} of package {package!r} not found in AMENT_PREFIX_PATH; '
        'is the workspace built (make setup) and its environment sourced?')


def die_with_parent() -> None:
    """
    In a child, before exec: get SIGTERM if the parent dies, however it dies.

    (PR_SET_PDEATHSIG: strictly, when the thread that started the child ends; start
    children from a thread that lives as long as they should.)
    """
    _LIBC.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)


class ManagedNode:
    """A node process of the system, with its restart bookkeeping."""

    def __init__(self, spec: NodeProcess, command: List[str], env: Dict[str, str]):
        self.spec = spec
        self.command = command
        self.env = env
        self.process: Optional[subprocess.Popen] = None
        self.starts = 0
        self.restart_at: Optional[float] = None
        self.reader: Optional[threading.Thread] = None
        #: The process's reload answers (node_reload's lines), in order.
        self.answers: 'queue.Queue[str]' = queue.Queue()


#: What must be equal for a running process to take another system's node by a reload.
RELOAD_SAME = ('package', 'executable', 'name', 'namespace', 'env', 'launch_prefix',
               'respawn', 'respawn_delay_s', 'shutdown_on_exit')
#: Wall seconds a process may take to answer an unload, and a load.
UNLOAD_TIMEOUT_S = 20.0
LOAD_TIMEOUT_S = 60.0


def reload_refusal(running: List[NodeProcess], new: List[NodeProcess]) -> Optional[str]:
    """
    Say why the running processes cannot take the new system's nodes (None: they can).

    The processes must be the same, in the same order: only their arguments, parameters
    and remappings (a container's node list among them) may differ.
    """
    if [n.label for n in running] != [n.label for n in new]:
        return (f'other processes ({", ".join(n.label for n in new)} instead of '
                f'{", ".join(n.label for n in running)})')
    for old, spec in zip(running, new):
        for name in RELOAD_SAME:
            if getattr(old, name) != getattr(spec, name):
                return f'{spec.label}: {name} differs ({getattr(spec, name)!r})'
    return None


class Supervisor:
    """Starts the nodes of a System and keeps them running until shutdown."""

    def __init__(self, system: System, environ: Mapping[str, str], out: TextIO = sys.stdout,
                 sigint_timeout_s: float = 3.0, sigterm_timeout_s: float = 2.0,
                 reloadable: bool = False):
        self._out = out
        self.reloadable = reloadable
        #: Reload commands (node_reload's words: ('unload', None), ('load', document)).
        self.commands: 'queue.Queue[tuple]' = queue.Queue()
        self._unloaded = False
        self._out_lock = threading.Lock()
        self._sigint_timeout_s = sigint_timeout_s
        self._sigterm_timeout_s = sigterm_timeout_s
        self._shutdown_reason: Optional[str] = None
        self._exit_code = 0
        base_env = dict(environ)
        base_env.setdefault('PYTHONUNBUFFERED', '1')
        base_env.setdefault('RCUTILS_LOGGING_BUFFERED_STREAM', '1')
        base_env.pop(node_reload.RELOAD_VARIABLE, None)
        if reloadable:
            base_env[node_reload.RELOAD_VARIABLE] = 'stdin'
        if getattr(out, 'isatty', lambda: False)():
            base_env.setdefault('RCUTILS_COLORIZED_OUTPUT', '1')
        self.nodes: List[ManagedNode] = []
        for spec in system.nodes:
            executable = find_executable(spec.package, spec.executable, base_env)
            command = [*spec.launch_prefix, str(executable), *process_arguments(spec)]
            self.nodes.append(ManagedNode(spec, command, dict(base_env, **spec.env)))

    def say(self, label: str, text: str) -> None:
        """Print one line with a ``[label]`` prefix, whole even with many writers."""
        with self._out_lock:
            self._out.write(f'[{label}] {text}\n')
            self._out.flush()

    def request_shutdown(self, reason: str, exit_code: int = 0) -> None:
        """Ask the supervision loop to stop every node (first request wins)."""
        if self._shutdown_reason is None:
            self._shutdown_reason = reason
            self._exit_code = exit_code

    @property
    def shutting_down(self) -> bool:
        """Whether shutdown was requested."""
        return self._shutdown_reason is not None

    def _start(self, node: ManagedNode) -> None:
        node.process = subprocess.Popen(
            node.command, env=node.env,
            stdin=subprocess.PIPE if self.reloadable else subprocess.DEVNULL,
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True,
            preexec_fn=die_with_parent)
        node.starts += 1
        node.restart_at = None
        verb = 'started' if node.starts == 1 else 'restarted'
        count = '' if node.starts == 1 else f'start {node.starts}, '
        self.say('runner', f'{verb} {node.spec.label} ({count}pid {node.process.pid}): '
                           f'{node.spec.package}/{node.spec.executable}')
        node.reader = threading.Thread(target=self._forward_output, args=(node, node.process),
                                       daemon=True)
        node.reader.start()

    def _forward_output(self, node: ManagedNode, process: subprocess.Popen) -> None:
        for raw in iter(process.stdout.readline, b''):
            line = raw.decode(errors='replace').rstrip('\n')
            if self.reloadable and line.startswith('reload: '):
                node.answers.put(line)
            self.say(node.spec.label, line)
        process.stdout.close()

    def _check(self, node: ManagedNode, now: float) -> None:
        """React to a node's exit: respawn it, shut the system down, or report it."""
        if node.process is None:
            if node.restart_at is not None and now >= node.restart_at:
                self._start(node)
            return
        code = node.process.poll()
        if code is None:
            return
        if node.reader is not None:
            node.reader.join(timeout=1.0)
        node.process = None
        self.say('runner', f'{node.spec.label} exited with code {code}')
        if node.spec.shutdown_on_exit:
            self.request_shutdown(f'{node.spec.label} exited (on_exit: shutdown)', code)
        elif node.spec.respawn:
            node.restart_at = now + node.spec.respawn_delay_s
            self.say('runner', f'respawning {node.spec.label} in {node.spec.respawn_delay_s:g} s')

    def run(self) -> int:
        """Start every node and supervise until shutdown; return the exit code."""
        try:
            for node in self.nodes:
                self._start(node)
            while not self.shutting_down:
                now = time.monotonic()
                for node in self.nodes:
                    self._check(node, now)
                try:
                    word, document = self.commands.get(timeout=0.05)
                except queue.Empty:
                    continue
                if word == 'unload':
                    self.unload()
                else:
                    self.load(document)
        finally:
            self.stop_all()
        return self._exit_code

    # --- reloads (warm stacks) ---------------------------------------------------------

    def read_commands(self, stream: TextIO) -> None:
        """Queue the reload commands of stream (a daemon thread); its end stops the system."""
        def read() -> None:
            for line in stream:
                word, _, rest = line.strip().partition(' ')
                if word == 'unload' and not rest:
                    self.commands.put(('unload', None))
                elif word == 'load':
                    try:
                        self.commands.put(('load', json.loads(rest)))
                    except json.JSONDecodeError as error:
                        self.say('runner', f'reload failed: the load is not JSON: {error}')
                elif word:
                    self.say('runner', f'reload failed: unknown command {line.strip()!r}')
            self.request_shutdown('standard input closed')
        threading.Thread(target=read, name='reload_commands', daemon=True).start()

    def _tell(self, node: ManagedNode, text: str) -> bool:
        try:
            node.process.stdin.write(text.encode())
            node.process.stdin.flush()
            return True
        except (OSError, ValueError, AttributeError):
            return False

    def _await(self, nodes: List[ManagedNode], expected: str, timeout_s: float) -> Optional[str]:
        """Wait until every node answered expected; return what went wrong (None: nothing)."""
        deadline = time.monotonic() + timeout_s
        for node in nodes:
            while True:
                if node.process is None or node.process.poll() is not None:
                    return f'{node.spec.label} exited'
                try:
                    answer = node.answers.get(timeout=0.05)
                except queue.Empty:
                    if time.monotonic() > deadline:
                        return f'{node.spec.label} did not answer within {timeout_s:g} s'
                    continue
                if answer == expected:
                    break
                if answer.startswith(node_reload.FAILED_PREFIX):
                    return f'{node.spec.label}: {answer[len(node_reload.FAILED_PREFIX):]}'
        return None

    def unload(self) -> bool:
        """Have every process close its nodes; say 'unloaded' or why not."""
        problem = None
        if not self.reloadable:
            problem = 'the runner was not started with --reloadable'
        elif any(n.process is None or n.process.poll() is not None for n in self.nodes):
            problem = 'a process is not running'
        if problem is None:
            for node in self.nodes:
                while not node.answers.empty():
                    node.answers.get_nowait()
                if not self._tell(node, 'unload\n'):
                    problem = f'{node.spec.label} takes no commands'
                    break
        if problem is None:
            problem = self._await(self.nodes, node_reload.UNLOADED_LINE, UNLOAD_TIMEOUT_S)
        if problem is not None:
            self.say('runner', f'reload failed: {problem}')
            return False
        self._unloaded = True
        self.say('runner', 'unloaded: every process is idle, without nodes')
        return True

    def load(self, document) -> bool:
        """Make every process's nodes anew from the system document names; say 'loaded'."""
        try:
            if not isinstance(document, dict) or 'launch_file' not in document:
                raise SystemDescriptionError('expected {"launch_file": ..., "compose": ..., '
                                             '"composition": ...}')
            path = Path(document['launch_file'])
            composition = document.get('composition')
            system = build_system(path, {}, bool(document.get('compose')),
                                  Path(composition) if composition else None)
            commands = [process_arguments(spec) for spec in system.nodes]
        except (SystemDescriptionError, LookupError, OSError) as error:
            self.say('runner', f'reload refused: {error}')
            return False
        problem = reload_refusal([n.spec for n in self.nodes], system.nodes)
        if problem is None and not self._unloaded:
            problem = 'the processes were not unloaded first'
        if problem is None and any(n.starts != 1 for n in self.nodes):
            problem = 'a process was restarted (' + ', '.join(
                n.spec.label for n in self.nodes if n.starts != 1) + ')'
        if problem is not None:
            self.say('runner', f'reload refused: {problem}')
            return False
        for node, spec, arguments in zip(self.nodes, system.nodes, commands):
            executable = node.command[len(spec.launch_prefix)]   # the prefix is the same
            node.spec, node.command = spec, [*spec.launch_prefix, executable, *arguments]
            if not self._tell(node, node_reload.load_command(arguments)):
                self.say('runner', f'reload failed: {node.spec.label} takes no commands')
                return False
        problem = self._await(self.nodes, node_reload.LOADED_LINE, LOAD_TIMEOUT_S)
        if problem is not None:
            self.say('runner', f'reload failed: {problem}')
            return False
        self._unloaded = False
        self.say('runner', f'loaded {path.name}: ' + ', '.join(n.spec.label for n in self.nodes))
        return True

    def stop_all(self) -> None:
        """Stop every node: SIGINT, then SIGTERM, then SIGKILL, each to its process group."""
        reason = self._shutdown_reason or 'runner stopping'
        running = [n for n in self.nodes if n.process is not None]
        if running:
            self.say('runner', f'shutting down ({reason}): stopping '
                               + ', '.join(n.spec.label for n in running))
        groups = [n.process.pid for n in running]
        for sig, timeout in ((signal.SIGINT, self._sigint_timeout_s),
                             (signal.SIGTERM, self._sigterm_timeout_s)):
            alive = [n for n in running if n.process.poll() is None]
            if not alive:
                break
            if sig == signal.SIGTERM:
                self.say('runner', 'still running after SIGINT, sending SIGTERM to '
                                   + ', '.join(n.spec.label for n in alive))
            for node in alive:
                _signal_group(node.process.pid, sig)
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline and any(n.process.poll() is None for n in alive):
                time.sleep(0.02)
        for node in running:
            if node.process.poll() is None:
                self.say('runner', f'killing {node.spec.label} (SIGKILL)')
        # Leaders may be gone while their children linger: the whole group goes.
        for pgid in groups:
            _signal_group(pgid, signal.SIGKILL)
        for node in running:
            node.process.wait()
            if node.reader is not None:
                node.reader.join(timeout=1.0)
            node.process = None


def _signal_group(pgid: int, sig: int) -> None:
    try:
        os.killpg(pgid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def resolve_launch_file(package_or_path: str, file_name: Optional[str]) -> Path:
    """Return the launch file named like ``ros2 launch`` takes it (package + file, or a path)."""
    if file_name is None:
        return Path(package_or_path)
    share = Path(default_find_package_share(package_or_path))
    for candidate in (share / 'launch' / file_name, share / file_name):
        if description_file(candidate).exists():
            return candidate
    raise SystemDescriptionError(f'no launch file {file_name!r} in package {package_or_path!r}')


def default_composition_file() -> Path:
    """Return mecanum_bringup's config/composition.yaml (installed share)."""
    return Path(default_find_package_share('mecanum_bringup')) / 'config' / 'composition.yaml'


def build_system(path: Path, arguments: Dict[str, str], composed: bool,
                 composition: Optional[Path] = None) -> System:
    """Load the launch file's system; with composed, grouped into containers (composition)."""
    system = load_system(path, arguments)
    if composed:
        system = compose(system, load_composition(composition or default_composition_file()))
    return system


def process_arguments(spec: NodeProcess) -> List[str]:
    """Return what follows the executable on a node process's command line."""
    return [*spec.arguments, *spec.ros_args()]


def domain_words(environ: Dict[str, str], isolated: bool) -> str:
    """
    Return e.g. 'ROS_DOMAIN_ID=7 (leased: this system alone)' for the start-up line.

    A system in the environment's domain shares it with every other ROS program of the
    machine in that domain (domain 0 when ROS_DOMAIN_ID is unset): the words say so, and
    how to get one of its own.
    """
    domain = environ.get('ROS_DOMAIN_ID', '') or '0'
    if isolated:
        return f'ROS_DOMAIN_ID={domain} (leased: this system alone)'
    where = 'ROS_DOMAIN_ID unset: domain 0' if not environ.get('ROS_DOMAIN_ID') \
        else f'ROS_DOMAIN_ID={domain}'
    return (f'{where}, shared with every ROS program in it on this machine (--isolated: '
            'a domain of its own)')


def main(argv: Optional[List[str]] = None) -> int:
    """Command line entry point; returns the process exit code."""
    parser = argparse.ArgumentParser(
        prog='launch_runner',
        description='Run a launch YAML system description without ros2 launch.')
    parser.add_argument('package_or_path', help='package name, or path of a launch file')
    parser.add_argument('rest', nargs='*', help='[launch file] [name:=value ...]')
    parser.add_argument('--isolated', action='store_true',
                        help='run in a ROS domain no other process of this machine uses')
    parser.add_argument('--show-args', action='store_true',
                        help='print the launch arguments and their values, then exit')
    parser.add_argument('--print', dest='print_only', action='store_true',
                        help='print the command of every node, then exit')
    parser.add_argument('--compose', action='store_true',
                        help='run groups of nodes in one process each (node_container)')
    parser.add_argument('--reloadable', action='store_true',
                        help='take unload / load commands on standard input (warm stacks; '
                             'see the module docstring)')
    parser.add_argument('--composition', type=Path, metavar='FILE',
                        help='the groups for --compose (default: mecanum_bringup '
                             'config/composition.yaml)')
    options = parser.parse_args(argv)
    file_name = None
    rest = list(options.rest)
    if rest and ':=' not in rest[0]:
        file_name = rest.pop(0)
    try:
        path = resolve_launch_file(options.package_or_path, file_name)
        system = build_system(path, parse_launch_arguments(rest), options.compose,
                              options.composition)
    except (SystemDescriptionError, LookupError) as error:
        print(f'[runner] error: {error}', file=sys.stderr)
        return 2
    if options.show_args:
        for name, value in system.arguments.items():
            print(f'{name}:={value}')
        return 0
    lease = lease_domain_id() if options.isolated else None
    environ = isolated_environment(os.environ, lease.domain_id if lease else None)
    try:
        supervisor = Supervisor(system, environ, reloadable=options.reloadable)
    except FileNotFoundError as error:
        print(f'[runner] error: {error}', file=sys.stderr)
        return 2
    if options.print_only:
        for node in supervisor.nodes:
            print(' '.join(node.command))
        return 0
    supervisor.say('runner', f'system {path.name}: {len(supervisor.nodes)} nodes ('
                   + ', '.join(n.spec.label for n in supervisor.nodes) + '); '
                   + domain_words(environ, options.isolated) + ', discovery range '
                   f'{environ["ROS_AUTOMATIC_DISCOVERY_RANGE"]}; Ctrl-C stops everything')

    def on_signal(signum: int, _frame: object) -> None:
        supervisor.request_shutdown(f'received {signal.Signals(signum).name}')

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    # A blocked signal stays blocked across exec: a Ray worker starts its children with
    # SIGINT blocked, and the runner never saw the Ctrl-C that ends a scenario (it was
    # killed 20 s later, its nodes with it). The nodes inherit the mask set here.
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    if options.reloadable:
        supervisor.read_commands(sys.stdin)
    try:
        return supervisor.run()
    finally:
        if lease is not None:
            lease.release()


if __name__ == '__main__':
    sys.exit(main())
