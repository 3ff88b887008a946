"""
A URDF robot model: links, joints and the transforms between them (pure, no ROS).

:func:`parse_urdf` reads URDF XML into a validated :class:`RobotModel` (one root link,
no cycles, every joint's parent and child exist, finite numbers). Transforms follow
URDF and tf2: a joint's transform takes points from the child frame to the parent
frame, ``p_parent = origin * motion(position) * p_child``. Rotations are quaternions
``(x, y, z, w)``; ``rpy`` is URDF's fixed-axis roll (about x), then pitch (about y),
then yaw (about z), i.e. ``R = Rz(yaw) Ry(pitch) Rx(roll)``. Units: m and rad.

Joints that never move (``fixed``, and, as robot_state_publisher does, ``floating``
and ``planar``, which it cannot represent) belong on ``/tf_static``; ``revolute``,
``continuous`` (rotation about the axis by the position, rad) and ``prismatic``
(translation along the axis by the position, m) joints move.
"""

from dataclasses import dataclass
import math
from typing import Dict, List, Mapping, Optional, Sequence, Tuple
import xml.etree.ElementTree as ElementTree

Vector = Tuple[float, float, float]
Quaternion = Tuple[float, float, float, float]

IDENTITY: Quaternion = (0.0, 0.0, 0.0, 1.0)
MOVING_TYPES = ('revolute', 'continuous', 'prismatic')
STATIC_TYPES = ('fixed', 'floating', 'planar')


class UrdfError(ValueError):
    """A robot description is not valid URDF (the message names the link or joint)."""


# --- Quaternion math -------------------------------------------------------------------


def quaternion_multiply(a: Quaternion, b: Quaternion) -> Quaternion:
    """Hamilton product a * b (rotate by b, then by a)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


def quaternion_from_axis_angle(axis: Vector, angle_rad: float) -> Quaternion:
    """Rotation by angle_rad about axis (any non-zero length; right-hand rule)."""
    norm = math.sqrt(sum(c * c for c in axis))
    if not norm > 0.0:
        raise ValueError(f'rotation axis must not be zero, got {axis}')
    half = 0.5 * angle_rad
    s = math.sin(half) / norm
    return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(half))


def quaternion_from_rpy(roll: float, pitch: float, yaw: float) -> Quaternion:
    """URDF rpy (fixed axes: roll about x, then pitch about y, then yaw about z)."""
    qx = quaternion_from_axis_angle((1.0, 0.0, 0.0), roll)
    qy = quaternion_from_axis_angle((0.0, 1.0, 0.0), pitch)
    qz = quaternion_from_axis_angle((0.0, 0.0, 1.0), yaw)
    return quaternion_multiply(qz, quaternion_multiply(qy, qx))


def rotate_vector(q: Quaternion, v: Vector) -> Vector:
    """Rotate vector v by unit quaternion q (q v q*)."""
    x, y, z, w = q
    # v + 2 w (u x v) + 2 u x (u x v), with u the vector part of q.
    cx = y * v[2] - z * v[1]
    cy = z * v[0] - x * v[2]
    cz = x * v[1] - y * v[0]
    return (v[0] + 2.0 * (w * cx + y * cz - z * cy),
            v[1] + 2.0 * (w * cy + z * cx - x * cz),
            v[2] + 2.0 * (w * cz + x * cy - y * cx))


# --- Model -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Transform:
    """The pose of child in parent: p_parent = rotation * p_child + translation."""

    parent: str
    child: str
    translation: Vector
    rotation: Quaternion

    def then(self, other: 'Transform') -> 'Transform':
        """Compose self (parent -> child) with other (child -> grandchild)."""
        if other.parent != self.child:
            raise ValueError(f'cannot chain {self.parent}->{self.child} with '
                             f'{other.parent}->{other.child}')
        moved = rotate_vector(self.rotation, other.translation)
        return Transform(self.parent, other.child,
                         tuple(a + b for a, b in zip(self.translation, moved)),
                         quaternion_multiply(self.rotation, other.rotation))


@dataclass(frozen=True)
class Inertial:
    """Mass (kg), centre of mass pose in the link and inertia tensor (kg m^2) there."""

    mass_kg: float
    origin_xyz: Vector
    origin_rpy: Vector
    ixx: float
    ixy: float
    ixz: float
    iyy: float
    iyz: float
    izz: float

    def matrix(self) -> Tuple[Vector, Vector, Vector]:
        """Return the symmetric 3x3 inertia tensor, rows."""
        return ((self.ixx, self.ixy, self.ixz),
                (self.ixy, self.iyy, self.iyz),
                (self.ixz, self.iyz, self.izz))


@dataclass(frozen=True)
class Link:
    """A URDF link (only what transforms and mass properties need)."""

    name: str
    inertial: Optional[Inertial] = None


@dataclass(frozen=True)
class Mimic:
    """The joint follows another: position = multiplier * other + offset."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class Joint:
    """A URDF joint: type, parent and child links, origin, axis, limits, mimic."""

    name: str
    joint_type: str
    parent: str
    child: str
    origin_xyz: Vector = (0.0, 0.0, 0.0)
    origin_rpy: Vector = (0.0, 0.0, 0.0)
    axis: Vector = (1.0, 0.0, 0.0)
    lower: Optional[float] = None
    upper: Optional[float] = None
    effort: Optional[float] = None
    velocity: Optional[float] = None
    mimic: Optional[Mimic] = None

    @property
    def moving(self) -> bool:
        """Tell whether the joint has a position (revolute, continuous, prismatic)."""
        return self.joint_type in MOVING_TYPES

    def origin(self) -> Transform:
        """Return the parent -> child transform at position 0."""
        return Transform(self.parent, self.child, self.origin_xyz,
                         quaternion_from_rpy(*self.origin_rpy))

    def transform(self, position: float = 0.0) -> Transform:
        """Return the parent -> child transform at position (rad or m)."""
        origin = self.origin()
        if not self.moving or position == 0.0:
            return origin
        if self.joint_type == 'prismatic':
            motion = Transform(self.child, self.child,
                               tuple(a * position for a in self.axis), IDENTITY)
        else:
            motion = Transform(self.child, self.child, (0.0, 0.0, 0.0),
                               quaternion_from_axis_angle(self.axis, position))
        return origin.then(motion)


@dataclass(frozen=True)
class RobotModel:
    """A validated robot: links, joints (in file order) and the root link."""

    name: str
    links: Dict[str, Link]
    joints: Dict[str, Joint]
    root: str

    def static_joints(self) -> List[Joint]:
        """Joints whose transform never changes (for /tf_static)."""
        return [j for j in self.joints.values() if not j.moving]

    def moving_joints(self) -> List[Joint]:
        """Joints with a position (revolute, continuous, prismatic), in file order."""
        return [j for j in self.joints.values() if j.moving]

    def fixed_transforms(self) -> List[Transform]:
        """Return the transforms of all static joints."""
        return [j.transform() for j in self.static_joints()]

    def joint_transform(self, name: str, position: float) -> Transform:
        """Return the transform of moving joint name at position; KeyError if unknown."""
        return self.joints[name].transform(position)

    def parent_joint(self, link: str) -> Optional[Joint]:
        """Return the joint whose child is link (None for the root)."""
        for joint in self.joints.values():
            if joint.child == link:
                return joint
        return None

    def link_pose(self, link: str, positions: Optional[Mapping[str, float]] = None,
                  base: Optional[str] = None) -> Transform:
        """
        Pose of link in base (default the root), through the chain of joints.

        Joint positions not given are 0. base must be an ancestor of link.
        """
        base = base or self.root
        if link not in self.links or base not in self.links:
            raise KeyError(f'unknown link {link if link not in self.links else base!r}')
        positions = positions or {}
        chain = []
        current = link
        while current != base:
            joint = self.parent_joint(current)
            if joint is None:
                raise ValueError(f'link {base!r} is not an ancestor of {link!r}')
            chain.append(joint)
            current = joint.parent
        pose = Transform(base, base, (0.0, 0.0, 0.0), IDENTITY)
        for joint in reversed(chain):
            pose = pose.then(joint.transform(positions.get(joint.name, 0.0)))
        return pose

    def mimic_positions(self, positions: Mapping[str, float]) -> Dict[str, float]:
        """Positions of mimic joints whose leader is in positions."""
        return {j.name: j.mimic.multiplier * positions[j.mimic.joint] + j.mimic.offset
                for j in self.joints.values()
                if j.mimic is not None and j.mimic.joint in positions}


# --- Parsing ---------------------------------------------------------------------------


def _numbers(text: Optional[str], count: int, default: Sequence[float],
             where: str) -> Tuple[float, ...]:
    if text is None:
        return tuple(float(v) for v in default)
    parts = text.split()
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != count or not all(math.isfinite(v) for v in values):
        what = 'a finite number' if count == 1 else f'{count} finite numbers'
        raise UrdfError(f'{where} must be {what}, got {text!r}')
    return values


def _number(element: ElementTree.Element, attribute: str, where: str,
            default: Optional[float] = None) -> Optional[float]:
    text = element.get(attribute)
    if text is None:
        return default
    return _numbers(text, 1, (), f'{where} {attribute}')[0]


def _origin(element: ElementTree.Element, where: str) -> Tuple[Vector, Vector]:
    origin = element.find('origin')
    if origin is None:
        return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    return (_numbers(origin.get('xyz'), 3, (0, 0, 0), f'{where} origin xyz'),
            _numbers(origin.get('rpy'), 3, (0, 0, 0), f'{where} origin rpy'))


def _inertial(link: ElementTree.Element, where: str) -> Optional[Inertial]:
    element = link.find('inertial')
    if element is None:
        return None
    xyz, rpy = _origin(element, f'{where} inertial')
    mass = element.find('mass')
    inertia = element.find('inertia')
    if mass is None or inertia is None:
        raise UrdfError(f'{where}: <inertial> needs <mass> and <inertia>')
    mass_kg = _number(mass, 'value', f'{where} mass')
    if mass_kg is None or mass_kg < 0.0:
        raise UrdfError(f'{where}: mass value must be a number >= 0, got {mass.get("value")!r}')
    values = {}
    for name in ('ixx', 'ixy', 'ixz', 'iyy', 'iyz', 'izz'):
        value = _number(inertia, name, f'{where} inertia')
        if value is None:
            raise UrdfError(f'{where}: inertia needs {name}')
        values[name] = value
    return Inertial(mass_kg, xyz, rpy, **values)


def _joint(element: ElementTree.Element) -> Joint:
    name = element.get('name')
    if not name:
        raise UrdfError('a <joint> has no name')
    where = f'joint {name!r}'
    joint_type = element.get('type')
    if joint_type not in MOVING_TYPES + STATIC_TYPES:
        raise UrdfError(f'{where}: unknown type {joint_type!r} (one of '
                        f'{", ".join(MOVING_TYPES + STATIC_TYPES)})')
    links = {}
    for role in ('parent', 'child'):
        tag = element.find(role)
        if tag is None or not tag.get('link'):
            raise UrdfError(f'{where}: needs <{role} link="..."/>')
        links[role] = tag.get('link')
    xyz, rpy = _origin(element, where)
    axis_element = element.find('axis')
    axis = _numbers(None if axis_element is None else axis_element.get('xyz'), 3,
                    (1, 0, 0), f'{where} axis xyz')
    norm = math.sqrt(sum(c * c for c in axis))
    if joint_type in MOVING_TYPES and not norm > 0.0:
        raise UrdfError(f'{where}: axis must not be zero')
    if norm > 0.0:
        axis = tuple(c / norm for c in axis)
    limits = {}
    limit = element.find('limit')
    if limit is None and joint_type in ('revolute', 'prismatic'):
        raise UrdfError(f'{where}: a {joint_type} joint needs a <limit>')
    if limit is not None:
        for attribute in ('lower', 'upper', 'effort', 'velocity'):
            limits[attribute] = _number(limit, attribute, f'{where} limit')
    mimic = None
    mimic_element = element.find('mimic')
    if mimic_element is not None:
        if not mimic_element.get('joint'):
            raise UrdfError(f'{where}: <mimic> needs a joint')
        mimic = Mimic(mimic_element.get('joint'),
                      _number(mimic_element, 'multiplier', f'{where} mimic', 1.0),
                      _number(mimic_element, 'offset', f'{where} mimic', 0.0))
    return Joint(name, joint_type, links['parent'], links['child'], xyz, rpy, axis,
                 mimic=mimic, **limits)


def parse_urdf(text: str) -> RobotModel:
    """Parse and validate URDF XML; raise UrdfError naming what is wrong."""
    if not isinstance(text, str) or not text.strip():
        raise UrdfError('the robot description is empty')
    try:
        root = ElementTree.fromstring(text)
    except ElementTree.ParseError as error:
        raise UrdfError(f'the robot description is not well-formed XML: {error}') from None
    if root.tag != 'robot':
        raise UrdfError(f'the root element must be <robot>, got <{root.tag}>')
    name = root.get('name')
    if not name:
        raise UrdfError('<robot> has no name')
    links: Dict[str, Link] = {}
    for element in root.findall('link'):
        link_name = element.get('name')
        if not link_name:
            raise UrdfError('a <link> has no name')
        if link_name in links:
            raise UrdfError(f'link {link_name!r} is defined twice')
        links[link_name] = Link(link_name, _inertial(element, f'link {link_name!r}'))
    if not links:
        raise UrdfError(f'robot {name!r} has no links')
    joints: Dict[str, Joint] = {}
    for element in root.findall('joint'):
        joint = _joint(element)
        if joint.name in joints:
            raise UrdfError(f'joint {joint.name!r} is defined twice')
        joints[joint.name] = joint
    return RobotModel(name, links, joints, _validate_tree(links, joints))


def _validate_tree(links: Mapping[str, Link], joints: Mapping[str, Joint]) -> str:
    """Check the joints form one tree over the links; return its root link."""
    parent_of: Dict[str, Joint] = {}
    for joint in joints.values():
        for role, link in (('parent', joint.parent), ('child', joint.child)):
            if link not in links:
                raise UrdfError(f'joint {joint.name!r}: {role} link {link!r} does not exist')
        if joint.parent == joint.child:
            raise UrdfError(f'joint {joint.name!r}: link {joint.child!r} is its own parent')
        if joint.child in parent_of:
            raise UrdfError(f'link {joint.child!r} has two parent joints: '
                            f'{parent_of[joint.child].name!r} and {joint.name!r}')
        parent_of[joint.child] = joint
        if joint.mimic is not None:
            leader = joints.get(joint.mimic.joint)
            if leader is None or not leader.moving:
                raise UrdfError(f'joint {joint.name!r}: mimics {joint.mimic.joint!r}, which '
                                'is not a moving joint of this robot')
    roots = [name for name in links if name not in parent_of]
    # Every link has at most one parent, so a link whose chain of parents never reaches
    # a root is on a cycle.
    for link in links:
        seen = []
        current = link
        while current in parent_of:
            if current in seen:
                cycle = {parent_of[c].name for c in seen[seen.index(current):]}
                raise UrdfError('joints ' + ', '.join(repr(j) for j in joints if j in cycle)
                                + ' form a cycle')
            seen.append(current)
            current = parent_of[current].parent
    if len(roots) != 1:
        raise UrdfError(f'a robot needs exactly one root link, found {len(roots)}: '
                        + ', '.join(repr(r) for r in roots))
    return roots[0]
