"""
The authorised zone (geofence): where the robot may be, declared once (pure, no ROS).

A zone is one inclusion polygon and any number of exclusion polygons, in the map frame
(REP-105; metres, x east, y north). Polygons may be concave; they must be simple (no
self-crossing, no edge folding back onto the previous one: the rules of
:func:`mecanum_safety.polygon.polygon_problem`), and exclusions lie inside the inclusion
polygon. The robot's footprint (a circle of footprint_radius_m around base_link) is
allowed where it is inside the inclusion polygon and outside every exclusion.

The same definition serves everyone: the navigator writes everything outside it as
keepout in its global costmap, the zone guard keeps the commanded motion inside it,
robot_controller refuses text commands that end outside it, and the scenario judge
counts exits from it. Formats (YAML; the same in scenario files, world files and a
standalone zone file that a real deployment loads)::

    authorised_zone:                     # full form
      frame_id: map                      # optional; only 'map' is supported
      include: [[0.1, 0.1], [9.9, 0.1], [9.9, 7.9], [0.1, 7.9]]
      exclude:                           # optional
      - [[3.0, 4.1], [5.0, 4.1], [5.0, 7.8], [3.0, 7.8]]

    authorised_zone: [[0.1, 0.1], [9.9, 0.1], [9.9, 7.9], [0.1, 7.9]]   # inclusion only

``authorised_zone: []`` or ``null`` declares no zone. A standalone zone file holds one
top-level ``authorised_zone:`` key. :func:`parse_zone` and :func:`load_zone_file` raise
:class:`ZoneError` naming the file and the key for anything malformed.
"""

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any, List, Optional, Sequence, Tuple, Union

from mecanum_safety.polygon import (
    point_in_polygon, points_in_polygon, polygon_edges, polygon_problem, segments_touch,
    signed_area)
import numpy as np
import yaml

Point = Tuple[float, float]
PathLike = Union[str, Path]

#: Lengths and areas below this (m, m^2) count as zero.
_EPS = 1e-9


class ZoneError(ValueError):
    """A malformed zone: the message names where (file, key) and what is wrong."""


@dataclass(frozen=True, eq=False)
class Zone:
    """
    An authorised zone in the map frame: inside ``include`` and outside every ``exclude``.

    include: (N, 2) float array of polygon vertices (x, y) in m, counter-clockwise.
    exclude: tuple of (M, 2) arrays, each an exclusion polygon, counter-clockwise.
    Build one with :func:`make_zone` (which checks it) or :func:`parse_zone`.
    """

    include: np.ndarray
    exclude: Tuple[np.ndarray, ...] = ()
    frame_id: str = 'map'

    def __eq__(self, other: object) -> bool:
        """Zones are equal when their frame and every polygon's vertices are."""
        if not isinstance(other, Zone):
            return NotImplemented
        return (self.frame_id == other.frame_id and len(self.exclude) == len(other.exclude)
                and all(np.array_equal(a, b) for a, b in zip(self.polygons(), other.polygons())))

    def __hash__(self) -> int:
        """Hash the vertices (zones are immutable)."""
        return hash((self.frame_id, *(polygon.tobytes() for polygon in self.polygons())))

    def polygons(self) -> List[np.ndarray]:
        """Return every border polygon: the inclusion first, then the exclusions."""
        return [self.include, *self.exclude]

    def edges(self) -> np.ndarray:
        """Return every border edge as a (K, 4) array of x1, y1, x2, y2 rows (m)."""
        return np.vstack([polygon_edges(polygon) for polygon in self.polygons()])

    def contains(self, xs, ys) -> np.ndarray:
        """Return a bool array: which points (map frame, m) are in the allowed region."""
        xs = np.asarray(xs, dtype=np.float64)
        ys = np.asarray(ys, dtype=np.float64)
        inside = points_in_polygon(xs, ys, self.include)
        for polygon in self.exclude:
            inside &= ~points_in_polygon(xs, ys, polygon)
        return inside

    def contains_point(self, x: float, y: float) -> bool:
        """Return whether one point (m) is in the allowed region (no numpy: per-step use)."""
        if not point_in_polygon(x, y, self.include):
            return False
        return not any(point_in_polygon(x, y, polygon) for polygon in self.exclude)

    def clearance(self, xs, ys) -> np.ndarray:
        """
        Return the signed distance (m) of each point to the zone's border.

        Positive inside the allowed region (the distance to the nearest border edge),
        negative outside it; a circle of radius r centred on a point lies in the allowed
        region exactly when its clearance is >= r.
        """
        xs = np.asarray(xs, dtype=np.float64)
        ys = np.asarray(ys, dtype=np.float64)
        distance = points_segments_distance(xs, ys, self.edges())
        return np.where(self.contains(xs, ys), distance, -distance)

    def footprint_inside(self, x: float, y: float, radius_m: float) -> bool:
        """Whether a circle of radius_m (m) centred on (x, y) lies in the allowed region."""
        return bool(self.clearance(np.array([x]), np.array([y]))[0] >= radius_m)

    def to_document(self) -> dict:
        """Return the zone in its full YAML form (the value of ``authorised_zone``)."""
        document = {'frame_id': self.frame_id, 'include': _as_lists(self.include)}
        if self.exclude:
            document['exclude'] = [_as_lists(polygon) for polygon in self.exclude]
        return document


def make_zone(include: Sequence[Point], exclude: Sequence[Sequence[Point]] = (),
              frame_id: str = 'map') -> Zone:
    """Check the polygons and return the Zone (ZoneError naming the polygon if wrong)."""
    return _build(include, exclude, frame_id, 'authorised_zone', 'authorised_zone.include')


def parse_zone(raw: Any, where: str = 'authorised_zone') -> Optional[Zone]:
    """
    Return the Zone that raw (a parsed ``authorised_zone`` value) declares, or None.

    raw: None or [] (no zone), a list of [x, y] (inclusion only) or a mapping with
    ``include`` and optional ``exclude`` and ``frame_id``. where: how errors name it
    (e.g. 'tour.yaml: authorised_zone').
    """
    if raw is None or (isinstance(raw, (list, tuple)) and len(raw) == 0):
        return None
    if isinstance(raw, (list, tuple)):
        return _build(raw, (), 'map', where, where)
    if not isinstance(raw, dict):
        raise ZoneError(f'{where}: must be a list of [x, y] points or a mapping with '
                        f'include (and exclude), not {raw!r}')
    unknown = sorted(set(raw) - {'include', 'exclude', 'frame_id'})
    if unknown:
        raise ZoneError(f'{where}: unknown key(s) {", ".join(map(str, unknown))} '
                        '(expected include, exclude, frame_id)')
    if 'include' not in raw:
        raise ZoneError(f'{where}: include (the inclusion polygon) is required')
    exclude = raw.get('exclude') or []
    if not isinstance(exclude, (list, tuple)):
        raise ZoneError(f'{where}.exclude: must be a list of polygons, not {exclude!r}')
    return _build(raw['include'], exclude, raw.get('frame_id', 'map'), where,
                  f'{where}.include')


def load_zone_file(path: PathLike) -> Optional[Zone]:
    """Load a standalone zone file (top-level ``authorised_zone:``); None if it declares none."""
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text())
    except OSError as error:
        raise ZoneError(f'{path}: cannot read the zone file: {error.strerror or error}') \
            from None
    except yaml.YAMLError as error:
        raise ZoneError(f'{path}: not valid YAML: {error}') from None
    if not isinstance(document, dict) or 'authorised_zone' not in document:
        raise ZoneError(f'{path}: expected a top-level "authorised_zone:" key')
    extra = sorted(set(document) - {'authorised_zone'})
    if extra:
        raise ZoneError(f'{path}: unknown top-level key(s) {", ".join(map(str, extra))}')
    return parse_zone(document['authorised_zone'], f'{path}: authorised_zone')


def zone_file_text(zone: Optional[Zone]) -> str:
    """Return the text of a standalone zone file declaring zone (None: no zone)."""
    value = zone.to_document() if zone is not None else []
    return yaml.safe_dump({'authorised_zone': value}, sort_keys=False,
                          default_flow_style=None)


def points_segments_distance(xs: np.ndarray, ys: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Return, for each point, its distance (m) to the nearest x1, y1, x2, y2 segment."""
    px = np.asarray(xs, dtype=np.float64)[..., None]
    py = np.asarray(ys, dtype=np.float64)[..., None]
    x1, y1, x2, y2 = (segments[:, i] for i in range(4))
    dx, dy = x2 - x1, y2 - y1
    length2 = np.maximum(dx * dx + dy * dy, _EPS)
    t = np.clip(((px - x1) * dx + (py - y1) * dy) / length2, 0.0, 1.0)
    return np.min(np.hypot(x1 + t * dx - px, y1 + t * dy - py), axis=-1)


def _build(include: Any, exclude: Sequence[Any], frame_id: Any, where: str,
           include_where: str) -> Zone:
    if frame_id != 'map':
        raise ZoneError(f'{where}.frame_id: only the map frame is supported, not {frame_id!r}')
    inclusion = _polygon(include, include_where)
    exclusions = []
    for index, polygon in enumerate(exclude):
        name = f'{where}.exclude[{index}]'
        vertices = _polygon(polygon, name)
        outside = ~points_in_polygon(vertices[:, 0], vertices[:, 1], inclusion)
        if np.any(outside):
            raise ZoneError(f'{name}: vertex {int(np.argmax(outside))} is outside the '
                            'inclusion polygon (exclusions must lie inside it)')
        # A concave inclusion can hold every vertex while an edge crosses its notch.
        for i in range(len(vertices)):
            for j in range(len(inclusion)):
                if segments_touch(vertices[i], vertices[(i + 1) % len(vertices)],
                                  inclusion[j], inclusion[(j + 1) % len(inclusion)]):
                    raise ZoneError(f'{name}: edge {i} crosses edge {j} of the inclusion '
                                    'polygon (exclusions must lie inside it)')
        exclusions.append(vertices)
    return Zone(inclusion, tuple(exclusions), 'map')


def _polygon(raw: Any, where: str) -> np.ndarray:
    if not isinstance(raw, (list, tuple)):
        raise ZoneError(f'{where}: must be a list of [x, y] points, not {raw!r}')
    points = []
    for index, point in enumerate(raw):
        if (not isinstance(point, (list, tuple)) or len(point) != 2
                or not all(_is_number(c) for c in point)):
            raise ZoneError(f'{where}[{index}]: must be an [x, y] pair of numbers, '
                            f'not {point!r}')
        x, y = float(point[0]), float(point[1])
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ZoneError(f'{where}[{index}]: coordinates must be finite, not {point!r}')
        points.append((x, y))
    problem = polygon_problem(points)
    if problem:
        raise ZoneError(f'{where}: the polygon {problem}')
    if signed_area(points) < 0.0:
        points.reverse()
    return np.array(points, dtype=np.float64)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _as_lists(polygon: np.ndarray) -> List[List[float]]:
    return [[float(x), float(y)] for x, y in polygon]
