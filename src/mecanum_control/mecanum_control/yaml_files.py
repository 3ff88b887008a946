"""
Reading and checking the workspace's YAML files, with one kind of error message (pure).

Scenario, sweep and world files are read the same way: the text (UTF-8), then one YAML
document with PyYAML's C safe loader where there is one. What goes wrong becomes the
caller's error type with a message that names the file:

- ``PATH: no such WHAT`` (e.g. 'no such scenario file');
- ``PATH: cannot read WHAT: REASON`` (permissions, a folder, not UTF-8);
- ``NAME: YAML syntax error at line L, column C: PROBLEM``.

:class:`DocumentChecker` then checks the document's values the same way for every kind
of file: each failure is the caller's error type with a message naming the file (and the
line, where the caller has the keys' lines, see :func:`key_lines`) and the key, e.g.
``tour.yaml: steps[3].goal.yaw: must be a number, not 'north'``.
"""

import math
from pathlib import Path
import re
from typing import Any, Callable, Dict, Mapping, NoReturn, Optional, Sequence, Tuple, Union

import yaml

#: PyYAML's safe loader, the C one when PyYAML was built with libyaml (10x faster).
SAFE_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)

PathLike = Union[str, Path]
ErrorType = Callable[[str], Exception]

#: What a name (of a scenario, a sweep, ...) may be made of.
IDENTIFIER = re.compile(r'[A-Za-z0-9_-]+')
#: The last part of a key path: '.name' or '[index]'.
_LAST_KEY = re.compile(r'(\.[^.\[]*|\[\d+\])$')


def read_text_file(path: PathLike, what: str, error: ErrorType) -> str:
    """Return the UTF-8 text of path; raise error('PATH: no such WHAT' / 'cannot read ...')."""
    path = Path(path)
    try:
        return path.read_text(encoding='utf-8')
    except FileNotFoundError:
        raise error(f'{path}: no such {what}') from None
    except (OSError, UnicodeDecodeError) as problem:
        raise error(f'{path}: cannot read {what}: {problem}') from None


def syntax_error_message(label: str, problem: yaml.YAMLError) -> str:
    """Return 'LABEL: YAML syntax error at line L, column C: PROBLEM' (lines from 1)."""
    mark = getattr(problem, 'problem_mark', None)
    text = getattr(problem, 'problem', None) or str(problem)
    where = f' at line {mark.line + 1}, column {mark.column + 1}' if mark else ''
    return f'{label}: YAML syntax error{where}: {text}'


def load_yaml_file(path: PathLike, what: str, error: ErrorType) -> Any:
    """Return the one YAML document of path (None when empty); errors as the module says."""
    path = Path(path)
    text = read_text_file(path, what, error)
    try:
        return yaml.load(text, Loader=SAFE_LOADER)
    except yaml.YAMLError as problem:
        raise error(syntax_error_message(path.name, problem)) from None


def load_yaml_file_with_nodes(path: PathLike, what: str,
                              error: ErrorType) -> Tuple[Any, Optional[yaml.Node]]:
    """
    Return (document, its composed node tree) of path, parsed once; (None, None) if empty.

    The node tree has every key's line (``start_mark``), for messages naming the line of
    a bad value.
    """
    path = Path(path)
    loader = SAFE_LOADER(read_text_file(path, what, error))
    try:
        node = loader.get_single_node()
        return (loader.construct_document(node) if node is not None else None), node
    except yaml.YAMLError as problem:
        raise error(syntax_error_message(path.name, problem)) from None
    finally:
        loader.dispose()


def join_key(parent: str, name: Any) -> str:
    """Return the key path of name inside parent: 'PARENT.NAME', or 'NAME' at the top."""
    return f'{parent}.{name}' if parent else str(name)


def parent_key(key: str) -> str:
    """Return the key path without its last part: 'a.b[2]' -> 'a.b' -> 'a' -> ''."""
    parent = _LAST_KEY.sub('', key)
    return parent if parent != key else ''


def key_lines(node: Optional[yaml.Node]) -> Dict[str, int]:
    """
    Return {key path: line (from 1)} for a composed YAML node tree (None: {}).

    Key paths are dotted, with list indices: 'sweep.axes.seed[1]'; '' is the document's
    first line. A key's line is the line of the key itself, not of its value.
    """
    lines: Dict[str, int] = {}
    if node is not None:
        _record_lines(node, '', lines)
    return lines


def _record_lines(node: yaml.Node, key: str, lines: Dict[str, int]) -> None:
    lines.setdefault(key, node.start_mark.line + 1)
    if isinstance(node, yaml.MappingNode):
        for key_node, value_node in node.value:
            child = join_key(key, key_node.value)
            lines[child] = key_node.start_mark.line + 1
            _record_lines(value_node, child, lines)
    elif isinstance(node, yaml.SequenceNode):
        for index, item in enumerate(node.value):
            _record_lines(item, f'{key}[{index}]', lines)


def _say(what: str, message: str) -> str:
    return f'{what} {message}' if what else message


class DocumentChecker:
    """
    Checks the values of one YAML document; every failure names the file and the key.

    A failure raises ``error('LABEL: KEY: MESSAGE')`` (``'LABEL: MESSAGE'`` for the empty
    key), with ``LABEL:LINE`` when ``lines`` ({key path: line}, see :func:`key_lines`)
    has the key or one of its parents. A key is a dotted path with list indices, e.g.
    ``steps[0].goal.x``; ``top_key`` is what the empty path is called in a missing key's
    message. Where a method takes ``what``, the key names an entry and ``what`` the value
    inside it: ``walls[0]: thickness_m must be > 0, not 0``.

    Subclasses add the checks of their kind of document.
    """

    def __init__(self, error: ErrorType, label: str,
                 lines: Optional[Mapping[str, int]] = None, top_key: str = ''):
        self.error = error
        self.label = label
        self.lines: Mapping[str, int] = lines or {}
        self.top_key = top_key

    def line(self, key: str) -> Optional[int]:
        """Return the line of key, or of its nearest parent in lines; None if neither."""
        while key and key not in self.lines:
            key = parent_key(key)
        return self.lines.get(key)

    def fail(self, key: str, message: str) -> NoReturn:
        """Raise error('LABEL[:LINE]: KEY: MESSAGE'), or 'LABEL[:LINE]: MESSAGE' for key ''."""
        line = self.line(key)
        where = f'{self.label}:{line}' if line else self.label
        raise self.error(f'{where}: {key}: {message}' if key else f'{where}: {message}')

    def document(self, doc: Any, name: str) -> Any:
        """Return doc[name] of a document that must be one top-level mapping 'NAME: ...'."""
        if not isinstance(doc, dict) or name not in doc:
            self.fail('', f'expected a top-level "{name}:" mapping')
        for key in doc:
            if key != name:
                self.fail(str(key), f'unknown top-level key (only "{name}:" is allowed)')
        return doc[name]

    def mapping(self, value: Any, key: str, required: Sequence[str] = (),
                optional: Sequence[str] = ()) -> Dict[str, Any]:
        """Return value if it is a mapping with the required keys and no unknown ones."""
        allowed = ', '.join(list(required) + list(optional))
        if not isinstance(value, dict):
            self.fail(key, f'must be a mapping with keys {allowed}, not {value!r}')
        for name in value:
            if name not in required and name not in optional:
                self.fail(join_key(key, name), f'unknown key (allowed: {allowed})')
        for name in required:
            if name not in value:
                self.fail(key or self.top_key, f"missing key '{name}'")
        return value

    def number(self, value: Any, key: str, what: str = '', *,
               minimum: Optional[float] = None) -> float:
        """Return value as a finite float (>= minimum when given)."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(key, _say(what, f'must be a number, not {value!r}'))
        if not math.isfinite(value):
            self.fail(key, _say(what, f'must be a finite number, not {value}'))
        if minimum is not None and value < minimum:
            self.fail(key, _say(what, f'must be >= {minimum:g}, not {value}'))
        return float(value)

    def positive(self, value: Any, key: str, what: str = '') -> float:
        """Return value as a finite float > 0."""
        number = self.number(value, key, what)
        if number <= 0.0:
            self.fail(key, _say(what, f'must be > 0, not {value}'))
        return number

    def optional_positive(self, value: Any, key: str, what: str = '') -> Optional[float]:
        """Return None for null, else value as a finite float > 0."""
        return None if value is None else self.positive(value, key, what)

    def integer(self, value: Any, key: str, minimum: int = 0, what: str = '') -> int:
        """Return value if it is an integer >= minimum (true and false are not)."""
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            self.fail(key, _say(what, f'must be an integer >= {minimum}, not {value!r}'))
        return value

    def numbers(self, value: Any, key: str, count: int, what: str = '') -> Tuple[float, ...]:
        """
        Return a list of exactly count finite numbers as a tuple of floats.

        A bad item is reported at key with what, or without what at 'KEY[INDEX]'.
        """
        if not isinstance(value, (list, tuple)) or len(value) != count:
            self.fail(key, _say(what, f'must be {count} numbers, not {value!r}'))
        return tuple(self.number(item, key if what else f'{key}[{index}]', what)
                     for index, item in enumerate(value))

    def boolean(self, value: Any, key: str, what: str = '') -> bool:
        """Return value if it is true or false."""
        if not isinstance(value, bool):
            self.fail(key, _say(what, f'must be true or false, not {value!r}'))
        return value

    def choice(self, value: Any, key: str, choices: Sequence[str], what: str = '') -> str:
        """Return value if it is one of choices."""
        if not isinstance(value, str) or value not in choices:
            self.fail(key, _say(what, f'must be one of {", ".join(choices)}, not {value!r}'))
        return value

    def text(self, value: Any, key: str, what: str = '') -> str:
        """Return value if it is a string that is not empty or blank."""
        if not isinstance(value, str) or not value.strip():
            self.fail(key, _say(what, f'must be a non-empty string, not {value!r}'))
        return value

    def identifier(self, value: Any, key: str, what: str = '') -> str:
        """Return value if it is a name of letters, digits, _ and - (IDENTIFIER)."""
        if not isinstance(value, str) or not IDENTIFIER.fullmatch(value):
            message = f'must be letters, digits, _ and - only, not {value!r}'
            self.fail(key, _say(what, message))
        return value
