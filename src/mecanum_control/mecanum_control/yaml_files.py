"""
Reading the workspace's YAML files with one kind of error message (pure, no ROS).

Scenario, sweep and world files are read the same way: the text (UTF-8), then one YAML
document with PyYAML's C safe loader where there is one. What goes wrong becomes the
caller's error type with a message that names the file:

- ``PATH: no such WHAT`` (e.g. 'no such scenario file');
- ``PATH: cannot read WHAT: REASON`` (permissions, a folder, not UTF-8);
- ``NAME: YAML syntax error at line L, column C: PROBLEM``.
"""

from pathlib import Path
from typing import Any, Callable, Optional, Tuple, Union

import yaml

#: PyYAML's safe loader, the C one when PyYAML was built with libyaml (10x faster).
SAFE_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)

PathLike = Union[str, Path]
ErrorType = Callable[[str], Exception]


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
