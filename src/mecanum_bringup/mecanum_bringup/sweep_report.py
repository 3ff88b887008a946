"""
Reports of a sweep: rate tables, the per-axis plot, JUnit XML and one HTML page (no ROS).

Rates come from :mod:`mecanum_bringup.sweep_stats`; rows are the
:class:`mecanum_bringup.sweep_store.VariantRow` s of a results store. The plot is drawn
with matplotlib's object API on an Agg canvas (no pyplot, no display), as in
:mod:`mecanum_bringup.scenario_report`. The HTML page is self-contained (the plot is
embedded as a base64 PNG); it links the worst variants' run folders relatively, so the
sweep's folder can be moved or served as a whole. Where the variants measured it, every
report also gives the least zone clearance (the footprint's least clearance to the
authorised zone's border, m, < 0: out of it; see sweep_stats): per variant (JUnit
property ``min_zone_clearance_m``), overall, and per value of each axis. Where variants
have margins (scenario_judge: how far each criterion was from failing, m or s; positive
when it passed), the rates table gives each criterion's least margin and its variant,
and a second plot (``margins.png``) gives every variant's margin along each axis, one
row of plots per criterion (the steps as one: each variant's least step margin).

Steps are named by what they do, not only by number (:func:`step_labels`): the store
keeps each criterion as the judge named it ('step 2'), and the report reads each
variant's steps from the scenario file that run_sweep writes into its run folder
(``runs/NAME/scenario.yaml``, for every variant before any runs) and describes them
with :meth:`mecanum_bringup.scenario_model.GoalStep.describe` and its siblings. Step 2
of a sweep whose variants all have the same step 2 reads ``step 2: goal (4.00, 2.30)``.
Where variants differ (the scenario axis, or a fault or goals axis, which put a fault
step first or keep other goals), the rate stays one rate per step number, as stored,
and its label says so: ``step 2 (differs by scenario)``, with each scenario's step, when
every variant of one scenario has the same step N; otherwise ``step 1 (differs by
variant)``, with how many different steps of which kinds. A variant whose scenario file
cannot be read (moved or deleted run folders) counts for the rates but names nothing.
"""

import base64
from dataclasses import dataclass
import functools
import html
import json
import math
import os
from pathlib import Path
import re
from typing import Dict, Iterable, List, Optional, Sequence, Tuple, Union
import xml.etree.ElementTree as ElementTree

from mecanum_bringup.scenario_judge import margin_unit
from mecanum_bringup.scenario_report import one_line, xml_text
from mecanum_bringup.sweep_stats import (
    axis_clearances, axis_margins, axis_rates, Change, clearance_order, criterion_rates,
    failed_criteria, least_clearance, least_margins, LeastClearance, LeastMargin,
    margin_group_order, Rate, STEPS_GROUP, summary_axes, value_label, VariantChange,
    worst_variants)
from mecanum_bringup.sweep_store import VariantRow
import yaml

PathLike = Union[str, Path]
#: Longest first failure shown in a table cell or a JUnit message.
MAX_DETAIL_CHARS = 200
#: The files of a run folder that the page links, if they exist.
RUN_FILES = ('run.png', 'summary.json', 'bag', 'scenario.yaml')
#: The variant's scenario file in its run folder (sweep_runner.write_variant_files).
VARIANT_SCENARIO = 'scenario.yaml'
#: A step's criterion name, as the judge names it (scenario_judge: 'step 1' = steps[0]).
_STEP = re.compile(r'step ([1-9][0-9]*)')
_YAML_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)


# --- the steps' names ------------------------------------------------------------------

@dataclass(frozen=True)
class StepLabel:
    """
    What one step number stands for in a sweep: a short label and, if it varies, why.

    label: the table's name of the criterion, e.g. 'step 2: goal (4.00, 2.30)', 'step 2
    (differs by scenario)' or 'step 1 (differs by variant)'; differs: '' (the same in
    every variant), 'scenario' or 'variant'; lines: for a step that differs, what it
    is, e.g. ('fault_border_patrol: goal (4.00, 1.20)', ...) by scenario, or ('66
    different fault steps',) by variant.
    """

    label: str
    differs: str = ''
    lines: Tuple[str, ...] = ()


def _variant_folders(row: VariantRow, runs_base: Optional[Path],
                     out_dir: Optional[Path]) -> List[Path]:
    """Return where the row's run folder may be: run_dir, then out_dir/runs/NAME."""
    folders = []
    if row.run_dir:
        run_dir = Path(row.run_dir)
        if not run_dir.is_absolute() and runs_base is not None:
            run_dir = runs_base / run_dir
        folders.append(run_dir)
    if out_dir is not None:
        folders.append(out_dir / 'runs' / row.name)
    return folders


def variant_steps(row: VariantRow, runs_base: Optional[PathLike] = None,
                  out_dir: Optional[PathLike] = None) -> Optional[Tuple[str, ...]]:
    """
    Return the descriptions of a variant's steps in order ('goal (4.00, 2.30)', ...).

    They come from the scenario file in the row's run folder (run_dir, relative to
    runs_base if relative; else out_dir/runs/NAME), parsed with the scenario loader's
    step checks and described by Step.describe(). None when no such file can be read
    or its steps do not parse.
    """
    base = Path(runs_base) if runs_base is not None else None
    out = Path(out_dir) if out_dir is not None else None
    for folder in _variant_folders(row, base, out):
        try:
            text = (folder / VARIANT_SCENARIO).read_text(encoding='utf-8')
        except (OSError, UnicodeDecodeError):
            continue
        try:
            document = yaml.load(text, Loader=_YAML_LOADER)
            steps = document['scenario']['steps']
            key = json.dumps(steps, sort_keys=True)
        except (yaml.YAMLError, TypeError, KeyError, ValueError):
            return None
        return _describe_steps(key)
    return None


@functools.lru_cache(maxsize=4096)
def _describe_steps(steps_json: str) -> Optional[Tuple[str, ...]]:
    """Return the descriptions of a scenario's steps list (as JSON), or None."""
    from mecanum_bringup.scenario_loader import parse_steps, ScenarioError
    try:
        # The loader's own step checks (no world needed): the same Step objects, so the
        # same describe() as the judge's lines and the runner's progress.
        steps = parse_steps(json.loads(steps_json), VARIANT_SCENARIO)
    except (ScenarioError, LookupError, OSError):
        return None
    return tuple(step.describe() for step in steps)


def _kinds_text(descriptions: Iterable[str]) -> str:
    """Return e.g. '66 different fault steps' or '3 different steps (goal, wait)'."""
    distinct = list(dict.fromkeys(descriptions))
    kinds = list(dict.fromkeys(text.split(' ', 1)[0] for text in distinct))
    if len(kinds) == 1:
        return f'{len(distinct)} different {kinds[0]} steps'
    return f'{len(distinct)} different steps ({", ".join(kinds)})'


def step_labels(rows: Sequence[VariantRow], runs_base: Optional[PathLike] = None,
                out_dir: Optional[PathLike] = None) -> Dict[str, StepLabel]:
    """
    Return {'step N': StepLabel} for each step number of the rows' variants.

    A step every variant has the same way gets 'step N: DESCRIPTION'. One that differs
    between variants of different scenarios (axis 'scenario') but is the same within
    each scenario gets 'step N (differs by scenario)' with a line 'SCENARIO: DESCRIPTION'
    per scenario (in order of first appearance by index; a scenario without a step N has
    no line); any other that differs gets 'step N (differs by variant)' with one line
    counting its different steps and their kinds. Only variants whose steps could be read
    (variant_steps) count; a step number none of them has is left out.
    """
    found: Dict[str, List[Tuple[Optional[str], str]]] = {}
    for row in sorted(rows, key=lambda item: item.index):
        steps = variant_steps(row, runs_base, out_dir)
        if steps is None:
            continue
        scenario = row.values.get('scenario')
        scenario = scenario if isinstance(scenario, str) else None
        for number, description in enumerate(steps, start=1):
            found.setdefault(f'step {number}', []).append((scenario, description))
    labels = {}
    for name, pairs in found.items():
        descriptions = list(dict.fromkeys(description for _, description in pairs))
        if len(descriptions) == 1:
            labels[name] = StepLabel(f'{name}: {descriptions[0]}')
            continue
        by_scenario: Dict[Optional[str], List[str]] = {}
        for scenario, description in pairs:
            by_scenario.setdefault(scenario, [])
            if description not in by_scenario[scenario]:
                by_scenario[scenario].append(description)
        if None not in by_scenario and all(len(d) == 1 for d in by_scenario.values()):
            labels[name] = StepLabel(
                f'{name} (differs by scenario)', 'scenario',
                tuple(f'{scenario}: {d[0]}' for scenario, d in by_scenario.items()))
        else:
            labels[name] = StepLabel(f'{name} (differs by variant)', 'variant',
                                     (_kinds_text(descriptions),))
    return labels


def _criterion_label(name: str, labels: Dict[str, StepLabel]) -> str:
    """Return a criterion's table label: a step's label, or the name itself."""
    label = labels.get(name)
    return label.label if label is not None else name


def _step_legend(labels: Dict[str, StepLabel]) -> List[str]:
    """Return one line per step that differs: 'step 2 by scenario: A: ...; B: ...'."""
    lines = []
    for name in sorted(labels, key=lambda item: int(_STEP.fullmatch(item).group(1))):
        label = labels[name]
        if label.differs:
            lines.append(f'{name} by {label.differs}: {"; ".join(label.lines)}')
    return lines


def _percent(value: float) -> str:
    return f'{100 * value:.1f} %'


def _interval(rate: Rate) -> str:
    return f'{100 * rate.low:.1f}-{100 * rate.high:.1f} %' if rate.n else '-'


def _fixed_width(rows: Sequence[Sequence[str]], right: Sequence[int] = ()) -> List[str]:
    """Return the rows (the first is the header) as aligned lines, a dash line second."""
    widths = [max(len(row[column]) for row in rows) for column in range(len(rows[0]))]

    def line(row: Sequence[str]) -> str:
        return '  '.join(cell.rjust(width) if column in right else cell.ljust(width)
                         for column, (cell, width) in enumerate(zip(row, widths))).rstrip()

    return [line(rows[0]), '  '.join('-' * width for width in widths)] + [
        line(row) for row in rows[1:]]


def _metres(value: Optional[float]) -> str:
    return f'{value:.3f} m' if value is not None and math.isfinite(value) else '-'


def _least_text(least: LeastClearance) -> str:
    """Return e.g. '-0.050 m in tour_0001; 1 of 3 measured variants below 0 m'."""
    return (f'{_metres(least.clearance_m)} in {least.variant}; {least.below_zero} of '
            f'{least.measured} measured variant{"" if least.measured == 1 else "s"} below 0 m')


def _margin_text(least: Optional[LeastMargin]) -> str:
    """Return e.g. '0.085 m (tour_0003)' for a criterion's least margin, '-' if none."""
    if least is None:
        return '-'
    return f'{least.margin:.3f} {margin_unit(least.criterion)} ({least.variant})'


def _status_counts(rows: Sequence[VariantRow]) -> str:
    counts = {status: sum(row.status == status for row in rows)
              for status in ('OK', 'UNEXPECTED', 'ERROR')}
    return (f'{len(rows)} variant{"" if len(rows) == 1 else "s"}: {counts["OK"]} as '
            f'expected, {counts["UNEXPECTED"]} unexpected, {counts["ERROR"]} errors')


def rates_table(rows: Sequence[VariantRow], runs_base: Optional[PathLike] = None) -> str:
    """
    Return a fixed-width table of the failure rates and a summary line.

    One line per rate (the verdict first, then the criteria): criterion, failures/n, rate,
    95 % CI (Wilson). The verdict counts ERROR rows as failures. A step is named by what
    it does (step_labels; run folders relative to runs_base, default the current
    folder), e.g. 'step 2: goal (4.00, 2.30)'; for each step that differs between
    variants a line after the table says how ('step 2 by scenario: A: ...; B: ...').
    When some variant measured it, a last line gives the least zone clearance and its
    variant.
    """
    labels = step_labels(rows, runs_base)
    margins = least_margins(rows)
    table = [('criterion', 'failures/n', 'rate', '95 % CI')
             + (('least margin',) if margins else ())]
    for rate in criterion_rates(rows):
        table.append((_criterion_label(rate.name, labels), f'{rate.failures}/{rate.n}',
                      _percent(rate.rate) if rate.n else '-', _interval(rate))
                     + ((_margin_text(margins.get(rate.name)),) if margins else ()))
    lines = _fixed_width(table, right=(1, 2, 3))
    lines += _step_legend(labels)
    lines.append(_status_counts(rows))
    least = least_clearance(rows)
    if least.measured:
        lines.append(f'least zone clearance: {_least_text(least)}')
    return '\n'.join(lines) + '\n'


def compare_table(changes: Sequence[Change],
                  labels: Optional[Dict[str, StepLabel]] = None) -> str:
    """
    Return a fixed-width table of compare's changes and a summary line.

    One line per rate: criterion, A's and B's failures/n with rate and interval, and
    the change ('worse' or 'better' only when the intervals do not overlap). labels
    (step_labels) name the steps by what they do, e.g. 'step 2: goal (4.00, 2.30)'; the
    lines after the table say how the steps that differ between variants differ.
    """
    labels = labels or {}
    table = [('criterion', 'A failures/n', 'A rate (95 % CI)', 'B failures/n',
              'B rate (95 % CI)', 'change')]
    for change in changes:
        cells: List[str] = [_criterion_label(change.name, labels)]
        for rate in (change.a, change.b):
            cells += [f'{rate.failures}/{rate.n}',
                      f'{_percent(rate.rate)} ({_interval(rate)})' if rate.n else '-']
        cells.append(change.verdict)
        table.append(tuple(cells))
    lines = _fixed_width(table, right=(1, 2, 3, 4))
    lines += _step_legend(labels)
    worse = [c.name for c in changes if c.verdict == 'worse']
    better = [c.name for c in changes if c.verdict == 'better']
    lines.append(f'{len(worse)} worse{": " + ", ".join(worse) if worse else ""}; '
                 f'{len(better)} better{": " + ", ".join(better) if better else ""} '
                 '(beyond the 95 % intervals)')
    return '\n'.join(lines) + '\n'


def variant_changes_table(changes: Sequence[VariantChange], both: int) -> str:
    """
    Return the variants whose status differs between sweeps A and B, one line each.

    Each line: the variant, A's and B's status and, for a failed one, its first failure
    (or error); then how many of the variants run in both kept their status.
    """
    lines = []
    for change in changes:
        parts = []
        for label, row in (('A', change.a), ('B', change.b)):
            why = row.first_failure or row.error
            parts.append(f'{label} {row.status}' + (f' ({one_line(why, 120)})' if why else ''))
        lines.append(f'{change.name}: ' + '; '.join(parts))
    lines.append(f'{both - len(changes)} of {both} variants run in both sweeps have the same '
                 f'status; {len(changes)} another')
    return '\n'.join(lines) + '\n'


def plot_axis_rates(rows: Sequence[VariantRow], axes: Sequence[str],
                    path_png: PathLike) -> None:
    """
    Write a PNG of the verdict's failure rate along each axis (one subplot per axis).

    Each value (or bin, see sweep_stats.axis_rates) is a point at its failure rate
    with its Wilson 95 % interval as an error bar, labelled with the number of runs.
    An axis without rows says so. At least one subplot is drawn.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    axes = list(axes) or ['(no axes)']
    figure = Figure(figsize=(8.0, 0.6 + 2.8 * len(axes)), dpi=100)
    FigureCanvasAgg(figure)
    for number, axis in enumerate(axes, start=1):
        plot = figure.add_subplot(len(axes), 1, number)
        rates = axis_rates(rows, axis)
        plot.set_title(axis, fontsize=10)
        plot.set_ylim(-0.02, 1.02)
        plot.set_ylabel('failure rate')
        plot.grid(True, axis='y', alpha=0.3)
        if not rates:
            plot.text(0.5, 0.5, 'no variants with this axis', ha='center', va='center',
                      transform=plot.transAxes, color='grey')
            plot.set_xticks([])
            continue
        xs = list(range(len(rates)))
        values = [rate.rate for _, rate in rates]
        below = [rate.rate - rate.low for _, rate in rates]
        above = [rate.high - rate.rate for _, rate in rates]
        plot.errorbar(xs, values, yerr=[below, above], fmt='o', color='tab:red',
                      ecolor='grey', capsize=4, markersize=5)
        for x, (_, rate) in zip(xs, rates):
            plot.annotate(f'{rate.failures}/{rate.n}', (x, rate.rate),
                          textcoords='offset points', xytext=(6, 4), fontsize=7)
        labels = [one_line(label, 24) for label, _ in rates]
        long_labels = len(rates) > 4 or max(len(label) for label in labels) > 10
        plot.set_xticks(xs)
        plot.set_xticklabels(labels, rotation=30 if long_labels else 0,
                             ha='right' if long_labels else 'center', fontsize=8)
        plot.set_xlim(-0.5, len(rates) - 0.5)
    figure.tight_layout()
    figure.savefig(str(path_png), format='png')


def plot_axis_margins(rows: Sequence[VariantRow], axes: Sequence[str],
                      path_png: PathLike) -> bool:
    """
    Write a PNG of every variant's margins along each axis; return False if none has any.

    One row of subplots per margin group (sweep_stats.margin_group_order: 'steps', each
    variant's least step margin, then each criterion), one column per axis; each variant
    is a point at its axis value (or bin, as in the rates plot) and its margin, red when
    its verdict was not the expected one; a line marks 0, below which a criterion failed.
    """
    groups = margin_group_order(rows)
    if not groups:
        return False
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    axes = list(axes) or ['(no axes)']
    figure = Figure(figsize=(0.8 + 3.4 * len(axes), 0.6 + 2.4 * len(groups)), dpi=100)
    FigureCanvasAgg(figure)
    for row_number, group in enumerate(groups):
        unit = margin_unit('step 1' if group == STEPS_GROUP else group)
        for column, axis in enumerate(axes):
            plot = figure.add_subplot(len(groups), len(axes), row_number * len(axes)
                                      + column + 1)
            plot.axhline(0.0, color='grey', linewidth=0.8)
            plot.grid(True, axis='y', alpha=0.3)
            if row_number == 0:
                plot.set_title(axis, fontsize=10)
            if column == 0:
                plot.set_ylabel(f'{group} margin ({unit})', fontsize=8)
            points = axis_margins(rows, axis, group)
            if not any(values for _, values in points):
                plot.text(0.5, 0.5, 'no margins', ha='center', va='center',
                          transform=plot.transAxes, color='grey')
                plot.set_xticks([])
                continue
            for x, (_, values) in enumerate(points):
                spread = [x + 0.3 * ((i + 0.5) / len(values) - 0.5) for i in range(len(values))]
                plot.scatter(spread, [margin for margin, _ in values], s=10,
                             c=['tab:red' if failed else 'tab:blue' for _, failed in values])
            labels = [one_line(label, 16) for label, _ in points]
            plot.set_xticks(list(range(len(points))))
            plot.set_xticklabels(labels, rotation=30 if len(points) > 3 else 0,
                                 ha='right' if len(points) > 3 else 'center', fontsize=7)
            plot.set_xlim(-0.5, len(points) - 0.5)
    figure.tight_layout()
    figure.savefig(str(path_png), format='png')
    return True


def replay_command(row: VariantRow, runs_base: Optional[PathLike] = None) -> str:
    """
    Return the command that runs a variant again, exactly, recorded ('' without a folder).

    The scenario file the sweep wrote for it (runs/NAME/scenario.yaml, with its own
    world file beside it when the person axis changed it), run by run_scenarios with
    --record into the sweep folder's replay/ (a run folder relative to runs_base).
    """
    if not row.run_dir:
        return ''
    run_dir = Path(row.run_dir)
    if not run_dir.is_absolute() and runs_base is not None:
        run_dir = Path(runs_base) / run_dir
    return (f'ros2 run mecanum_bringup run_scenarios {run_dir / VARIANT_SCENARIO} --record '
            f'--out {run_dir.parent.parent / "replay"}')


def _values_text(row: VariantRow) -> str:
    return '\n'.join(f'{axis} = {value_label(value)}' for axis, value in row.values.items())


def junit_xml(rows: Sequence[VariantRow], sweep_name: str) -> str:
    """
    Return a JUnit XML report: one testsuite named sweep_name, one testcase per variant.

    A testcase is named by the row's name, classname = sweep_name, time = its wall-clock
    time. Status UNEXPECTED gives a <failure> (message = first_failure), ERROR an
    <error> (message = error); OK rows (expected failures included) pass. Each testcase
    has <properties> with the variant's axis values (as JSON-ish labels), its status,
    when measured, min_zone_clearance_m (m, 3 decimals), and replay (the command that
    runs it again, recorded: replay_command), and a <system-out> with the values, the
    failed criteria, the least zone clearance, the run folder and that command.
    """
    rows = sorted(rows, key=lambda row: row.index)

    def seconds(value: Optional[float]) -> float:
        return value if value is not None and math.isfinite(value) else 0.0

    suite = ElementTree.Element('testsuite', {
        'name': xml_text(sweep_name), 'tests': str(len(rows)),
        'failures': str(sum(row.status == 'UNEXPECTED' for row in rows)),
        'errors': str(sum(row.status == 'ERROR' for row in rows)), 'skipped': '0',
        'time': f'{sum(seconds(row.wall_time_s) for row in rows):.3f}'})
    for row in rows:
        case = ElementTree.SubElement(suite, 'testcase', {
            'name': xml_text(row.name), 'classname': xml_text(sweep_name),
            'time': f'{seconds(row.wall_time_s):.3f}'})
        properties = ElementTree.SubElement(case, 'properties')
        for key, value in [('index', row.index), ('status', row.status)] + list(
                row.values.items()):
            ElementTree.SubElement(properties, 'property', {
                'name': xml_text(key), 'value': xml_text(value_label(value))})
        clearance = row.min_zone_clearance_m
        if clearance is not None and math.isfinite(clearance):
            ElementTree.SubElement(properties, 'property', {
                'name': 'min_zone_clearance_m', 'value': f'{clearance:.3f}'})
        replay = replay_command(row)
        if replay:
            ElementTree.SubElement(properties, 'property', {
                'name': 'replay', 'value': xml_text(replay)})
        if row.status == 'ERROR':
            error = ElementTree.SubElement(case, 'error', {
                'message': xml_text(one_line(row.error, 500)), 'type': 'ScenarioError'})
            error.text = xml_text(row.error)
        elif row.status != 'OK':
            failure = ElementTree.SubElement(case, 'failure', {
                'message': xml_text(one_line(row.first_failure, 500)),
                'type': 'UnexpectedVerdict'})
            failure.text = xml_text(
                f'expected {row.expected}, got {row.verdict or "no verdict"}: '
                f'{row.first_failure}')
        failed = failed_criteria(row)
        system_out = ElementTree.SubElement(case, 'system-out')
        system_out.text = xml_text(
            f'{_values_text(row)}\nstatus {row.status}, verdict {row.verdict or "-"} '
            f'(expected {row.expected})\nfailed criteria: {", ".join(failed) or "none"}\n'
            f'least zone clearance: {_metres(clearance)}\nrun folder: {row.run_dir or "-"}'
            f'\nreplay: {replay or "-"}')
    ElementTree.indent(suite)
    return ('<?xml version="1.0" encoding="UTF-8"?>\n'
            + ElementTree.tostring(suite, encoding='unicode') + '\n')


def _run_links(row: VariantRow, out_dir: Path, runs_base: Path) -> List[Tuple[str, str]]:
    """Return (file name, relative link) for the run folder's files that exist."""
    if not row.run_dir:
        return []
    run_dir = Path(row.run_dir)
    if not run_dir.is_absolute():
        run_dir = runs_base / run_dir
    links = []
    for name in RUN_FILES:
        target = run_dir / name
        if target.exists():
            link = Path(os.path.relpath(target.resolve(), out_dir.resolve())).as_posix()
            links.append((name, link + ('/' if target.is_dir() else '')))
    return links


def _html_table(header: Sequence[str], rows: Sequence[Sequence[str]],
                numeric: Sequence[int] = ()) -> str:
    """Return an HTML table; cells are already HTML (escape them before)."""
    head = ''.join(f'<th>{cell}</th>' for cell in header)
    body = ''.join(
        '<tr>' + ''.join(f'<td class="num">{cell}</td>' if column in numeric
                         else f'<td>{cell}</td>' for column, cell in enumerate(row)) + '</tr>'
        for row in rows)
    return f'<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'


def _criterion_cell(name: str, labels: Dict[str, StepLabel]) -> str:
    """Return a criterion's rates table cell (HTML): its label and, if it differs, how."""
    label = labels.get(name)
    if label is None:
        return html.escape(name)
    return '<br>'.join(html.escape(line) for line in (label.label,) + label.lines)


def _failed_names(row: VariantRow, steps: Optional[Sequence[str]]) -> List[str]:
    """Return the row's failed criteria, each step with its description if known."""
    names = []
    for name in failed_criteria(row):
        match = _STEP.fullmatch(name)
        number = int(match.group(1)) if match else 0
        names.append(f'{name}: {steps[number - 1]}' if steps and 0 < number <= len(steps)
                     else name)
    return names


def _least_cell(least: LeastClearance) -> str:
    """Return e.g. '-0.050 m (tour_0001)', or '-' when no variant measured it."""
    if least.clearance_m is None:
        return '-'
    return f'{_metres(least.clearance_m)} ({html.escape(least.variant)})'


_STYLE = ('body{font-family:sans-serif;margin:2em;max-width:70em}'
          'table{border-collapse:collapse;margin:0.5em 0 1.5em}'
          'th,td{border:1px solid #ccc;padding:0.25em 0.6em;text-align:left;'
          'vertical-align:top}td.num{text-align:right;font-variant-numeric:tabular-nums}'
          'th{background:#f3f3f3}.bad{color:#b00}pre{margin:0}img{max-width:100%}')


def write_report(rows: Sequence[VariantRow], sweep_name: str, out_dir: PathLike,
                 axes: Sequence[str], description: str = '', worst_count: int = 10,
                 runs_base: Optional[PathLike] = None) -> Path:
    """
    Write out_dir/report.html, rates.png, junit.xml (and margins.png); return the HTML path.

    The page (self-contained, every text HTML-escaped) has the sweep's name and
    description, the number of variants, the rates table with Wilson 95 % intervals,
    the per-axis plot (embedded as a base64 PNG) with its numbers, and the worst
    worst_count variants (sweep_stats.worst_variants) with their values, failed criteria,
    first failure or error, and relative links to their run folder's run.png,
    summary.json and bag/ when those exist. A row's relative run_dir is taken relative to
    runs_base (default: out_dir). Steps are named by what they do (step_labels, reading
    each variant's run folder, or out_dir/runs/NAME): 'step 2: goal (4.00, 2.30)' in the
    rates table, with each scenario's step, or how many different steps, under a step
    that differs between variants; a worst variant's failed steps are its own. The axes
    are axes and, for an axis of mappings with a
    kind (faults), 'AXIS.kind' after it (sweep_stats.summary_axes). When some variant
    measured its least zone clearance, the per-axis tables give each value's least (and
    its variant), a section gives the overall least and the worst_count variants of
    least clearance, and the worst variants table gives each one's. When some variant has
    margins, the rates table gives each criterion's least margin and its variant, and
    margins.png (plot_axis_margins) is embedded after the rates plot.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    base = Path(runs_base) if runs_base is not None else out_dir
    esc = html.escape
    rows = sorted(rows, key=lambda row: row.index)
    axes = summary_axes(rows, axes)
    least = least_clearance(rows)
    clearances = least.measured > 0

    png_path = out_dir / 'rates.png'
    plot_axis_rates(rows, axes, png_path)
    margins_png = out_dir / 'margins.png'
    has_margins = plot_axis_margins(rows, axes, margins_png)
    (out_dir / 'junit.xml').write_text(junit_xml(rows, sweep_name), encoding='utf-8')
    png = base64.b64encode(png_path.read_bytes()).decode('ascii')

    labels = step_labels(rows, base, out_dir)
    margins = least_margins(rows)
    rate_rows = [(_criterion_cell(rate.name, labels), f'{rate.failures}/{rate.n}',
                  _percent(rate.rate) if rate.n else '-', _interval(rate))
                 + ((esc(_margin_text(margins.get(rate.name))),) if margins else ())
                 for rate in criterion_rates(rows)]
    parts = [
        '<!DOCTYPE html>', '<html lang="en"><head><meta charset="utf-8">',
        f'<title>Sweep {esc(sweep_name)}</title><style>{_STYLE}</style></head><body>',
        f'<h1>Sweep {esc(sweep_name)}</h1>']
    if description:
        parts.append(f'<p>{esc(description)}</p>')
    parts += [f'<p>{esc(_status_counts(rows))}. A variant fails when its verdict is not the '
              'expected one or it could not be judged (ERROR).</p>',
              '<h2>Failure rates</h2>',
              _html_table(('criterion', 'failures/n', 'rate', '95 % CI (Wilson)')
                          + (('least margin (variant)',) if margins else ()), rate_rows,
                          numeric=(1, 2, 3)),
              '<h2>Failure rate along each axis</h2>',
              f'<img src="data:image/png;base64,{png}" alt="failure rate along each axis">']
    if has_margins:
        margins_data = base64.b64encode(margins_png.read_bytes()).decode('ascii')
        parts += ['<h2>Margins along each axis</h2>',
                  '<p>How far each variant was from failing each criterion (m or s; '
                  'below 0 it failed; red: the verdict was not the expected one; the '
                  "steps as one: each variant's least step margin, the time left before "
                  'its timeout).</p>',
                  f'<img src="data:image/png;base64,{margins_data}" '
                  'alt="margins along each axis">']
    for axis in axes:
        rates = axis_rates(rows, axis)
        if rates:
            header = ('value', 'failures/n', 'rate', '95 % CI')
            cells = [(esc(label), f'{rate.failures}/{rate.n}', _percent(rate.rate),
                      _interval(rate)) for label, rate in rates]
            if clearances:   # the same groups, in the same order
                header += ('least zone clearance',)
                cells = [row_cells + (_least_cell(group),) for row_cells, group in
                         zip(cells, axis_clearances(rows, axis))]
            parts.append(f'<h3>{esc(axis)}</h3>')
            parts.append(_html_table(header, cells, numeric=(1, 2, 3, 4)))

    if clearances:
        parts += ['<h2>Zone clearance</h2>',
                  f"<p>The footprint's least clearance to the authorised zone's border "
                  f'(m; below 0 it left the zone): least {esc(_least_text(least))}; '
                  f'{least.n - least.measured} not measured. The '
                  f'{min(max(0, worst_count), least.measured)} least clearances (every '
                  "variant's is in junit.xml and results.sqlite):</p>"]
        least_rows = []
        for row in clearance_order(rows)[:max(0, worst_count)]:
            judged = row.criteria.get('stay_in_zone')
            links = ' '.join(f'<a href="{esc(link)}">{esc(name)}</a>'
                             for name, link in _run_links(row, out_dir, base))
            least_rows.append((
                esc(row.name), _metres(row.min_zone_clearance_m),
                '-' if judged is None else 'pass' if judged else 'FAIL', esc(row.status),
                '<br>'.join(esc(line) for line in _values_text(row).splitlines()) or '-',
                links or '-'))
        parts.append(_html_table(('variant', 'least zone clearance', 'stay_in_zone',
                                  'status', 'values', 'run'), least_rows, numeric=(1,)))

    worst = worst_variants(rows, worst_count)
    parts.append('<h2>Worst variants</h2>')
    if not worst:
        parts.append('<p>No variant failed.</p>')
    else:
        worst_rows = []
        for row in worst:
            detail = row.error if row.status == 'ERROR' else row.first_failure
            links = ' '.join(f'<a href="{esc(link)}">{esc(name)}</a>'
                             for name, link in _run_links(row, out_dir, base))
            replay = replay_command(row, base)
            cells = (
                esc(row.name), f'<span class="bad">{esc(row.status)}</span>',
                '<br>'.join(esc(line) for line in _values_text(row).splitlines()) or '-',
                '<br>'.join(esc(name) for name in _failed_names(
                    row, variant_steps(row, base, out_dir))) or '-',
                esc(one_line(detail, MAX_DETAIL_CHARS)) or '-', links or '-',
                f'<code>{esc(replay)}</code>' if replay else '-')
            worst_rows.append(cells + ((_metres(row.min_zone_clearance_m),)
                                       if clearances else ()))
        header = ('variant', 'status', 'values', 'failed criteria', 'first failure / error',
                  'run', 'replay (recorded)') + (('least zone clearance',) if clearances
                                                 else ())
        parts.append(_html_table(header, worst_rows, numeric=(7,)))
    parts.append('</body></html>')
    path = out_dir / 'report.html'
    path.write_text('\n'.join(parts) + '\n', encoding='utf-8')
    return path
