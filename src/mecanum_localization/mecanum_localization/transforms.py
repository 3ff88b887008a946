"""
Planar transforms and a tf2-like transform buffer (pure, no ROS).

The robot moves in a plane, so every transform is kept as its planar part: the pose
(x, y m, yaw rad) of a child frame in its parent (tf2's convention: it maps points from
the child frame to the parent). :class:`TransformBuffer` does tf2's job for such
transforms: static ones (``/tf_static``) hold forever, dynamic ones (``/tf``) are kept for
``cache_time_s`` and interpolated (x, y linearly, yaw the short way) at the time asked.
Each child has one parent, as in tf2. Lookups name the frames the way tf2's
``lookup_transform(target, source, time)`` does and fail with a
:class:`TransformError` saying why (frames not connected, a time outside what is
known).
"""

import bisect
from dataclasses import dataclass
import math
from typing import Dict, List, Optional, Tuple

from mecanum_control.angles import wrap_angle
import numpy as np


@dataclass(frozen=True)
class PlanarTransform:
    """A planar rigid transform: the pose (x, y m, yaw rad) of a child frame in its parent."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    def compose(self, other: 'PlanarTransform') -> 'PlanarTransform':
        """Return self * other (other expressed in self's child frame)."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return PlanarTransform(self.x + c * other.x - s * other.y,
                               self.y + s * other.x + c * other.y,
                               wrap_angle(self.yaw + other.yaw))

    def inverse(self) -> 'PlanarTransform':
        """Return the transform from child back to parent."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return PlanarTransform(-c * self.x - s * self.y, s * self.x - c * self.y,
                               wrap_angle(-self.yaw))

    def rotation(self) -> np.ndarray:
        """Return the 2x2 rotation matrix of the yaw."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return np.array([[c, -s], [s, c]])

    def apply(self, x: float, y: float) -> Tuple[float, float]:
        """Return the point (x, y) of the child frame in the parent frame."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return self.x + c * x - s * y, self.y + s * x + c * y

    def interpolate(self, other: 'PlanarTransform', fraction: float) -> 'PlanarTransform':
        """Return the transform a fraction (0..1) of the way from self to other."""
        return PlanarTransform(self.x + (other.x - self.x) * fraction,
                               self.y + (other.y - self.y) * fraction,
                               wrap_angle(self.yaw + wrap_angle(other.yaw - self.yaw)
                                          * fraction))


IDENTITY = PlanarTransform()


class TransformError(LookupError):
    """A transform cannot be looked up (not connected, or not known at that time)."""


class _Link:
    """The transforms of one child frame in its parent: static, or a time series."""

    def __init__(self, parent: str, static: bool):
        self.parent = parent
        self.static = static
        self.times: List[float] = []
        self.transforms: List[PlanarTransform] = []

    def add(self, time_s: float, transform: PlanarTransform, cache_time_s: float) -> None:
        if self.static:
            self.times, self.transforms = [time_s], [transform]
            return
        index = bisect.bisect_right(self.times, time_s)
        if index > 0 and self.times[index - 1] == time_s:
            self.transforms[index - 1] = transform  # the same stamp again: replace
        else:
            self.times.insert(index, time_s)
            self.transforms.insert(index, transform)
        oldest = self.times[-1] - cache_time_s
        drop = bisect.bisect_left(self.times, oldest)
        if drop:
            del self.times[:drop], self.transforms[:drop]

    def at(self, time_s: Optional[float], child: str) -> PlanarTransform:
        if self.static or time_s is None:
            return self.transforms[-1]
        times = self.times
        if time_s > times[-1] + 1e-9 or time_s < times[0] - 1e-9:
            when = 'future' if time_s > times[-1] else 'past'
            raise TransformError(
                f'Lookup would require extrapolation into the {when}: requested time '
                f'{time_s:.6f} but the {self.parent} -> {child} transform is known from '
                f'{times[0]:.6f} to {times[-1]:.6f}')
        index = bisect.bisect_left(times, time_s)
        if index < len(times) and abs(times[index] - time_s) <= 1e-9:
            return self.transforms[index]
        if index == 0:
            return self.transforms[0]
        if index == len(times):  # within the 1 ns tolerance after the newest
            return self.transforms[-1]
        before, after = times[index - 1], times[index]
        return self.transforms[index - 1].interpolate(
            self.transforms[index], (time_s - before) / (after - before))


class TransformBuffer:
    """
    Static and timed planar transforms between frames, looked up along the tree.

    ``lookup(target, source, time_s)`` returns the pose of ``source`` in ``target``
    (tf2's lookup_transform(target_frame, source_frame, time)); ``time_s`` None means
    the latest transform of every link (tf2's Time(0)).
    """

    MAX_DEPTH = 100

    def __init__(self, cache_time_s: float = 10.0):
        if not (math.isfinite(cache_time_s) and cache_time_s > 0.0):
            raise ValueError(f'cache_time_s must be finite and > 0, got {cache_time_s}')
        self.cache_time_s = float(cache_time_s)
        self._links: Dict[str, _Link] = {}

    def set_transform(self, parent: str, child: str, transform: PlanarTransform,
                      time_s: float = 0.0, static: bool = False) -> None:
        """Record the pose of child in parent (at time_s unless static)."""
        parent, child = parent.lstrip('/'), child.lstrip('/')
        if not parent or not child or parent == child:
            raise ValueError(f'a transform needs two different frames, got {parent!r} -> '
                             f'{child!r}')
        if not all(math.isfinite(v) for v in (transform.x, transform.y, transform.yaw,
                                              time_s)):
            raise ValueError(f'{parent} -> {child} transform is not finite: {transform} at '
                             f'{time_s}')
        link = self._links.get(child)
        if link is None or link.parent != parent or link.static != static:
            link = self._links[child] = _Link(parent, static)
        link.add(float(time_s), transform, self.cache_time_s)

    def frames(self) -> List[str]:
        """Return every frame known (as a parent or a child), sorted."""
        names = set(self._links)
        names.update(link.parent for link in self._links.values())
        return sorted(names)

    def _path_to_root(self, frame: str) -> List[str]:
        path = [frame]
        while path[-1] in self._links:
            path.append(self._links[path[-1]].parent)
            if len(path) > self.MAX_DEPTH:
                raise TransformError(f'the frames above {frame!r} form a loop')
        return path

    def _to_ancestor(self, path: List[str], ancestor: str,
                     time_s: Optional[float]) -> PlanarTransform:
        """Return the pose of path[0] in ancestor, composing the links on the way up."""
        transform = IDENTITY
        for frame in path:
            if frame == ancestor:
                return transform
            transform = self._links[frame].at(time_s, frame).compose(transform)
        return transform

    def lookup(self, target: str, source: str,
               time_s: Optional[float] = None) -> PlanarTransform:
        """Return the pose of frame source in frame target; raise TransformError if unknown."""
        target, source = target.lstrip('/'), source.lstrip('/')
        if target == source:
            return IDENTITY
        target_path, source_path = self._path_to_root(target), self._path_to_root(source)
        common = next((frame for frame in source_path if frame in set(target_path)), None)
        if common is None:
            known = ', '.join(self.frames()) or 'none'
            raise TransformError(
                f'Could not find a connection between {target!r} and {source!r} because they '
                f'are not part of the same tree (known frames: {known})')
        return self._to_ancestor(target_path, common, time_s).inverse().compose(
            self._to_ancestor(source_path, common, time_s))

    def oldest_link(self, target: str, source: str) -> Optional[Tuple[float, str]]:
        """
        Return how old the latest target <- source pose is: its stalest timed link.

        For each timed (not static) link on the chain joining target and source, take
        the stamp (s) of its newest transform; return the oldest of those with the link's
        name, (stamp, 'parent -> child'). None when every link is static (or the frames
        are the same); TransformError when they are not connected.
        """
        target, source = target.lstrip('/'), source.lstrip('/')
        if target == source:
            return None
        target_path, source_path = self._path_to_root(target), self._path_to_root(source)
        common = next((frame for frame in source_path if frame in set(target_path)), None)
        if common is None:
            raise TransformError(f'{target!r} and {source!r} are not part of the same tree')
        oldest: Optional[Tuple[float, str]] = None
        for path in (target_path, source_path):
            for child in path[:path.index(common)]:
                link = self._links[child]
                if not link.static and (oldest is None or link.times[-1] < oldest[0]):
                    oldest = (link.times[-1], f'{link.parent} -> {child}')
        return oldest

    def can_transform(self, target: str, source: str, time_s: Optional[float] = None) -> bool:
        """Tell whether lookup(target, source, time_s) would succeed."""
        try:
            self.lookup(target, source, time_s)
        except TransformError:
            return False
        return True
