"""
The command line of tf2_ros' static_transform_publisher, parsed to a Transform (pure).

Accepted, as in ROS 2 Jazzy's tf2_ros::StaticTransformBroadcasterNode::
``--x X --y Y --z Z`` (m, default 0), then either ``--yaw Y --pitch P --roll R``
(rad, default 0, applied yaw about z, then pitch about y, then roll about x) or
``--qx --qy --qz --qw`` (a quaternion, normalised; not both forms), and
``--frame-id PARENT --child-frame-id CHILD`` (both required, different). The old
positional form ``x y z yaw pitch roll parent child`` is accepted too.
"""

import argparse
import math
from typing import List, Sequence

from mecanum_description.robot_model import quaternion_from_rpy, Transform


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser that raises ValueError instead of exiting."""

    def error(self, message: str) -> None:
        raise ValueError(f'static_transform_publisher: {message}')


def _parser() -> _Parser:
    parser = _Parser(prog='static_transform_publisher', add_help=False)
    for name in ('x', 'y', 'z', 'yaw', 'pitch', 'roll', 'qx', 'qy', 'qz', 'qw'):
        parser.add_argument(f'--{name}', type=float)
    parser.add_argument('--frame-id', dest='frame_id')
    parser.add_argument('--child-frame-id', dest='child_frame_id')
    parser.add_argument('positional', nargs='*')
    return parser


def parse_static_transform(argv: Sequence[str]) -> Transform:
    """Return the transform (parent = frame id, child = child frame id) argv describes."""
    options = _parser().parse_args(list(argv))
    if options.positional:
        return _positional(options.positional)
    values = {name: getattr(options, name) for name in
              ('x', 'y', 'z', 'yaw', 'pitch', 'roll', 'qx', 'qy', 'qz', 'qw')}
    for name, value in values.items():
        if value is not None and not math.isfinite(value):
            raise ValueError(f'static_transform_publisher: --{name} must be finite, got {value}')
    euler = any(values[n] is not None for n in ('yaw', 'pitch', 'roll'))
    quaternion = [values[n] for n in ('qx', 'qy', 'qz', 'qw')]
    if euler and any(q is not None for q in quaternion):
        raise ValueError('static_transform_publisher: give either --yaw/--pitch/--roll '
                         'or --qx/--qy/--qz/--qw, not both')
    if any(q is not None for q in quaternion):
        rotation = _normalised([0.0 if q is None else q for q in quaternion[:3]]
                               + [1.0 if quaternion[3] is None else quaternion[3]])
    else:
        rotation = quaternion_from_rpy(values['roll'] or 0.0, values['pitch'] or 0.0,
                                       values['yaw'] or 0.0)
    translation = tuple(values[n] or 0.0 for n in ('x', 'y', 'z'))
    return _checked(options.frame_id, options.child_frame_id, translation, rotation)


def _positional(words: List[str]) -> Transform:
    if len(words) != 8:
        raise ValueError('static_transform_publisher: expected --frame-id and '
                         '--child-frame-id options, or 8 positional arguments '
                         f'x y z yaw pitch roll parent child, got {words}')
    try:
        numbers = [float(w) for w in words[:6]]
    except ValueError:
        raise ValueError(f'static_transform_publisher: not numbers: {words[:6]}') from None
    if not all(math.isfinite(n) for n in numbers):
        raise ValueError(f'static_transform_publisher: values must be finite, got {words[:6]}')
    x, y, z, yaw, pitch, roll = numbers
    return _checked(words[6], words[7], (x, y, z), quaternion_from_rpy(roll, pitch, yaw))


def _normalised(q: List[float]) -> tuple:
    norm = math.sqrt(sum(v * v for v in q))
    if not math.isfinite(norm) or norm < 1e-9:
        raise ValueError(f'static_transform_publisher: quaternion {q} cannot be normalised')
    return tuple(v / norm for v in q)


def _checked(parent, child, translation, rotation) -> Transform:
    if not parent or not child:
        raise ValueError('static_transform_publisher: --frame-id and --child-frame-id '
                         'are required')
    if parent == child:
        raise ValueError(f'static_transform_publisher: frame id and child frame id are '
                         f'both {parent!r}')
    return Transform(parent, child, tuple(float(v) for v in translation), rotation)
