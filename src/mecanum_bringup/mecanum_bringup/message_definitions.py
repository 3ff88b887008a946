"""
Complete ROS 2 message definitions in the ``ros2msg`` encoding (pure, no rclpy).

A recording or a live viewer that has no compiled message types (MCAP readers, the
Foxglove app) decodes CDR with the full definition of a type: its ``.msg`` text,
then each nested type once, preceded by a line of 80 ``=`` and a line
``MSG: pkg/Type``. The text is built the way rosbag2 (Jazzy) builds it for the MCAP
schemas it writes, so our bags carry byte-identical schemas: the ``.msg`` files are
read unchanged from ``share/<pkg>/msg/`` (found through the ament index, so this
works in the pip setup and on an apt install), a type's dependencies are the field
types named in its text (types without a package are in the same package), sorted
by name, visited depth first, each written once, the first time it is met.
"""

import functools
import os
import re
from typing import List, Tuple

from ament_index_python.packages import get_package_share_directory, PackageNotFoundError

#: The line that separates the definitions of nested types.
SEPARATOR = '=' * 80
#: Field types that are not messages.
PRIMITIVE_TYPES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string'))
#: Deepest nesting of message types followed (rosbag2's limit).
MAX_DEPTH = 50

# A field type at the start of a line (after blanks), optionally an array, then blanks.
# Comment lines ('#') and bounded strings ('string<=5') do not match. ASCII blanks only.
_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+', re.ASCII)
_NAME = r'[a-zA-Z][a-zA-Z0-9_]*'
_TYPE_NAME = re.compile(rf'({_NAME})/(?:({_NAME})/)?({_NAME})')


class MessageDefinitionError(LookupError):
    """A message type whose definition cannot be found or resolved."""


def split_type_name(type_name: str) -> Tuple[str, str, str]:
    """Split 'pkg/msg/Type' (or 'pkg/Type') into (package, 'msg', type)."""
    match = _TYPE_NAME.fullmatch(type_name) if isinstance(type_name, str) else None
    if match is None:
        raise MessageDefinitionError(
            f'not a message type name: {type_name!r} (expected pkg/msg/Type)')
    package, namespace, name = match.groups()
    return package, namespace or 'msg', name


def msg_dependencies(text: str, package: str) -> List[str]:
    """Return the message types a .msg text uses, as written ('pkg/Type'), sorted, once."""
    found = set()
    for match in _FIELD_TYPE.finditer(text):
        field_type = match.group(1)
        if field_type in PRIMITIVE_TYPES:
            continue
        found.add(field_type if '/' in field_type else f'{package}/{field_type}')
    return sorted(found)


@functools.lru_cache(maxsize=None)
def msg_text(type_name: str) -> str:
    """Return the unchanged text of a type's .msg file (found through the ament index)."""
    package, namespace, name = split_type_name(type_name)
    try:
        share = get_package_share_directory(package)
    except (PackageNotFoundError, ValueError) as error:
        raise MessageDefinitionError(
            f'no definition of {type_name}: package {package!r} not found ({error})') from None
    path = os.path.join(share, namespace, name + '.msg')
    try:
        with open(path, encoding='utf-8', newline='') as file:
            return file.read()
    except (OSError, UnicodeDecodeError) as error:
        raise MessageDefinitionError(
            f'no definition of {type_name}: cannot read {path} ({error})') from None


@functools.lru_cache(maxsize=None)
def message_definition(type_name: str) -> str:
    """
    Return the complete ros2msg definition of type_name ('pkg/msg/Type'), as rosbag2 does.

    Raises MessageDefinitionError naming the type for unknown packages or types,
    malformed names and definitions nested deeper than MAX_DEPTH. A type that
    contains itself (invalid in ROS) is expanded once more, then not again, as by rosbag2.
    """
    seen = set()

    def expand(name: str, depth: int) -> str:
        if depth > MAX_DEPTH:
            raise MessageDefinitionError(
                f'definition of {type_name} nests deeper than {MAX_DEPTH} types')
        text = msg_text(name)
        parts = [text]
        for dependency in msg_dependencies(text, split_type_name(name)[0]):
            if dependency in seen:
                continue
            seen.add(dependency)
            parts.append(f'\n{SEPARATOR}\nMSG: {dependency}\n')
            parts.append(expand(dependency, depth + 1))
        return ''.join(parts)

    try:
        return expand(type_name, 1)
    except MessageDefinitionError as error:
        if type_name in str(error):
            raise
        raise MessageDefinitionError(f'cannot define {type_name}: {error}') from None
