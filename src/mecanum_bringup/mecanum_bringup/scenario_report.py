"""
Reports of scenario runs: a text table, JUnit XML, a JSON summary and a plot (pure, no ROS).

Inputs come from :mod:`mecanum_bringup.scenario_model` (Scenario, RunRecord, Verdict) and the
runner (wall-clock time). Tracks are (N, 4) arrays of t, x, y, yaw in the map frame
(metres, seconds, radians; REP-103). The plot is drawn with matplotlib's object API on
an Agg canvas (no pyplot, no display, no global backend change).
"""

from dataclasses import dataclass
import math
import re
from typing import Any, Dict, Optional, Sequence, Tuple
import xml.etree.ElementTree as ElementTree

from mecanum_bringup.scenario_judge import (
    distance_travelled_m, localization_errors, track_array, zone_result)
from mecanum_bringup.scenario_model import GoalStep, RunRecord, Scenario, Verdict, WaypointsStep
from mecanum_safety.zone import Zone
import numpy as np

#: Longest text in the table's last column.
MAX_DETAIL_CHARS = 70
#: Characters XML 1.0 cannot hold, even escaped.
_XML_INVALID = re.compile('[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]')


@dataclass(frozen=True)
class ScenarioResult:
    """
    One scenario's outcome for the reports.

    verdict is None when the scenario could not be judged (invalid file, runner failure);
    error then says why. sim_time_s and wall_time_s are the run's simulated and
    wall-clock durations in seconds (None when unknown).
    """

    name: str
    expected: str
    verdict: Optional[Verdict] = None
    sim_time_s: Optional[float] = None
    wall_time_s: Optional[float] = None
    error: str = ''

    @classmethod
    def from_run(cls, verdict: Verdict, record: RunRecord,
                 wall_time_s: Optional[float] = None) -> 'ScenarioResult':
        """Return the result of a judged run (sim time = record.duration_s)."""
        return cls(verdict.scenario, verdict.expected, verdict, float(record.duration_s),
                   wall_time_s)

    @property
    def status(self) -> str:
        """Return 'OK' (verdict as expected), 'UNEXPECTED' or 'ERROR' (no verdict)."""
        if self.verdict is None:
            return 'ERROR'
        return 'OK' if self.verdict.as_expected else 'UNEXPECTED'

    @property
    def first_failure(self) -> str:
        """Return the first failed criterion's detail, the error, or ''."""
        if self.verdict is None:
            return self.error
        failure = self.verdict.first_failure
        return failure.detail if failure else ''


def _seconds(value: Optional[float]) -> str:
    if value is None or not math.isfinite(value):
        return '-'
    return f'{value:.1f} s'


def one_line(text: str, limit: int) -> str:
    """Return text on one line, control characters replaced, cut to limit characters."""
    text = ''.join(c if c.isprintable() else ' ' for c in ' '.join(str(text).split()))
    return text if len(text) <= limit else text[:limit - 3] + '...'


def results_table(results: Sequence[ScenarioResult]) -> str:
    """Return a fixed-width text table, one row per scenario, and a summary line."""
    header = ('scenario', 'expected', 'verdict', 'result', 'sim time', 'wall time',
              'first failed criterion')
    rows = [header]
    for result in results:
        rows.append((result.name, result.expected,
                     result.verdict.verdict if result.verdict else '-', result.status,
                     _seconds(result.sim_time_s), _seconds(result.wall_time_s),
                     one_line(result.first_failure, MAX_DETAIL_CHARS) or '-'))
    widths = [max(len(row[column]) for row in rows) for column in range(len(header))]
    right = {4, 5}  # times are right-aligned

    def line(row):
        cells = [cell.rjust(width) if column in right else cell.ljust(width)
                 for column, (cell, width) in enumerate(zip(row, widths))]
        return '  '.join(cells).rstrip()

    lines = [line(header), '  '.join('-' * width for width in widths)]
    lines += [line(row) for row in rows[1:]]
    counts = {status: sum(r.status == status for r in results)
              for status in ('OK', 'UNEXPECTED', 'ERROR')}
    lines.append(f'{len(results)} scenario{"" if len(results) == 1 else "s"}: '
                 f'{counts["OK"]} as expected, {counts["UNEXPECTED"]} unexpected, '
                 f'{counts["ERROR"]} errors')
    return '\n'.join(lines) + '\n'


def xml_text(text: Any) -> str:
    """Return text without the characters XML 1.0 cannot hold (replaced by U+FFFD)."""
    return _XML_INVALID.sub('\ufffd', str(text))


def _criteria_lines(verdict: Verdict) -> str:
    return '\n'.join(f'[{"PASS" if c.passed else "FAIL"}] {c.detail}' for c in verdict.criteria)


def junit_xml(results: Sequence[ScenarioResult]) -> str:
    """
    Return a JUnit XML report: one testsuite 'scenarios', one testcase per scenario.

    A verdict other than the expected one is a <failure> listing every criterion; a
    scenario without a verdict is an <error>. Every testcase's <system-out> holds its
    criteria. time is the wall-clock time in seconds.
    """
    failures = sum(r.status == 'UNEXPECTED' for r in results)
    errors = sum(r.status == 'ERROR' for r in results)
    total_time = sum(r.wall_time_s for r in results
                     if r.wall_time_s is not None and math.isfinite(r.wall_time_s))
    suite = ElementTree.Element('testsuite', {
        'name': 'scenarios', 'tests': str(len(results)), 'failures': str(failures),
        'errors': str(errors), 'skipped': '0', 'time': f'{total_time:.3f}'})
    for result in results:
        wall = result.wall_time_s
        case = ElementTree.SubElement(suite, 'testcase', {
            'name': xml_text(result.name), 'classname': 'scenarios',
            'time': f'{wall:.3f}' if wall is not None and math.isfinite(wall) else '0.000'})
        if result.verdict is None:
            error = ElementTree.SubElement(case, 'error', {
                'message': xml_text(one_line(result.error, 500)), 'type': 'ScenarioError'})
            error.text = xml_text(result.error)
            continue
        verdict = result.verdict
        details = _criteria_lines(verdict)
        if not verdict.as_expected:
            first = result.first_failure or 'every criterion passed'
            failure = ElementTree.SubElement(case, 'failure', {
                'message': xml_text(f'expected {verdict.expected}, got {verdict.verdict}: '
                                    f'{one_line(first, 500)}'),
                'type': 'UnexpectedVerdict'})
            failure.text = xml_text(details)
        system_out = ElementTree.SubElement(case, 'system-out')
        system_out.text = xml_text(f'verdict {verdict.verdict} (expected {verdict.expected})'
                                   f'\n{details}')
    ElementTree.indent(suite)
    return ('<?xml version="1.0" encoding="UTF-8"?>\n'
            + ElementTree.tostring(suite, encoding='unicode') + '\n')


def _finite_or_none(value: float, digits: int = 3) -> Optional[float]:
    value = float(value)
    return round(value, digits) if math.isfinite(value) else None


def summary_json(scenario: Scenario, record: RunRecord, verdict: Verdict,
                 extra: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
    """
    Return a JSON-ready summary of one run (plain types; None where undefined).

    Goals reached counts goal and waypoints steps whose outcome is 'reached' (a
    waypoints step counts once, all its waypoints reached); distance_m is the
    length of the true path; localisation errors are |estimate - truth| in x, y (see
    scenario.localization_errors). min_zone_clearance_m is stay_in_zone's least footprint
    clearance (m, < 0: the footprint left the zone; see scenario_judge), first reached at
    min_zone_clearance_at {t_s, x_m, y_m}, with footprint_radius_m the radius judged: all
    None when stay_in_zone measured nothing (disabled, no zone, no ground truth). Each
    criterion has its margin (positive when it passed, <= 0 when it failed; None where it
    has none) and margin_unit ('m', 's'; see scenario_judge). extra
    adds top-level keys (e.g. wall_time_s); a key that is already there raises ValueError.
    """
    goal_indices = [i for i, step in enumerate(scenario.steps)
                    if isinstance(step, (GoalStep, WaypointsStep))]
    reached = sum(1 for i in goal_indices if i < len(record.step_results)
                  and record.step_results[i].outcome == 'reached')
    errors = localization_errors(record.truth, record.estimate)[:, 1]
    zone = zone_result(verdict)
    measured = zone is not None and zone.min_clearance_m is not None
    summary: Dict[str, Any] = {
        'scenario': scenario.name,
        'description': scenario.description,
        'world': scenario.world.name if scenario.world else scenario.world_file.stem,
        'expected': verdict.expected,
        'verdict': verdict.verdict,
        'as_expected': verdict.as_expected,
        'goals_reached': reached,
        'goals_total': len(goal_indices),
        'duration_s': _finite_or_none(record.duration_s),
        'distance_m': _finite_or_none(distance_travelled_m(record.truth)),
        'collisions': len(record.collision_times),
        'localization_error_max_m': (_finite_or_none(np.max(errors)) if len(errors) else None),
        'localization_error_rms_m': (_finite_or_none(math.sqrt(np.mean(errors ** 2)))
                                     if len(errors) else None),
        'min_zone_clearance_m': _finite_or_none(zone.min_clearance_m) if measured else None,
        'min_zone_clearance_at': {'t_s': _finite_or_none(zone.t_s),
                                  'x_m': _finite_or_none(zone.x_m),
                                  'y_m': _finite_or_none(zone.y_m)} if measured else None,
        'footprint_radius_m': _finite_or_none(zone.footprint_radius_m) if measured else None,
        'aborted': record.aborted,
        'safety_events': [{'t_s': _finite_or_none(t), 'node': node, 'state': text,
                           'x_m': _finite_or_none(x), 'y_m': _finite_or_none(y)}
                          for t, node, text, x, y in record.safety_events],
        'chain_states': [{'t_s': _finite_or_none(t), 'node': node, 'state': text}
                         for t, node, text in record.chain_states],
        'steps': [{'kind': r.kind, 'outcome': r.outcome, 'error_code': int(r.error_code),
                   'error_message': r.error_message, 'start_s': _finite_or_none(r.start_s),
                   'end_s': _finite_or_none(r.end_s)} for r in record.step_results],
        'criteria': [{'name': c.name, 'passed': c.passed, 'detail': c.detail,
                      'margin': _finite_or_none(c.margin) if c.margin is not None else None,
                      'margin_unit': c.margin_unit or None}
                     for c in verdict.criteria],
    }
    for key, value in (extra or {}).items():
        if key in summary:
            raise ValueError(f'summary_json: extra key {key!r} would replace a computed one')
        summary[key] = value
    return summary


def plot_run(path_png: Any, occupancy_map: Any, truth: Any, estimate: Any,
             planned_paths: Sequence[Any] = (), goals: Sequence[Sequence[float]] = (),
             collision_points: Sequence[Sequence[float]] = (),
             zone: Optional[Zone] = None, title: str = '',
             safety_events: Sequence[Tuple[float, float, str]] = ()) -> None:
    """
    Write a PNG of one run in world coordinates (metres, equal aspect).

    occupancy_map: a mecanum_map_server.map_io.OccupancyMap (data row 0 = lowest y,
    origin = the lower-left cell corner and yaw) drawn grey (free white, occupied black,
    unknown mid grey), or None. truth (solid) and estimate (dashed): (N, 4) t, x, y, yaw.
    planned_paths: (K, 2) x, y polylines (thin). goals: (x, y[, yaw]) numbered markers.
    collision_points: (x, y) red crosses. zone: the authorised zone (its inclusion and
    exclusion outlines). safety_events: (x, y, text) where the command chain stopped or
    refused a motion (orange triangles).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.transforms import Affine2D

    figure = Figure(figsize=(8.0, 6.5), dpi=100)
    FigureCanvasAgg(figure)
    axes = figure.add_subplot(1, 1, 1)
    if occupancy_map is not None:
        data = np.asarray(occupancy_map.data, dtype=np.float64)
        shade = np.where(data < 0, 0.7, 1.0 - np.clip(data, 0.0, 100.0) / 100.0)
        resolution = occupancy_map.resolution_m
        origin_x, origin_y, yaw = occupancy_map.origin
        image = axes.imshow(
            shade, cmap='gray', vmin=0.0, vmax=1.0, origin='lower', interpolation='nearest',
            extent=(origin_x, origin_x + data.shape[1] * resolution,
                    origin_y, origin_y + data.shape[0] * resolution))
        if yaw:
            image.set_transform(Affine2D().rotate_around(origin_x, origin_y, yaw)
                                + axes.transData)
    if zone is not None:
        for index, polygon in enumerate(zone.polygons()):
            outline = np.vstack([polygon, polygon[:1]])
            if index:
                axes.fill(outline[:, 0], outline[:, 1], color='tab:red', alpha=0.12,
                          label='excluded' if index == 1 else None)
            axes.plot(outline[:, 0], outline[:, 1], color='tab:green' if index == 0
                      else 'tab:red', linewidth=1.2, linestyle=':',
                      label='authorised zone' if index == 0 else None)
    for index, path in enumerate(planned_paths):
        points = np.asarray(path, dtype=np.float64).reshape(-1, 2)
        axes.plot(points[:, 0], points[:, 1], color='tab:blue', linewidth=0.8, alpha=0.8,
                  label='planned paths' if index == 0 else None, zorder=4)
    estimate = track_array(estimate, 'estimate')
    if len(estimate):   # drawn over the truth (it mostly lies on it)
        axes.plot(estimate[:, 1], estimate[:, 2], color='tab:orange', linewidth=1.0,
                  linestyle='--', label='estimate', zorder=3)
    truth = track_array(truth, 'truth')
    if len(truth):
        axes.plot(truth[:, 1], truth[:, 2], color='black', linewidth=1.5, label='ground truth')
        axes.plot(truth[0, 1], truth[0, 2], marker='o', color='black', markersize=5,
                  linestyle='none', label='start')
    for number, goal in enumerate(goals, start=1):
        gx, gy = float(goal[0]), float(goal[1])
        axes.plot(gx, gy, marker='*', color='tab:purple', markersize=11, linestyle='none',
                  label='goals' if number == 1 else None)
        if len(goal) > 2 and math.isfinite(float(goal[2])):
            axes.annotate('', xy=(gx + 0.3 * math.cos(goal[2]), gy + 0.3 * math.sin(goal[2])),
                          xytext=(gx, gy),
                          arrowprops={'arrowstyle': '->', 'color': 'tab:purple'})
        axes.annotate(str(number), (gx, gy), textcoords='offset points', xytext=(6, 6),
                      color='tab:purple', fontsize=9, fontweight='bold')
    events = [(float(x), float(y)) for x, y, _ in safety_events
              if math.isfinite(float(x)) and math.isfinite(float(y))]
    if events:
        points = np.asarray(events)
        axes.plot(points[:, 0], points[:, 1], marker='^', color='tab:orange', markersize=7,
                  markeredgecolor='black', linestyle='none', zorder=6,
                  label=f'command chain stops ({len(events)})')
    collisions = np.asarray(collision_points, dtype=np.float64).reshape(-1, 2)
    if len(collisions):
        axes.plot(collisions[:, 0], collisions[:, 1], marker='x', color='red', markersize=9,
                  markeredgewidth=2, linestyle='none', label='collisions')
    axes.set_aspect('equal')
    axes.set_xlabel('x (m)')
    axes.set_ylabel('y (m)')
    if title:
        axes.set_title(title)
    handles, _ = axes.get_legend_handles_labels()
    if handles:
        axes.legend(loc='upper left', bbox_to_anchor=(1.01, 1.0), fontsize=8,
                    borderaxespad=0.0)
    figure.tight_layout()
    figure.savefig(str(path_png), format='png')
