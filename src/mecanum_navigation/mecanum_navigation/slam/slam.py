"""
Online 2-D SLAM from laser scans and odometry, slam_toolbox's job (pure, no ROS).

Frames follow REP-105: odometry gives odom_T_base (continuous, drifting); SLAM estimates
map_T_base and publishes the correction map_T_odom, with map_T_base = map_T_odom *
odom_T_base. Poses are (x_m, y_m, yaw_rad), REP-103 (x forward, y left, yaw CCW).

OnlineSlam.add_scan() takes one LaserScan with the odometry pose at its time:

* A scan becomes a keyframe when the robot has moved at least minimum_travel_distance
  or turned minimum_travel_heading (odometry) since the last keyframe; the first usable
  scan is always one. Other scans only update the current pose from odometry (cheap).
  A scan with fewer than minimum_scan_returns usable returns (NaN, +-inf and ranges out
  of [range_min, range_max] do not count) is skipped: no keyframe, pose from odometry.
* The first keyframe sits at the odometry pose (map == odom) or at initial_pose.
* Each next keyframe is predicted from the last one plus the odometry delta, then its
  scan is matched (scan_matching: branch and bound on a 5 cm field, Gauss-Newton on a
  finer one) against a local map of the last scan_buffer_size keyframes (those within
  scan_buffer_maximum_scan_distance). The match is accepted when its score reaches
  link_match_minimum_response_fine and it pins the yaw and at least one direction of
  x-y down (standard deviations within match_maximum_stddev_yaw / _xy; a few close
  points, e.g. a person in front of the lidar, fit many poses). Accepted: the node is
  placed at the match, with a match edge (information: the inverse match covariance)
  and an odometry edge from the previous keyframe. Not accepted: the keyframe is put
  off to the next scans until the robot has travelled twice the thresholds, then
  placed by odometry alone (odometry edge only) and left out of later matching maps.
  Odometry edges have a Cauchy kernel: a wheel slip is an outlier, not a pull.
* Matching maps are built from the keyframes' returns themselves (sub-cell accuracy),
  keeping those that an occupancy grid of the same keyframes still holds as occupied
  (moving people get cleared), that face the prior pose (it is on the side of their
  surface they were seen from; normals from neighbouring beams) and that a lidar at
  the prior would see first (ray casting): the far face of a thin wall or things
  hidden behind others cannot pull the match.
* Loop closure (do_loop_closing), after an accepted match: matched keyframes older than
  the scan buffer and at least loop_match_minimum_travel_distance of travel back,
  within loop_search_maximum_distance of the new keyframe (at least
  loop_match_minimum_chain_size of them, the closest 30 used) make a map the scan is
  matched against with the wider loop window. A score of at least
  loop_match_minimum_response_fine (and the same standard-deviation bounds) adds an
  edge from the nearest of them, with the match covariance plus
  loop_closure_minimum_stddev_xy / _yaw and a Cauchy kernel of
  loop_closure_kernel_scale; the graph is optimised (pose_graph) and the map is
  rebuilt from the optimised keyframe poses when next asked.

Matching scores are the fraction of scan points that land within 1.5 cells of an
occupied cell (0..1), so the thresholds here are on that scale, not Karto's response.
"""

from dataclasses import dataclass, fields
import math
from typing import List, Optional, Sequence, Tuple

from mecanum_control.angles import wrap_angle
from mecanum_map_server.map_io import OccupancyMap
from mecanum_navigation.slam.occupancy_grid_mapping import (
    GridMappingConfig, OccupancyGridMapper, scan_to_rays)
from mecanum_navigation.slam.pose_graph import compose, inverse, PoseGraph, relative
from mecanum_navigation.slam.scan_matching import (
    LikelihoodField, match_scan, MatchResult, ScanMatcherConfig, voxel_filter)
import numpy as np

Pose = Tuple[float, float, float]

#: Cells with at least this log-odds-derived probability are walls for matching.
_MATCH_OCCUPIED_PROBABILITY = 0.5
#: Floors of the odometry edge standard deviations (m, rad).
_ODOM_MIN_STDDEV_M = 0.01
_ODOM_MIN_STDDEV_RAD = 0.01
#: Cauchy kernel scale (sigmas) of the odometry edges.
_ODOMETRY_KERNEL_SCALE = 3.0
#: At most this many old keyframes (the closest) make the map of a loop-closure match.
_LOOP_MAX_KEYFRAMES = 30


def _is_number(value) -> bool:
    """Return True for an int or float (not bool)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
        value, (bool, np.bool_))


@dataclass(frozen=True)
class SlamConfig:
    """
    OnlineSlam parameters; names follow slam_toolbox's mapper_params_online_async.yaml.

    Lengths in metres, angles in radians. Search space dimensions are full widths (the
    window is +- half of it). Response thresholds are match scores in [0, 1]. The search
    field has sigma max(resolution, correlation_search_space_smear_deviation), the fine
    (refinement) field correlation_search_space_resolution cells and the smear sigma.
    """

    resolution: float = 0.05                    # m, map cells (and the search grid)
    max_laser_range: float = 12.0               # m; longer returns only clear the map
    minimum_travel_distance: float = 0.5        # m of odometry between keyframes, or ...
    minimum_travel_heading: float = 0.5         # ... rad of turn
    scan_buffer_size: int = 10                  # keyframes in the local matching map
    scan_buffer_maximum_scan_distance: float = 10.0     # m, farther ones are left out
    link_match_minimum_response_fine: float = 0.5       # score to accept a local match
    correlation_search_space_dimension: float = 0.8     # m, full width of the search
    correlation_search_space_resolution: float = 0.025  # m, cells of the fine field
    correlation_search_space_smear_deviation: float = 0.025  # m, its sigma
    coarse_search_angle_offset: float = 0.35    # rad, +- of every search
    do_loop_closing: bool = True
    loop_search_maximum_distance: float = 3.0   # m, old keyframes this near are candidates
    loop_match_minimum_chain_size: int = 5      # at least this many of them
    loop_match_minimum_response_fine: float = 0.6       # score to accept a loop closure
    loop_search_space_dimension: float = 2.0    # m, full width of the loop search
    loop_match_minimum_travel_distance: float = 5.0     # m travelled since a candidate
    loop_closure_minimum_stddev_xy: float = 0.03        # m, added to a closure's
    loop_closure_minimum_stddev_yaw: float = 0.02       # rad, match covariance
    loop_closure_kernel_scale: float = 3.0      # Cauchy kernel scale (sigmas)
    match_maximum_stddev_xy: float = 0.05       # m, best x-y direction of a usable match
    match_maximum_stddev_yaw: float = 0.02      # rad, yaw of a usable match
    odometry_translation_noise: float = 0.1     # m per m, odometry edge sigma
    odometry_rotation_noise: float = 0.1        # rad per rad (+ half of it per m)
    minimum_scan_returns: int = 20              # usable returns for a keyframe

    def __post_init__(self) -> None:
        """Validate every field; raise ValueError naming the first bad one."""
        positive = ('resolution', 'max_laser_range', 'scan_buffer_maximum_scan_distance',
                    'correlation_search_space_resolution',
                    'correlation_search_space_smear_deviation', 'loop_search_maximum_distance',
                    'loop_closure_minimum_stddev_xy', 'loop_closure_minimum_stddev_yaw',
                    'loop_closure_kernel_scale', 'match_maximum_stddev_xy',
                    'match_maximum_stddev_yaw')
        non_negative = ('minimum_travel_distance', 'minimum_travel_heading',
                        'correlation_search_space_dimension', 'coarse_search_angle_offset',
                        'loop_search_space_dimension', 'loop_match_minimum_travel_distance',
                        'odometry_translation_noise',
                        'odometry_rotation_noise')
        fractions = ('link_match_minimum_response_fine', 'loop_match_minimum_response_fine')
        counts = ('scan_buffer_size', 'loop_match_minimum_chain_size', 'minimum_scan_returns')
        for item in fields(self):
            name, value = item.name, getattr(self, item.name)
            if name == 'do_loop_closing':
                if not isinstance(value, bool):
                    raise ValueError(f'SlamConfig.do_loop_closing must be a bool, got {value!r}')
            elif name in counts:
                if not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
                    raise ValueError(f'SlamConfig.{name} must be an integer >= 1, got {value!r}')
            elif not (_is_number(value) and math.isfinite(value)):
                raise ValueError(f'SlamConfig.{name} must be a finite number, got {value!r}')
            elif name in positive and not value > 0.0:
                raise ValueError(f'SlamConfig.{name} must be > 0, got {value!r}')
            elif name in non_negative and not value >= 0.0:
                raise ValueError(f'SlamConfig.{name} must be >= 0, got {value!r}')
            elif name in fractions and not 0.0 <= value <= 1.0:
                raise ValueError(f'SlamConfig.{name} must be in [0, 1], got {value!r}')
        if self.coarse_search_angle_offset > math.pi:
            raise ValueError('SlamConfig.coarse_search_angle_offset must be at most pi, got '
                             f'{self.coarse_search_angle_offset!r}')


@dataclass
class _Keyframe:
    """A keyframe: its odometry pose, its scan (base frame) and its graph node."""

    odom_pose: Pose
    laser_origin: Tuple[float, float]
    end_points: np.ndarray     # (M, 2) float64, base_link frame
    is_return: np.ndarray      # (M,) bool
    match_points: np.ndarray   # (K, 2) returns within max_laser_range, voxel filtered
    matched: bool              # placed by a scan match (or the first keyframe)
    normals: np.ndarray        # (R, 2) unit surface normals of the returns, NaN: unknown
    travelled_m: float         # odometry path length from the first keyframe


class OnlineSlam:
    """Incremental SLAM: keyframes, scan matching, loop closure, pose graph (see module)."""

    def __init__(self, config: SlamConfig = SlamConfig(),
                 initial_pose: Optional[Sequence[float]] = None) -> None:
        if not isinstance(config, SlamConfig):
            raise ValueError(f'config must be a SlamConfig, got {config!r}')
        self._config = config
        self._initial_pose = (None if initial_pose is None
                              else _pose(initial_pose, 'initial_pose'))
        self._graph = PoseGraph()
        self._keyframes: List[_Keyframe] = []
        self._map_to_odom: Pose = (0.0, 0.0, 0.0)
        self._odom_pose: Optional[Pose] = None
        self._grid_config = GridMappingConfig(resolution_m=config.resolution)
        self._map = OccupancyGridMapper(self._grid_config)
        self._map_keyframes = 0      # keyframes inserted in self._map
        self._map_dirty = False      # poses moved: rebuild self._map when next asked
        self._loop_closures = 0
        self._last_score = math.nan
        self._sequential = ScanMatcherConfig(
            linear_window_m=config.correlation_search_space_dimension / 2.0,
            angular_window_rad=config.coarse_search_angle_offset)
        self._loop = ScanMatcherConfig(
            linear_window_m=config.loop_search_space_dimension / 2.0,
            angular_window_rad=config.coarse_search_angle_offset)

    @property
    def config(self) -> SlamConfig:
        """Return the configuration."""
        return self._config

    @property
    def keyframe_count(self) -> int:
        """Return the number of keyframes (pose-graph nodes)."""
        return len(self._keyframes)

    @property
    def loop_closure_count(self) -> int:
        """Return the number of loop-closure edges accepted so far."""
        return self._loop_closures

    @property
    def last_match_score(self) -> float:
        """Return the score of the last sequential match (NaN before any)."""
        return self._last_score

    def add_scan(self, odom_pose: Sequence[float], ranges, angle_min: float,
                 angle_increment: float, range_min: float, range_max: float,
                 laser_mount: Sequence[float] = (0.0, 0.0, 0.0)) -> bool:
        """
        Process one scan taken at odom_pose (odom_T_base); return True if it became a keyframe.

        ranges, angle_min, angle_increment, range_min, range_max are the LaserScan's;
        laser_mount is the laser's pose (x_m, y_m, yaw_rad) in base_link. Raises
        ValueError for a non-finite or wrong-length odom_pose / laser_mount, ranges that
        are not a 1-D array of numbers, or bad angle / range limits; bad beams are
        ignored (see the module docstring).
        """
        odom = _pose(odom_pose, 'odom_pose')
        mount = _pose(laser_mount, 'laser_mount')
        end_points, is_return = scan_to_rays(ranges, angle_min, angle_increment, range_min,
                                             range_max, self._config.max_laser_range)
        self._odom_pose = odom
        if self._keyframes:
            last = self._keyframes[-1].odom_pose
            delta = relative(last, odom)
            if (math.hypot(delta[0], delta[1]) < self._config.minimum_travel_distance
                    and abs(delta[2]) < self._config.minimum_travel_heading):
                return False
        if int(np.count_nonzero(is_return)) < self._config.minimum_scan_returns:
            return False
        return self._add_keyframe(odom, mount, end_points, is_return)

    def map_to_odom(self) -> Pose:
        """Return map_T_odom (x_m, y_m, yaw_rad): map_T_base = map_T_odom * odom_T_base."""
        return self._map_to_odom

    def pose(self) -> Pose:
        """
        Return the current base_link pose in the map: map_T_odom * the latest odom pose.

        Before any scan: initial_pose if given, else (0, 0, 0).
        """
        if self._odom_pose is None:
            return self._initial_pose if self._initial_pose is not None else (0.0, 0.0, 0.0)
        if not self._keyframes and self._initial_pose is not None:
            return self._initial_pose
        return compose(self._map_to_odom, self._odom_pose)

    def trajectory(self) -> np.ndarray:
        """Return the keyframe poses (n, 3) in the map frame, oldest first (a copy)."""
        return self._graph.poses()

    def occupancy_map(self, trinary: bool = True) -> OccupancyMap:
        """Return the map (map_io.OccupancyMap, save it with map_io.save_map)."""
        if self._map_dirty:
            self._map = OccupancyGridMapper(self._grid_config)
            self._map_keyframes = 0
            self._map_dirty = False
        poses = self._graph.poses()
        for index in range(self._map_keyframes, len(self._keyframes)):
            _insert(self._map, self._keyframes[index], poses[index])
        self._map_keyframes = len(self._keyframes)
        return self._map.to_occupancy_map(trinary)

    def _add_keyframe(self, odom: Pose, mount: Pose, end_points: np.ndarray,
                      is_return: np.ndarray) -> bool:
        """Turn a scan into a keyframe (match, graph, loop closure); False if put off."""
        config = self._config
        base_points = _transform(mount, end_points)
        returns = base_points[is_return]
        match_points = voxel_filter(returns, config.resolution)
        normals = surface_normals(returns)
        previous = self._keyframes[-1] if self._keyframes else None
        if previous is None:
            start = self._initial_pose if self._initial_pose is not None else odom
            self._graph.add_node(start)
            self._keyframes.append(_Keyframe(odom, (mount[0], mount[1]), base_points,
                                             is_return, match_points, True, normals, 0.0))
            self._update_map_to_odom()
            return True
        index = len(self._keyframes)
        previous_pose = self._graph.pose(index - 1)
        odom_delta = relative(previous.odom_pose, odom)
        predicted = compose(previous_pose, odom_delta)
        match = self._match_local(match_points, predicted, index)
        self._last_score = match.score if match is not None else 0.0
        accepted = (match is not None and match.score >= config.link_match_minimum_response_fine
                    and self._certain(match))
        if not accepted and (
                math.hypot(odom_delta[0], odom_delta[1]) < 2.0 * config.minimum_travel_distance
                and abs(odom_delta[2]) < 2.0 * config.minimum_travel_heading):
            return False    # try the next scans (a person in front of the lidar moves on)
        node = self._graph.add_node(match.pose if accepted else predicted)
        travelled = previous.travelled_m + math.hypot(odom_delta[0], odom_delta[1])
        self._keyframes.append(_Keyframe(odom, (mount[0], mount[1]), base_points, is_return,
                                         match_points, accepted, normals, travelled))
        # Wheels slip: an odometry step far off the scan matches is an outlier, not a pull.
        self._graph.add_edge(index - 1, node, odom_delta, self._odometry_information(odom_delta),
                             'cauchy', _ODOMETRY_KERNEL_SCALE)
        if accepted:
            self._graph.add_edge(index - 1, node, relative(previous_pose, match.pose),
                                 _relative_information(match.covariance, previous_pose[2]))
            if config.do_loop_closing:
                self._try_loop_closure(node)
        self._update_map_to_odom()
        return True

    def _match_local(self, points: np.ndarray, predicted: Pose,
                     index: int) -> Optional[MatchResult]:
        """Match against the map of the last scan_buffer_size keyframes near predicted."""
        config = self._config
        poses = self._graph.poses()
        chosen = []
        for k in range(index - 1, max(index - 1 - config.scan_buffer_size, -1), -1):
            if (math.hypot(poses[k, 0] - predicted[0], poses[k, 1] - predicted[1])
                    <= config.scan_buffer_maximum_scan_distance):
                chosen.append(k)
        matched = [k for k in chosen if self._keyframes[k].matched]
        chosen = matched or chosen
        if not chosen:
            return None
        field, fine = self._fields([self._keyframes[k] for k in chosen], poses[chosen],
                                   predicted)
        return match_scan(field, points, predicted, self._sequential, fine)

    def _try_loop_closure(self, node: int) -> None:
        """Match keyframe node against old keyframes near it; add an edge and optimise."""
        config = self._config
        poses = self._graph.poses()
        current = poses[node]
        # Far back: older than the scan buffer and a loop's worth of travel ago.
        now = self._keyframes[node].travelled_m
        old = np.array([k for k in range(max(node - config.scan_buffer_size, 0))
                        if self._keyframes[k].matched and now - self._keyframes[k].travelled_m
                        >= config.loop_match_minimum_travel_distance], dtype=np.int64)
        if len(old) == 0:
            return
        distances = np.hypot(poses[old, 0] - current[0], poses[old, 1] - current[1])
        within = distances <= config.loop_search_maximum_distance
        if np.count_nonzero(within) < config.loop_match_minimum_chain_size:
            return
        # The closest ones (bounded, for a place visited many times).
        near = old[within][np.argsort(distances[within], kind='stable')[:_LOOP_MAX_KEYFRAMES]]
        field, fine = self._fields([self._keyframes[k] for k in near], poses[near], current)
        keyframe = self._keyframes[node]
        match = match_scan(field, keyframe.match_points, tuple(current), self._loop, fine)
        if match.score < config.loop_match_minimum_response_fine or not self._certain(match):
            return
        matched = np.asarray(match.pose)
        nearest = int(near[np.argmin(np.hypot(poses[near, 0] - matched[0],
                                              poses[near, 1] - matched[1]))])
        anchor = tuple(poses[nearest])
        covariance = match.covariance.copy()
        floor = np.array([config.loop_closure_minimum_stddev_xy,
                          config.loop_closure_minimum_stddev_xy,
                          config.loop_closure_minimum_stddev_yaw]) ** 2
        covariance += np.diag(floor)
        self._graph.add_edge(nearest, node, relative(anchor, match.pose),
                             _relative_information(covariance, anchor[2]), 'cauchy',
                             config.loop_closure_kernel_scale)
        self._loop_closures += 1
        self._graph.optimize()
        self._map_dirty = True

    def _fields(self, keyframes: List[_Keyframe], poses: np.ndarray,
                centre) -> Tuple[LikelihoodField, LikelihoodField]:
        """
        Return the (search, fine) likelihood fields of keyframes' returns at poses.

        The returns kept are those in cells the keyframes' occupancy grid holds occupied,
        facing centre (the pose to be matched) and first seen from it by ray casting,
        within max_laser_range plus the loop window of it (see the module docstring).
        """
        mapper = OccupancyGridMapper(self._grid_config)
        rays = []
        low, high = np.full(2, np.inf), np.full(2, -np.inf)
        for keyframe, pose in zip(keyframes, poses):
            origin = compose(pose, (keyframe.laser_origin[0], keyframe.laser_origin[1], 0.0))
            points = _transform(pose, keyframe.end_points)
            rays.append((origin[:2], points, keyframe.is_return))
            low = np.minimum(low, points.min(axis=0, initial=np.inf))
            high = np.maximum(high, points.max(axis=0, initial=-np.inf))
            low = np.minimum(low, origin[:2])
            high = np.maximum(high, origin[:2])
        mapper.reserve(low[0], low[1], high[0], high[1])
        for origin, points, is_return in rays:
            mapper.insert_rays(origin, points, is_return)
        # The returns themselves (not their cells) make the field, for sub-cell accuracy;
        # those in cells that later scans saw through (moving things) are dropped.
        occupied = mapper.occupied_mask(_MATCH_OCCUPIED_PROBABILITY)
        returns = np.vstack([points[is_return] for _, points, is_return in rays])
        # Which side of its surface each return was seen from: n . (laser - return), with
        # n the surface normal (NaN where unknown: then the viewing direction stands in).
        normals = np.vstack([_rotate(pose[2], keyframe.normals)
                             for keyframe, pose in zip(keyframes, poses)])
        viewed = np.vstack([origin - points[is_return] for origin, points, is_return in rays])
        res = self._config.resolution
        x0, y0 = mapper.origin
        rows = np.floor((returns[:, 1] - y0) / res).astype(np.int64)
        cols = np.floor((returns[:, 0] - x0) / res).astype(np.int64)
        config = self._config
        reach = config.max_laser_range + config.loop_search_space_dimension / 2.0 + 1.0
        # A return seen from the other side of its surface than centre (the far face of a
        # thin wall) cannot be seen from here: keep the ones on centre's side.
        here = np.asarray(centre[:2]) - returns
        known = np.isfinite(normals[:, 0])
        same_side = np.einsum('ij,ij->i', viewed, here) > 0.0
        same_side[known] = (np.einsum('ij,ij->i', normals[known], viewed[known])
                            * np.einsum('ij,ij->i', normals[known], here[known])) > 0.0
        visible = mapper.visible_mask(float(centre[0]), float(centre[1]), reach,
                                      _MATCH_OCCUPIED_PROBABILITY)
        kept = returns[occupied[rows, cols] & same_side & visible[rows, cols]
                       & (np.abs(returns[:, 0] - centre[0]) <= reach)
                       & (np.abs(returns[:, 1] - centre[1]) <= reach)]
        if len(kept) == 0:
            kept = returns
        coarse = LikelihoodField.from_points(
            kept, res, max(res, config.correlation_search_space_smear_deviation))
        fine = LikelihoodField.from_points(kept, config.correlation_search_space_resolution,
                                           config.correlation_search_space_smear_deviation)
        return coarse, fine

    def _certain(self, match: MatchResult) -> bool:
        """
        Return True if the match pins the yaw and at least one direction of x-y down.

        Its yaw standard deviation and the smaller one of x-y (along the best determined
        direction) must be within match_maximum_stddev_yaw / _xy. A corridor passes (its
        length is left to the covariance), a few close points (a person in front of the
        lidar) do not.
        """
        covariance = match.covariance
        smallest_xy = float(np.linalg.eigvalsh(covariance[:2, :2])[0])
        return bool(math.sqrt(max(smallest_xy, 0.0)) <= self._config.match_maximum_stddev_xy
                    and math.sqrt(covariance[2, 2]) <= self._config.match_maximum_stddev_yaw)

    def _odometry_information(self, delta: Pose) -> np.ndarray:
        """Return the information of an odometry edge spanning delta."""
        config = self._config
        distance = math.hypot(delta[0], delta[1])
        sigma_xy = config.odometry_translation_noise * distance + _ODOM_MIN_STDDEV_M
        sigma_yaw = (config.odometry_rotation_noise * abs(delta[2])
                     + 0.5 * config.odometry_translation_noise * distance
                     + _ODOM_MIN_STDDEV_RAD)
        return np.diag([sigma_xy ** -2, sigma_xy ** -2, sigma_yaw ** -2])

    def _update_map_to_odom(self) -> None:
        """Set map_T_odom from the newest keyframe: its map pose times its odom pose^-1."""
        last = len(self._keyframes) - 1
        self._map_to_odom = compose(self._graph.pose(last),
                                    inverse(self._keyframes[last].odom_pose))


def occupied_overlap(estimate: OccupancyMap, truth: OccupancyMap, tolerance_cells: int = 1,
                     occupied_threshold: int = 65) -> Tuple[float, float]:
    """
    Return (precision, recall) of estimate's walls against truth's, each in [0, 1].

    precision: the fraction of estimate's occupied cells (>= occupied_threshold) whose
    centre lies within tolerance_cells (a square neighbourhood, in truth's cells) of an
    occupied truth cell. recall: the fraction of truth's visible wall cells -- occupied
    cells with a 4-neighbour that is free in truth and explored (free) in estimate --
    within tolerance_cells (in estimate's cells) of an occupied estimate cell. Either is
    NaN when there is nothing to count.
    """
    if not (isinstance(tolerance_cells, int) and not isinstance(tolerance_cells, bool)
            and tolerance_cells >= 0):
        raise ValueError(f'tolerance_cells must be an integer >= 0, got {tolerance_cells!r}')
    estimate_occupied = estimate.data >= occupied_threshold
    truth_occupied = truth.data >= occupied_threshold
    rows, cols = np.indices(truth.data.shape)
    x, y = _cell_centres(truth, rows.ravel(), cols.ravel())
    explored = (_sample(estimate, x, y) == 0).reshape(truth.data.shape)
    seen_free = (truth.data == 0) & explored
    beside = np.zeros_like(seen_free)
    beside[1:, :] |= seen_free[:-1, :]
    beside[:-1, :] |= seen_free[1:, :]
    beside[:, 1:] |= seen_free[:, :-1]
    beside[:, :-1] |= seen_free[:, 1:]
    precision = _fraction_near(estimate, estimate_occupied, truth,
                               _dilate(truth_occupied, tolerance_cells))
    recall = _fraction_near(truth, truth_occupied & beside, estimate,
                            _dilate(estimate_occupied, tolerance_cells))
    return precision, recall


def _sample(grid: OccupancyMap, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Return grid's values at map-frame points (x, y); -1 outside the grid."""
    ox, oy, yaw = grid.origin
    cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
    local_x = cos_yaw * (x - ox) + sin_yaw * (y - oy)
    local_y = -sin_yaw * (x - ox) + cos_yaw * (y - oy)
    cols = np.floor(local_x / grid.resolution_m).astype(np.int64)
    rows = np.floor(local_y / grid.resolution_m).astype(np.int64)
    inside = (rows >= 0) & (rows < grid.height) & (cols >= 0) & (cols < grid.width)
    values = np.full(len(x), -1, dtype=np.int16)
    values[inside] = grid.data[rows[inside], cols[inside]]
    return values


def _fraction_near(source: OccupancyMap, mask: np.ndarray, target: OccupancyMap,
                   target_mask: np.ndarray) -> float:
    """Return the fraction of source's mask cells whose centres fall on target_mask."""
    rows, cols = np.nonzero(mask)
    if len(rows) == 0:
        return math.nan
    x, y = _cell_centres(source, rows, cols)
    as_grid = OccupancyMap(target.resolution_m, target.origin, target_mask.astype(np.int8))
    return float(np.count_nonzero(_sample(as_grid, x, y) == 1)) / len(rows)


def _cell_centres(grid: OccupancyMap, rows: np.ndarray, cols: np.ndarray):
    """Return the map-frame (x, y) arrays of the centres of cells (rows, cols)."""
    local_x = (cols + 0.5) * grid.resolution_m
    local_y = (rows + 0.5) * grid.resolution_m
    ox, oy, yaw = grid.origin
    cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
    return ox + cos_yaw * local_x - sin_yaw * local_y, oy + sin_yaw * local_x + cos_yaw * local_y


def _dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    """Return mask grown by radius cells in every direction (a square neighbourhood)."""
    out = mask.copy()
    rows, cols = mask.shape
    for dr in range(-radius, radius + 1):
        for dc in range(-radius, radius + 1):
            r0, r1 = max(dr, 0), rows + min(dr, 0)
            c0, c1 = max(dc, 0), cols + min(dc, 0)
            if r0 < r1 and c0 < c1:
                out[r0:r1, c0:c1] |= mask[r0 - dr:r1 - dr, c0 - dc:c1 - dc]
    return out


def surface_normals(points: np.ndarray, max_gap_m: float = 0.15,
                    gap_per_metre: float = 0.05) -> np.ndarray:
    """
    Return unit surface normals (N, 2) of scan points given in beam order (sign arbitrary).

    The tangent at a point runs between its neighbours in the list (or to the one
    neighbour close enough); a neighbour counts when it is within max_gap_m +
    gap_per_metre * range (range from the origin of the points' frame), so depth jumps
    do not make tangents. NaN where neither neighbour is close.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    normals = np.full(pts.shape, np.nan)
    if len(pts) < 2:
        return normals
    gaps = np.hypot(*(pts[1:] - pts[:-1]).T)
    limit = max_gap_m + gap_per_metre * np.hypot(pts[:, 0], pts[:, 1])
    before_ok = np.zeros(len(pts), dtype=bool)
    after_ok = np.zeros(len(pts), dtype=bool)
    before_ok[1:] = gaps <= limit[1:]
    after_ok[:-1] = gaps <= limit[:-1]
    previous = np.vstack([pts[:1], pts[:-1]])
    following = np.vstack([pts[1:], pts[-1:]])
    start = np.where(before_ok[:, None], previous, pts)
    end = np.where(after_ok[:, None], following, pts)
    tangent = end - start
    length = np.hypot(tangent[:, 0], tangent[:, 1])
    ok = (before_ok | after_ok) & (length > 0.0)
    normals[ok, 0] = -tangent[ok, 1] / length[ok]
    normals[ok, 1] = tangent[ok, 0] / length[ok]
    return normals


def _rotate(yaw: float, vectors: np.ndarray) -> np.ndarray:
    """Return vectors (N, 2) rotated by yaw (NaN stays NaN)."""
    cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
    return np.column_stack([cos_yaw * vectors[:, 0] - sin_yaw * vectors[:, 1],
                            sin_yaw * vectors[:, 0] + cos_yaw * vectors[:, 1]])


def _insert(mapper: OccupancyGridMapper, keyframe: _Keyframe, pose) -> None:
    """Insert a keyframe's rays into mapper with base_link at pose."""
    origin = compose(pose, (keyframe.laser_origin[0], keyframe.laser_origin[1], 0.0))
    mapper.insert_rays(origin[:2], _transform(pose, keyframe.end_points), keyframe.is_return)


def _transform(pose, points: np.ndarray) -> np.ndarray:
    """Return points (N, 2) given in pose's frame expressed in its parent frame."""
    cos_yaw, sin_yaw = math.cos(pose[2]), math.sin(pose[2])
    return np.column_stack([pose[0] + cos_yaw * points[:, 0] - sin_yaw * points[:, 1],
                            pose[1] + sin_yaw * points[:, 0] + cos_yaw * points[:, 1]])


def _relative_information(covariance: np.ndarray, anchor_yaw: float) -> np.ndarray:
    """
    Return the information of an edge from a node with yaw anchor_yaw.

    covariance is the map-frame covariance of the target pose; the edge measurement is
    expressed in the anchor's frame, so the x-y block is rotated by -anchor_yaw.
    """
    cos_yaw, sin_yaw = math.cos(anchor_yaw), math.sin(anchor_yaw)
    rotation = np.array([[cos_yaw, sin_yaw, 0.0], [-sin_yaw, cos_yaw, 0.0], [0.0, 0.0, 1.0]])
    local = rotation @ covariance @ rotation.T
    information = np.linalg.inv(0.5 * (local + local.T))
    return 0.5 * (information + information.T)


def _pose(pose, name: str) -> Pose:
    """Return pose as 3 finite floats (yaw wrapped) or raise ValueError naming it."""
    try:
        values = tuple(float(v) for v in pose)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be 3 finite numbers (x, y, yaw), got {pose!r}') from None
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise ValueError(f'{name} must be 3 finite numbers (x, y, yaw), got {pose!r}')
    return values[0], values[1], wrap_angle(values[2])
