"""
Read a system description: a ROS 2 launch file in the YAML frontend format.

A system (which nodes run, from which package and executable, with which
parameter files, remappings, namespace and respawn policy) is written once as a
``*.launch.yaml`` file. On an apt ROS 2 install ``ros2 launch`` reads it
natively (through the ``launch/*.launch.py`` wrappers); in the pip setup, where
``launch`` is not installable, :mod:`mecanum_bringup.launch_runner` reads it
with this module. Both read the same file, so they cannot drift.

Supported subset of the launch YAML format (anything else is an error that
names the file and the entry, never silently ignored)::

    launch:
    - arg: {name: use_sim_time, default: 'false', description: '...'}
    - let: {name: robot, value: 'mecanum'}
    - set_env: {name: ROS_AUTOMATIC_DISCOVERY_RANGE, value: LOCALHOST}
    - include:
        file: $(find-pkg-share mecanum_control)/launch/control.launch.yaml
        arg: [{name: use_sim_time, value: $(var use_sim_time)}]
    - node:
        pkg: robot_controller
        exec: robot_control_node
        name: robot_controller            # optional
        namespace: robot1                 # optional
        param:                            # in order; later entries win
        - from: $(find-pkg-share robot_controller)/config/robot_controller.yaml
        - {name: use_sim_time, value: $(var use_sim_time)}
        remap: [{from: cmd_vel, to: /cmd_vel}]
        args: '--extra arguments'         # optional
        respawn: 'true'                   # optional
        respawn_delay: 2.0                # optional, seconds (a float, unquoted)
        on_exit: shutdown                 # optional: stop the whole system when it exits
        if: $(var use_slam)               # optional on every entry but arg: skip it when
                                          # false (unless: skip it when true)
        output: screen                    # accepted; output is always shown
        env: [{name: FOO, value: bar}]    # optional

Substitutions: ``$(var NAME)``, ``$(find-pkg-share PKG)``,
``$(env NAME [DEFAULT])``, ``$(dirname)`` (the launch file's folder), ``$(anon NAME)``
(launch's AnonName: ``NAME_<host>_<pid>_<random>``, with '.', '-' and ':' made '_'; the
same NAME gives the same text throughout one launch, e.g. a file name of this launch
only) and ``$(command 'CMD ARGS' [ON_STDERR])``: CMD's standard output. As in ROS 2 launch,
the command is split like a shell would (shlex) but run without one, in the
launch environment; it fails on a non-zero exit and, with ON_STDERR ``fail`` (the
default), on any standard error output (``ignore``: drop it, ``warn``: print it,
``capture``: append it to the result). Arguments are separated by spaces and may be
quoted ('...' or "..."; in quotes a backslash escapes the quote, a backslash or
``$``) and hold nested substitutions, e.g.
``$(command 'xacro $(find-pkg-share mecanum_description)/urdf/robot.urdf.xacro')``.
This module does not import rclpy or launch.
"""

from dataclasses import dataclass, field
import os
from pathlib import Path
import re
import secrets
import shlex
import socket
import subprocess
import sys
from typing import Callable, Dict, List, Optional, Tuple, Union

import yaml

_IDENTIFIER = re.compile(r'[A-Za-z][A-Za-z0-9_-]*')
#: How long a $(command ...) may run before the launch is abandoned.
COMMAND_TIMEOUT_S = 120.0
_NODE_KEYS = {'pkg', 'exec', 'name', 'namespace', 'param', 'remap', 'args', 'ros_args',
              'respawn', 'respawn_delay', 'on_exit', 'output', 'env', 'launch-prefix'}
#: Node attributes that ROS 2 launch's YAML frontend takes as text only: launch_yaml
#: checks types and never coerces, so ``respawn: true`` (a YAML bool) fails there.
_NODE_TEXT_KEYS = ('pkg', 'exec', 'name', 'namespace', 'args', 'ros_args', 'respawn',
                   'on_exit', 'output', 'launch-prefix')


class SystemDescriptionError(ValueError):
    """A system description (launch YAML file) is malformed or refers to missing things."""


@dataclass
class NodeProcess:
    """
    One node of a system, resolved to the command line that starts it.

    ``parameters`` keeps the launch order of parameter sources: a ``Path`` is a
    parameter file, a ``(name, value)`` tuple a single parameter override.
    ``env`` holds the variables set for this node (set_env entries in force where
    it is declared, then its own env entries).
    """

    package: str
    executable: str
    name: Optional[str] = None
    namespace: Optional[str] = None
    parameters: List[object] = field(default_factory=list)
    remappings: List[Tuple[str, str]] = field(default_factory=list)
    arguments: List[str] = field(default_factory=list)
    ros_arguments: List[str] = field(default_factory=list)
    env: Dict[str, str] = field(default_factory=dict)
    launch_prefix: List[str] = field(default_factory=list)
    respawn: bool = False
    respawn_delay_s: float = 0.0
    shutdown_on_exit: bool = False

    @property
    def label(self) -> str:
        """Name used to prefix the node's output: its node name, else its executable."""
        return self.name or self.executable

    def ros_args(self) -> List[str]:
        """Return the ``--ros-args`` part of the command line, as launch_ros builds it."""
        args: List[str] = []
        if self.name:
            args += ['-r', f'__node:={self.name}']
        if self.namespace:
            args += ['-r', f'__ns:={normalize_namespace(self.namespace)}']
        for source in self.parameters:
            if isinstance(source, Path):
                args += ['--params-file', str(source)]
            else:
                name, value = source
                args += ['-p', f'{name}:={yaml_scalar(value)}']
        for remap_from, remap_to in self.remappings:
            args += ['-r', f'{remap_from}:={remap_to}']
        args += self.ros_arguments
        return ['--ros-args', *args] if args else []


@dataclass
class System:
    """A resolved system: its nodes, its launch arguments, and the files read."""

    nodes: List[NodeProcess] = field(default_factory=list)
    files: List[Path] = field(default_factory=list)
    # Every declared launch argument and the value it took.
    arguments: Dict[str, str] = field(default_factory=dict)


def normalize_namespace(namespace: str) -> str:
    """Return a namespace with exactly one leading slash and no trailing slash."""
    stripped = namespace.strip('/')
    return '/' + stripped if stripped else '/'


def yaml_scalar(value: object) -> str:
    """Encode a parameter value the way rcl parses ``-p name:=value`` (YAML)."""
    text = yaml.safe_dump(value, default_flow_style=True, width=1 << 30).strip()
    # A plain scalar is dumped as a document ("x\n..."); drop the end marker.
    if text.endswith('\n...'):
        text = text[:-len('\n...')]
    return text


def description_file(path: Path) -> Path:
    """Return the YAML system description behind a launch file name (x.launch.py -> .yaml)."""
    path = Path(path)
    if path.name.endswith('.launch.py'):
        return path.with_name(path.name[:-len('.launch.py')] + '.launch.yaml')
    return path


def parse_bool(text: object, where: str) -> bool:
    """Parse a launch boolean ('true'/'false', any case) or raise with context."""
    lowered = str(text).strip().lower()
    if lowered in ('true', '1', 'yes'):
        return True
    if lowered in ('false', '0', 'no'):
        return False
    raise SystemDescriptionError(f'{where}: expected true or false, got {text!r}')


def anon_name(name: str) -> str:
    """
    Return a name unique to this call, as launch's AnonName.compute_name makes it.

    ``NAME_<host name>_<pid>_<random>``, with '.', '-' and ':' replaced by '_'. The
    random part comes from the system's generator (a seeded ``random`` cannot repeat it).
    """
    text = f'{name}_{socket.gethostname()}_{os.getpid()}_{secrets.randbelow(sys.maxsize)}'
    return text.replace('.', '_').replace('-', '_').replace(':', '_')


def parse_launch_arguments(argv: List[str]) -> Dict[str, str]:
    """Parse ``name:=value`` command line arguments, as ``ros2 launch`` takes them."""
    arguments = {}
    for item in argv:
        name, sep, value = item.partition(':=')
        if not sep or not name or not re.fullmatch(r'[A-Za-z_][A-Za-z0-9_]*', name):
            raise SystemDescriptionError(
                f'launch argument {item!r} is not of the form name:=value')
        arguments[name] = value
    return arguments


_ON_STDERR = ('fail', 'ignore', 'warn', 'capture')


@dataclass
class _Substitution:
    """A parsed ``$(kind argument ...)``; each argument is a list of parts."""

    kind: str
    arguments: List[List['_Part']]
    source: str


_Part = Union[str, _Substitution]


class _TemplateParser:
    """
    Splits text into literal text and ``$(...)`` substitutions (launch's frontend syntax).

    A substitution is ``$(`` NAME, then arguments each preceded by spaces, then ``)``.
    An argument is quoted ('...' or "...", holding any text and substitutions) or a run
    of characters other than spaces, quotes and parentheses, with substitutions. In
    quotes a backslash escapes the quote, a backslash or ``$``.
    """

    def __init__(self, text: str, where: str):
        self.text = text
        self.where = where
        self.pos = 0

    def _fail(self, message: str) -> None:
        raise SystemDescriptionError(f'{self.where}: {message} in {self.text!r}')

    def template(self) -> List[_Part]:
        """Parse the whole text."""
        parts: List[_Part] = []
        literal = ''
        while self.pos < len(self.text):
            if self.text.startswith('$(', self.pos):
                parts += [literal] if literal else []
                literal = ''
                parts.append(self._substitution())
            else:
                literal += self.text[self.pos]
                self.pos += 1
        return parts + ([literal] if literal else [])

    def _substitution(self) -> _Substitution:
        start = self.pos
        self.pos += 2
        name = _IDENTIFIER.match(self.text, self.pos)
        if name is None:
            self._fail(f'"$(" at character {start + 1} is not followed by a substitution name')
        self.pos = name.end()
        arguments = []
        while True:
            spaced = self._skip_spaces()
            if self.pos >= len(self.text):
                self._fail(f'the substitution at character {start + 1} has no closing ")"')
            if self.text[self.pos] == ')':
                self.pos += 1
                return _Substitution(name.group(0), arguments, self.text[start:self.pos])
            if not spaced:
                self._fail(f'expected a space or ")" at character {self.pos + 1}')
            arguments.append(self._argument())

    def _skip_spaces(self) -> bool:
        start = self.pos
        while self.pos < len(self.text) and self.text[self.pos].isspace():
            self.pos += 1
        return self.pos > start

    def _argument(self) -> List[_Part]:
        start = self.pos
        quote = self.text[start] if self.text[start] in '\'"' else None
        self.pos += 1 if quote else 0
        parts: List[_Part] = []
        literal = ''
        while True:
            if self.pos >= len(self.text):
                if quote:
                    self._fail(f'the quote at character {start + 1} is not closed')
                break
            char = self.text[self.pos]
            if self.text.startswith('$(', self.pos):
                parts += [literal] if literal else []
                literal = ''
                parts.append(self._substitution())
                continue
            if quote is None and (char.isspace() or char in '()\'"'):
                break
            if char == quote:
                self.pos += 1
                break
            escaped = self.text[self.pos + 1:self.pos + 2]
            if quote and char == '\\' and escaped in (quote, '\\', '$'):
                char = escaped
                self.pos += 1
            literal += char
            self.pos += 1
        return parts + ([literal] if literal else [])


class _Resolver:
    """Resolves substitutions and entities of launch YAML files into a System."""

    def __init__(self, find_package_share: Callable[[str], str], environ: Dict[str, str]):
        self._find_package_share = find_package_share
        self._environ = environ
        # Variables set by set_env entries in force at this point of the files.
        self._set_env: Dict[str, str] = {}
        # Files being read, outermost first, to catch an include of an including file.
        self._include_stack: List[Path] = []
        # $(anon NAME) values, one per NAME for the whole launch (launch keeps them in
        # its launch configurations, which includes share).
        self._anon_names: Dict[str, str] = {}
        self.system = System()

    def substitute(self, value: object, scope: Dict[str, str], where: str,
                   launch_dir: Path) -> str:
        """Return value with every ``$(...)`` substitution performed."""
        parts = _TemplateParser(str(value), where).template()
        return self._evaluate(parts, scope, where, launch_dir)

    def _evaluate(self, parts: List['_Part'], scope: Dict[str, str], where: str,
                  launch_dir: Path) -> str:
        return ''.join(part if isinstance(part, str)
                       else self._perform(part, scope, where, launch_dir) for part in parts)

    def _perform(self, substitution: '_Substitution', scope: Dict[str, str], where: str,
                 launch_dir: Path) -> str:
        kind = substitution.kind
        rest = [self._evaluate(argument, scope, where, launch_dir)
                for argument in substitution.arguments]
        if kind == 'var' and len(rest) == 1:
            if rest[0] not in scope:
                raise SystemDescriptionError(
                    f'{where}: $(var {rest[0]}) is not a declared launch argument '
                    f'(known: {", ".join(sorted(scope)) or "none"})')
            return scope[rest[0]]
        if kind == 'find-pkg-share' and len(rest) == 1:
            try:
                return self._find_package_share(rest[0])
            except LookupError as error:
                raise SystemDescriptionError(
                    f'{where}: package {rest[0]!r} not found ({error}); is the workspace '
                    'built and sourced?') from None
        if kind == 'env' and len(rest) in (1, 2):
            if rest[0] in self._environ:
                return self._environ[rest[0]]
            if len(rest) == 2:
                return rest[1]
            raise SystemDescriptionError(
                f'{where}: environment variable {rest[0]} is not set and has no default')
        if kind == 'dirname' and not rest:
            return str(launch_dir)
        if kind == 'anon' and len(rest) == 1:
            if rest[0] not in self._anon_names:
                self._anon_names[rest[0]] = anon_name(rest[0])
            return self._anon_names[rest[0]]
        if kind == 'command' and len(rest) in (1, 2):
            return self._run_command(rest[0], rest[1] if len(rest) == 2 else 'fail', where)
        raise SystemDescriptionError(
            f'{where}: unsupported substitution {substitution.source!r}')

    def _run_command(self, command: str, on_stderr: str, where: str) -> str:
        """Run a $(command ...) without a shell; return its standard output."""
        what = f'{where}: $(command {command!r})'
        if on_stderr not in _ON_STDERR:
            raise SystemDescriptionError(
                f'{what}: on_stderr must be one of {", ".join(_ON_STDERR)}, got {on_stderr!r}')
        try:
            argv = shlex.split(command)
        except ValueError as error:
            raise SystemDescriptionError(f'{what}: cannot split the command: {error}') from None
        if not argv:
            raise SystemDescriptionError(f'{what}: the command is empty')
        try:
            result = subprocess.run(
                argv, env=self._environ, stdin=subprocess.DEVNULL, capture_output=True,
                encoding='utf-8', errors='replace', timeout=COMMAND_TIMEOUT_S)
        except FileNotFoundError:
            raise SystemDescriptionError(f'{what}: program {argv[0]!r} not found') from None
        except OSError as error:
            raise SystemDescriptionError(f'{what}: cannot run {argv[0]!r}: {error}') from None
        except subprocess.TimeoutExpired:
            raise SystemDescriptionError(
                f'{what}: still running after {COMMAND_TIMEOUT_S:g} s, stopped') from None
        errors = result.stderr.strip()
        if result.returncode != 0:
            raise SystemDescriptionError(
                f'{what} failed with exit code {result.returncode}'
                + (f':\n{errors}' if errors else ' (no error output)'))
        if errors and on_stderr == 'fail':
            raise SystemDescriptionError(
                f"{what} wrote to standard error (add 'ignore', 'warn' or 'capture' after "
                f'the command to accept that):\n{errors}')
        if errors and on_stderr == 'warn':
            print(f'warning: {what} wrote to standard error:\n{errors}', file=sys.stderr)
        if on_stderr == 'capture':
            return result.stdout + result.stderr
        return result.stdout

    def load(self, path: Path, inherited: Dict[str, str]) -> None:
        """
        Read one launch file.

        ``inherited`` holds the launch configurations visible to it: as in ROS 2
        launch, command line arguments and the including file's configurations
        flow into included files, and an include's ``arg`` entries add to them.
        """
        path = description_file(path)
        if not path.is_file():
            raise SystemDescriptionError(f'launch file {path} does not exist')
        if path in self._include_stack:
            raise SystemDescriptionError(f'{path}: included recursively')
        self.system.files.append(path)
        try:
            document = yaml.safe_load(path.read_text())
        except yaml.YAMLError as error:
            raise SystemDescriptionError(f'{path}: not valid YAML: {error}') from None
        if not isinstance(document, dict) or set(document) != {'launch'} \
                or not isinstance(document['launch'], list):
            raise SystemDescriptionError(
                f'{path}: a launch YAML file must be a mapping with one key, "launch", '
                'holding a list of entries')
        scope = dict(inherited)
        # As in ROS 2 launch, an included file's set_env does not leak out of it.
        saved_environ, saved_set_env = self._environ, self._set_env
        self._include_stack.append(path)
        self._load_entries(path, document['launch'], scope)
        self._include_stack.pop()
        self._environ, self._set_env = saved_environ, saved_set_env

    def _load_entries(self, path: Path, entries: list, scope: Dict[str, str]) -> None:
        for index, entry in enumerate(entries):
            where = f'{path.name}: entry {index + 1}'
            if not isinstance(entry, dict) or len(entry) != 1:
                raise SystemDescriptionError(
                    f'{where}: each entry must be a mapping with exactly one key '
                    '(arg, let, set_env, include or node)')
            (kind, body), = entry.items()
            if not isinstance(body, dict):
                raise SystemDescriptionError(f'{where}: "{kind}" must hold a mapping')
            where = f'{where} ({kind})'
            if kind != 'arg' and ('if' in body or 'unless' in body):
                body = dict(body)
                if not self._condition(body.pop('if', None), body.pop('unless', None), scope,
                                       where, path.parent):
                    continue
            if kind == 'arg':
                self._declare_argument(body, scope, where, path.parent)
            elif kind == 'let':
                name = str(self._required(body, 'name', where))
                scope[name] = self.substitute(self._required(body, 'value', where), scope,
                                              where, path.parent)
            elif kind == 'set_env':
                name = str(self._required(body, 'name', where))
                value = self.substitute(self._required(body, 'value', where), scope, where,
                                        path.parent)
                self._set_env = dict(self._set_env, **{name: value})
                self._environ = dict(self._environ, **{name: value})
            elif kind == 'include':
                self._include(body, scope, where, path.parent)
            elif kind == 'node':
                self.system.nodes.append(self._node(body, scope, where, path.parent))
            else:
                raise SystemDescriptionError(
                    f'{where}: unsupported entry "{kind}" (supported: arg, let, set_env, '
                    'include, node)')

    def _condition(self, if_value: object, unless_value: object, scope: Dict[str, str],
                   where: str, launch_dir: Path) -> bool:
        """Evaluate an entry's ``if`` / ``unless`` (ROS launch's IfCondition / UnlessCondition)."""
        run = True
        if if_value is not None:
            run = parse_bool(self.substitute(if_value, scope, where, launch_dir),
                             f'{where}: "if"')
        if unless_value is not None:
            run = run and not parse_bool(self.substitute(unless_value, scope, where,
                                                         launch_dir), f'{where}: "unless"')
        return run

    @staticmethod
    def _required(body: dict, key: str, where: str) -> object:
        if key not in body or body[key] is None:
            raise SystemDescriptionError(f'{where}: missing "{key}"')
        return body[key]

    def _declare_argument(self, body: dict, scope: Dict[str, str], where: str,
                          launch_dir: Path) -> None:
        name = str(self._required(body, 'name', where))
        unknown = set(body) - {'name', 'default', 'description', 'choices'}
        if unknown:
            raise SystemDescriptionError(f'{where}: unknown key(s) {sorted(unknown)}')
        if name not in scope:
            if 'default' not in body:
                raise SystemDescriptionError(
                    f'{where}: launch argument "{name}" has no default and was not given '
                    f'(pass {name}:=VALUE)')
            scope[name] = self.substitute(body['default'], scope, where, launch_dir)
        choices = body.get('choices')
        if choices is not None and scope[name] not in [str(c) for c in choices]:
            raise SystemDescriptionError(
                f'{where}: launch argument {name}:={scope[name]!r} is not one of {choices}')
        self.system.arguments.setdefault(name, scope[name])

    def _include(self, body: dict, scope: Dict[str, str], where: str, launch_dir: Path):
        file_name = self.substitute(self._required(body, 'file', where), scope, where,
                                    launch_dir)
        included_path = Path(file_name)
        if not included_path.is_absolute():
            included_path = launch_dir / included_path
        passed = dict(scope)
        for item in body.get('arg') or []:
            if not isinstance(item, dict) or 'name' not in item or 'value' not in item:
                raise SystemDescriptionError(f'{where}: each include arg needs name and value')
            passed[str(item['name'])] = self.substitute(item['value'], scope, where, launch_dir)
        self.load(included_path, passed)

    def _node(self, body: dict, scope: Dict[str, str], where: str,
              launch_dir: Path) -> NodeProcess:
        unknown = set(body) - _NODE_KEYS
        if unknown:
            raise SystemDescriptionError(
                f'{where}: unknown key(s) {sorted(unknown)}; supported: {sorted(_NODE_KEYS)}')

        def sub(value: object) -> str:
            return self.substitute(value, scope, where, launch_dir)

        for key in _NODE_TEXT_KEYS:
            if key in body and not isinstance(body[key], str):
                raise SystemDescriptionError(
                    f'{where}: {key} must be text (quote it: {key}: {yaml_scalar(body[key])!r}), '
                    f'got {type(body[key]).__name__} {body[key]!r}; ROS 2 launch rejects it')
        node = NodeProcess(package=sub(self._required(body, 'pkg', where)),
                           executable=sub(self._required(body, 'exec', where)),
                           env=dict(self._set_env))
        where = f'{where} {node.package}/{node.executable}'
        if body.get('name'):
            node.name = sub(body['name'])
        if body.get('namespace'):
            node.namespace = sub(body['namespace'])
        for item in body.get('param') or []:
            node.parameters.append(self._parameter(item, sub, where))
        for item in body.get('remap') or []:
            if not isinstance(item, dict) or set(item) != {'from', 'to'}:
                raise SystemDescriptionError(f'{where}: each remap needs exactly from and to')
            node.remappings.append((sub(item['from']), sub(item['to'])))
        for item in body.get('env') or []:
            if not isinstance(item, dict) or set(item) != {'name', 'value'}:
                raise SystemDescriptionError(f'{where}: each env entry needs name and value')
            node.env[sub(item['name'])] = sub(item['value'])
        node.arguments = shlex.split(sub(body.get('args', '')))
        node.ros_arguments = shlex.split(sub(body.get('ros_args', '')))
        node.launch_prefix = shlex.split(sub(body.get('launch-prefix', '')))
        node.respawn = parse_bool(sub(body.get('respawn', 'false')), f'{where}: respawn')
        delay = body.get('respawn_delay', 0.0)
        if not isinstance(delay, float):
            # launch_yaml takes a float as it is (an int or a quoted number fails there).
            raise SystemDescriptionError(
                f'{where}: respawn_delay must be a number with a decimal point, unquoted '
                f'(e.g. respawn_delay: 1.0), got {type(delay).__name__} {delay!r}; ROS 2 '
                'launch rejects it')
        node.respawn_delay_s = delay
        if not node.respawn_delay_s >= 0.0:
            raise SystemDescriptionError(f'{where}: respawn_delay must be >= 0')
        on_exit = sub(body.get('on_exit', '')).strip()
        if on_exit not in ('', 'shutdown'):
            raise SystemDescriptionError(f'{where}: on_exit supports only "shutdown"')
        node.shutdown_on_exit = on_exit == 'shutdown'
        return node

    @staticmethod
    def _parameter(item: object, sub: Callable[[object], str], where: str) -> object:
        if isinstance(item, dict) and set(item) == {'from'}:
            path = Path(sub(item['from']))
            if not path.is_file():
                raise SystemDescriptionError(f'{where}: parameter file {path} does not exist')
            try:
                content = yaml.safe_load(path.read_text())
            except yaml.YAMLError as error:
                raise SystemDescriptionError(
                    f'{where}: parameter file {path} is not valid YAML: {error}') from None
            if not isinstance(content, dict):
                raise SystemDescriptionError(
                    f'{where}: parameter file {path} must map node names to ros__parameters')
            return path
        if isinstance(item, dict) and set(item) == {'name', 'value'}:
            value = item['value']
            if isinstance(value, str) and '$(' in value:
                # As launch_ros does: evaluate substitutions, then read the text as YAML.
                # Text without one stays text: value: 'true' is the string 'true' (a
                # node declaring a bool then fails), value: true the bool.
                text = sub(value)
                try:
                    value = yaml.safe_load(text) if text.strip() else text
                except yaml.YAMLError:
                    value = text
            return (str(item['name']), value)
        raise SystemDescriptionError(
            f'{where}: each param entry is either {{from: FILE}} or {{name: N, value: V}}')


def default_find_package_share(package: str) -> str:
    """Find a package's share directory through the ament index."""
    from ament_index_python.packages import get_package_share_directory
    from ament_index_python.packages import PackageNotFoundError
    try:
        return get_package_share_directory(package)
    except PackageNotFoundError as error:
        raise LookupError(str(error)) from None


def load_system(path: Path, arguments: Optional[Dict[str, str]] = None,
                find_package_share: Callable[[str], str] = default_find_package_share,
                environ: Optional[Dict[str, str]] = None) -> System:
    """
    Read a system description and everything it includes into a System.

    ``path`` may name the ``.launch.py`` wrapper; its ``.launch.yaml`` is read.
    Raises SystemDescriptionError with a message naming the file and entry.
    """
    path = description_file(path)
    resolver = _Resolver(find_package_share, dict(os.environ if environ is None else environ))
    arguments = dict(arguments or {})
    resolver.load(path, arguments)
    undeclared = sorted(set(arguments) - set(resolver.system.arguments))
    if undeclared:
        raise SystemDescriptionError(
            f'{path.name}: unknown launch argument(s) {", ".join(undeclared)}; declared: '
            f'{", ".join(sorted(resolver.system.arguments)) or "none"}')
    if not resolver.system.nodes:
        raise SystemDescriptionError(f'{path}: the system has no nodes')
    return resolver.system
