"""
Sweep files: one scenario run over many variants, the same variants every time (pure).

A sweep varies a scenario along axes and runs every variant, so that a failure rate
replaces a single pass or fail. One sweep per YAML file; units as in scenario files::

    sweep:
      name: tour_robustness            # required, [A-Za-z0-9_-]+
      scenario: apartment_tour         # required (unless axes.scenario): a shipped
                                       # scenario's name, or a scenario file relative to
                                       # this file
      mode: random                     # grid (default: every combination of the axes'
                                       # lists) | random (samples draws from master_seed)
                                       # | search (rounds steered toward failures)
      samples: 50                      # random, search: how many variants (the budget)
      master_seed: 1                   # random, search: the same file gives the same
                                       # variants (search: and the same results)
      search:                          # search only; every key optional
        objective: least               # the margin to drive down: least (of every
                                       # line's), steps, no_collision, stay_in_zone,
                                       # max_localization_error_m, max_duration_s
        batch: 8                       # variants per round (run at once with --jobs)
        elite_fraction: 0.2            # the best share of the runs so far that the
                                       # next round's distributions are fitted to
        smoothing: 0.8                 # fitted share of each draw (the rest: the axis's
                                       # own distribution)
      axes:                            # at least one; each a list of values, or in random
                                       # mode a distribution
        scenario: [apartment_tour, ../scenarios/kitchen_run.yaml]   # instead of
                                       # sweep.scenario: the scenarios, as sweep.scenario
                                       # names them (values: the scenarios' names)
        seed: {range: [0, 1000]}       # the scenario's seed (sensor noise, the start
                                       # pose's spread): integers lo <= seed < hi, or a list
        world: [apartment]             # world names or files (relative to this file)
        floor_friction_coefficient: {uniform: [0.2, 1.0]}   # or a list; 0 = the robot's own
        sensor_noise_scale: [0.5, 1.0, 2.0]   # times the simulator's lidar and IMU noise
        spawn: [{x: 2.95, y: 2.0, yaw: 0.0}, {x: 4.8, y: 2.0}]   # start poses (initial
                                       # pose = spawn)
        person: [{speed_m_s: 0.5}, {speed_m_s: 1.2, path: [[5.0, 2.9], [7.2, 3.3]]}]
                                       # changes to the world's moving obstacle 'person'
                                       # (speed_m_s, path, loop, radius_m; name: another one)
        goals: {sample: 4}             # goal steps kept: k of them at random, in order;
                                       # or a list of index lists, e.g. [[0, 1], [2, 3]]
                                       # (indices among the scenario's goal steps, from 0;
                                       # with axes.scenario, of every scenario)
        fault:                         # a fault step first in the scenario: mappings of
        - {kind: lidar_blinded, duration_s: 5.0}   # robot_simulation.faults (a fault
        - {kind: node_killed, node: amcl}          # step's keys; null: no fault)
        fault_onset_s: [5, 15, 30]     # the faults' onset_s (s from the first step), or
                                       # {uniform: [lo, hi]}; needs the fault axis (whose
                                       # mappings then have no onset_s)

In grid mode every axis is a list and the variants are their cartesian product, in the
order of the axes above (the last axis varies fastest). In random mode variant i draws
each axis from its own generator seeded by (master_seed, i), so adding samples keeps
the earlier variants and a variant's values do not depend on the other axes. In search
mode the first round is drawn so too and each later one from distributions fitted to
the variants that came closest to failing (:mod:`mecanum_bringup.sweep_search`).

:func:`load_sweep` raises :class:`SweepError` naming the file, the line and the key,
e.g. ``sweep.yaml:7: axes.seed.range: must be [lo, hi] integers with lo < hi``.
:func:`variants` lists the :class:`Variant` s; :func:`variant_documents` turns one into
the scenario document (and, for the person axis, the world document) that the runner
writes and loads with :func:`mecanum_bringup.scenario_loader.load_scenario`, which checks it
like any scenario file (a spawn in a wall is an error naming the variant).
"""

import copy
from dataclasses import dataclass, field
import hashlib
import itertools
import json
import math
from pathlib import Path
import random
from typing import Any, Dict, List, Optional, Tuple, Union

from mecanum_control.yaml_files import DocumentChecker, key_lines, load_yaml_file_with_nodes
from robot_simulation.faults import FaultError, parse_fault
import yaml

PathLike = Union[str, Path]

#: The axes, in the order in which grid variants vary them (the last fastest).
AXES = ('scenario', 'seed', 'world', 'floor_friction_coefficient', 'sensor_noise_scale',
        'spawn', 'person', 'goals', 'fault', 'fault_onset_s')
MODES = ('grid', 'random', 'search')
#: Modes that draw samples variants from master_seed (distributions allowed).
DRAWN_MODES = ('random', 'search')
SWEEP_KEYS = ('name', 'scenario', 'mode', 'samples', 'master_seed', 'axes', 'description',
              'search')
SEARCH_KEYS = ('objective', 'batch', 'elite_fraction', 'smoothing')
#: A search's objective: the least margin of every line a variant has.
LEAST = 'least'
#: What a search's objective may name: the least of them, the steps (each variant's
#: least step margin, s) or a verdict line with a margin.
OBJECTIVES = (LEAST, 'steps', 'no_collision', 'stay_in_zone', 'max_localization_error_m',
              'max_duration_s')
PERSON_KEYS = ('name', 'speed_m_s', 'path', 'loop', 'radius_m')
#: Most variants a sweep may have (a typo in a grid should not start a month of runs).
MAX_VARIANTS = 10000


class SweepError(ValueError):
    """A malformed sweep file; the message names the file, the line and the key."""


@dataclass(frozen=True)
class SearchSpec:
    """A search's settings (see the module docstring and mecanum_bringup.sweep_search)."""

    objective: str = LEAST
    batch: int = 8
    elite_fraction: float = 0.2
    smoothing: float = 0.8

    def as_dict(self) -> Dict[str, Any]:
        """Return the settings as a mapping (part of the sweep's fingerprint)."""
        return {'objective': self.objective, 'batch': self.batch,
                'elite_fraction': self.elite_fraction, 'smoothing': self.smoothing}


@dataclass(frozen=True)
class Sweep:
    """A checked sweep file (axes: axis name -> list of values or a distribution)."""

    name: str
    source: Path
    scenario_file: Path
    mode: str
    axes: Dict[str, Any]
    samples: int = 0
    master_seed: int = 0
    description: str = ''
    goal_count: int = 0   # goal steps in the scenario (for the goals axis)
    scenario_document: Dict[str, Any] = field(default_factory=dict, compare=False,
                                              repr=False)
    #: With axes.scenario: scenario name -> (its file, its document); the first one is
    #: also scenario_file and scenario_document.
    scenarios: Dict[str, Tuple[Path, Dict[str, Any]]] = field(
        default_factory=dict, compare=False, repr=False)
    #: mode search: its settings (None in the other modes).
    search: Optional[SearchSpec] = None

    @property
    def fingerprint(self) -> str:
        """Return what fixes the variants (mode, samples, seed, axes) as canonical JSON."""
        fixed = {'scenario': str(self.scenario_file), 'mode': self.mode,
                 'samples': self.samples, 'master_seed': self.master_seed, 'axes': self.axes}
        if self.search is not None:
            fixed['search'] = self.search.as_dict()
        if self.scenarios:
            fixed['scenarios'] = {name: str(path) for name, (path, _) in self.scenarios.items()}
        return json.dumps(fixed, sort_keys=True)


@dataclass(frozen=True)
class Variant:
    """One variant: its index (from 0) and the value of each axis (JSON-ready)."""

    index: int
    values: Dict[str, Any]

    def name(self, sweep_name: str) -> str:
        """Return the variant's run name, e.g. 'tour_robustness_0007'."""
        return f'{sweep_name}_{self.index:04d}'

    @property
    def key(self) -> str:
        """Return the values as canonical JSON (what a results store compares)."""
        return json.dumps(self.values, sort_keys=True)

    def describe(self) -> str:
        """Return e.g. 'seed=3 floor_friction_coefficient=0.41'."""
        return ' '.join(f'{axis}={_short(value)}' for axis, value in self.values.items())


def _short(value: Any) -> str:
    if isinstance(value, float):
        return f'{value:g}'
    if value is None:
        return 'none'
    if isinstance(value, dict) and 'kind' in value:   # a fault: kind(key=value,...)
        params = ','.join(f'{key}={item if isinstance(item, str) else _short(item)}'
                          for key, item in value.items() if key != 'kind')
        return f'{value["kind"]}({params})' if params else str(value['kind'])
    if isinstance(value, dict) and set(value) <= {'x', 'y', 'yaw'}:
        return '({:g},{:g},{:g})'.format(value['x'], value['y'], value.get('yaw', 0.0))
    return json.dumps(value, separators=(',', ':'))


# --- loading -------------------------------------------------------------------------

def load_sweep(path: PathLike) -> Sweep:
    """Read and check a sweep file; raise SweepError naming the file, line and key."""
    path = Path(path)
    # One parse: the node tree gives the keys' lines, the document is built from it.
    doc, node = load_yaml_file_with_nodes(path, 'sweep file', SweepError)
    return _Parser(path, key_lines(node)).parse(doc)


class _Parser(DocumentChecker):
    """Checks one sweep document; every failure names the file, the line and the key."""

    def __init__(self, path: Path, lines: Dict[str, int]):
        super().__init__(SweepError, path.name, lines)
        self.path = path

    def parse(self, doc: Any) -> Sweep:
        """Check the whole document and return the Sweep."""
        raw = self.mapping(self.document(doc, 'sweep'), 'sweep', ('name', 'axes'),
                           [k for k in SWEEP_KEYS if k not in ('name', 'axes')])
        name = self.identifier(raw['name'], 'sweep.name')
        description = raw.get('description') or ''
        if not isinstance(description, str):
            self.fail('sweep.description', f'must be a string, not {description!r}')
        mode = self.choice(raw.get('mode', 'grid'), 'sweep.mode', MODES)
        axes_raw = raw['axes']
        scenarios: Dict[str, Tuple[Path, Dict[str, Any]]] = {}
        if isinstance(axes_raw, dict) and 'scenario' in axes_raw:
            if 'scenario' in raw:
                self.fail('sweep.scenario', 'is not allowed with axes.scenario (the axis '
                          'names the scenarios)')
            scenarios = self.scenario_axis(axes_raw['scenario'], 'sweep.axes.scenario')
            scenario_file, scenario_doc = next(iter(scenarios.values()))
        elif 'scenario' not in raw:
            self.fail('sweep', "missing key 'scenario'")
        else:
            scenario_file, scenario_doc = self.scenario(raw['scenario'])
        goal_count = min(goal_steps(document) for _, document in
                         (scenarios.values() or [(scenario_file, scenario_doc)]))
        samples = master_seed = 0
        if mode in DRAWN_MODES:
            for key in ('samples', 'master_seed'):
                if key not in raw:
                    self.fail('sweep', f"missing key '{key}' (needed in {mode} mode)")
            samples = self.integer(raw['samples'], 'sweep.samples', 1)
            master_seed = self.integer(raw['master_seed'], 'sweep.master_seed', 0)
        else:
            for key in ('samples', 'master_seed'):
                if key in raw:
                    self.fail(f'sweep.{key}', 'is only allowed with mode: random or search')
        search = None
        if mode == 'search':
            search = self.search(raw.get('search'))
        elif 'search' in raw:
            self.fail('sweep.search', 'is only allowed with mode: search')
        axes_raw = self.mapping(axes_raw, 'sweep.axes', (), AXES)
        if not axes_raw:
            self.fail('sweep.axes', f'needs at least one axis of {", ".join(AXES)}')
        axes = {axis: self.axis(axis, axes_raw[axis], f'sweep.axes.{axis}', mode, goal_count)
                for axis in AXES if axis in axes_raw and axis != 'scenario'}
        if scenarios:
            axes = dict({'scenario': list(scenarios)}, **axes)
        self.check_combinations(axes, scenarios)
        sweep = Sweep(name=name, source=self.path, scenario_file=scenario_file, mode=mode,
                      axes=axes, samples=samples, master_seed=master_seed,
                      description=description, goal_count=goal_count,
                      scenario_document=scenario_doc, scenarios=scenarios, search=search)
        count = variant_count(sweep)
        if count > MAX_VARIANTS:
            self.fail('sweep.axes' if mode == 'grid' else 'sweep.samples',
                      f'{count} variants, more than the {MAX_VARIANTS} allowed')
        return sweep

    def search(self, value: Any) -> SearchSpec:
        """Return the checked sweep.search settings (absent: the defaults)."""
        raw = self.mapping(value if value is not None else {}, 'sweep.search', (), SEARCH_KEYS)
        spec = SearchSpec()
        objective = self.choice(raw.get('objective', spec.objective), 'sweep.search.objective',
                                OBJECTIVES)
        batch = self.integer(raw.get('batch', spec.batch), 'sweep.search.batch', 1)
        fraction = self.number(raw.get('elite_fraction', spec.elite_fraction),
                               'sweep.search.elite_fraction', minimum=0.0)
        if not 0.0 < fraction <= 1.0:
            self.fail('sweep.search.elite_fraction', f'must be in (0, 1], not {fraction!r}')
        smoothing = self.number(raw.get('smoothing', spec.smoothing),
                                'sweep.search.smoothing', minimum=0.0)
        if smoothing > 1.0:
            self.fail('sweep.search.smoothing', f'must be in [0, 1], not {smoothing!r}')
        return SearchSpec(objective, batch, float(fraction), float(smoothing))

    def scenario(self, value: Any, key: str = 'sweep.scenario') -> Tuple[Path, Dict[str, Any]]:
        """Return the scenario file (relative to the sweep, or a shipped name) and its doc."""
        if not isinstance(value, str) or not value.strip():
            self.fail(key, f'must be a scenario name or file, not {value!r}')
        candidate = Path(value).expanduser()
        if not candidate.is_absolute():
            candidate = self.path.parent / candidate
        if not candidate.is_file() and '/' not in value and not value.endswith('.yaml'):
            candidate = shipped_scenarios_folder() / f'{value}.yaml'
        if not candidate.is_file():
            self.fail(key, f'no scenario file {value!r} (looked for {candidate})')
        try:
            doc = yaml.safe_load(candidate.read_text(encoding='utf-8'))
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as error:
            self.fail(key, f'cannot read {candidate}: {error}')
        if not isinstance(doc, dict) or not isinstance(doc.get('scenario'), dict):
            self.fail(key, f'{candidate} is not a scenario file')
        return candidate.resolve(), doc

    def axis(self, axis: str, value: Any, key: str, mode: str, goal_count: int) -> Any:
        """Check one axis: a non-empty list, or (random mode) a distribution mapping."""
        if isinstance(value, dict):
            return self.distribution(axis, value, key, mode, goal_count)
        if not isinstance(value, list) or not value:
            self.fail(key, 'must be a non-empty list of values'
                      + (' or a distribution' if mode in DRAWN_MODES else ''))
        check = {
            'seed': lambda v, k: self.integer(v, k, 0),
            'world': self.world,
            'floor_friction_coefficient': lambda v, k: self.number(v, k, minimum=0.0),
            'sensor_noise_scale': lambda v, k: self.number(v, k, minimum=0.0),
            'spawn': self.pose,
            'person': self.person,
            'goals': lambda v, k: self.goal_subset(v, k, goal_count),
            'fault': self.fault,
            'fault_onset_s': lambda v, k: self.number(v, k, minimum=0.0),
        }[axis]
        return [check(item, f'{key}[{index}]') for index, item in enumerate(value)]

    def distribution(self, axis: str, value: Dict[str, Any], key: str, mode: str,
                     goal_count: int) -> Dict[str, Any]:
        """Check a distribution: range (seed), uniform (numbers) or sample (goals)."""
        kinds = {'seed': 'range', 'floor_friction_coefficient': 'uniform',
                 'sensor_noise_scale': 'uniform', 'goals': 'sample',
                 'fault_onset_s': 'uniform'}
        if axis not in kinds:
            self.fail(key, 'must be a non-empty list of values (no distribution for '
                      f'{axis})')
        kind = kinds[axis]
        if mode not in DRAWN_MODES:
            self.fail(key, f'a distribution ({kind}) needs mode: random or search; a grid '
                      'takes lists')
        self.mapping(value, key, (kind,), ())
        bounds = value[kind]
        where = f'{key}.{kind}'
        if kind == 'sample':
            count = self.integer(bounds, where, 1)
            if count > goal_count:
                self.fail(where, f'{count} goals, but the scenario has {goal_count}')
            return {'sample': count}
        if not isinstance(bounds, list) or len(bounds) != 2:
            self.fail(where, f'must be [lo, hi], not {bounds!r}')
        if kind == 'range':
            lo, hi = (self.integer(b, where, 0) for b in bounds)
        else:
            lo, hi = (self.number(b, where, minimum=0.0) for b in bounds)
        if not lo < hi:
            self.fail(where, f'must be [lo, hi] with lo < hi, not {bounds!r}')
        return {kind: [lo, hi]}

    def scenario_axis(self, value: Any, key: str) -> Dict[str, Tuple[Path, Dict[str, Any]]]:
        """Return {name: (file, document)} of the scenario axis's scenarios, in order."""
        if not isinstance(value, list) or not value:
            self.fail(key, 'must be a non-empty list of scenario names or files')
        found: Dict[str, Tuple[Path, Dict[str, Any]]] = {}
        for index, item in enumerate(value):
            where = f'{key}[{index}]'
            path, document = self.scenario(item, where)
            name = document['scenario'].get('name')
            if not isinstance(name, str) or not name:
                self.fail(where, f'{path} has no scenario name')
            if name in found:
                self.fail(where, f'scenario {name!r} is already in the axis')
            found[name] = (path, document)
        return found

    def fault(self, value: Any, key: str) -> Optional[Dict[str, Any]]:
        """Return a fault mapping as written (checked by parse_fault), or None: no fault."""
        if value is None:
            return None
        try:
            parse_fault(value, key)
        except FaultError as error:
            where, _, message = str(error).partition(': ')
            self.fail(where, message)
        return dict(value)

    def check_combinations(self, axes: Dict[str, Any],
                           scenarios: Dict[str, Tuple[Path, Dict[str, Any]]]) -> None:
        """Check what one axis needs of another: the fault onsets, one world for person."""
        if 'fault_onset_s' in axes and 'fault' not in axes:
            self.fail('sweep.axes.fault_onset_s', 'needs the fault axis')
        if 'fault_onset_s' in axes:
            for index, fault in enumerate(axes['fault']):
                if isinstance(fault, dict) and 'onset_s' in fault:
                    self.fail(f'sweep.axes.fault[{index}].onset_s', 'is given by '
                              'axes.fault_onset_s: leave it out here')
        if 'person' in axes and 'world' not in axes and len(scenarios) > 1:
            worlds = {_world_of(path, document) for path, document in scenarios.values()}
            if len(worlds) > 1:
                self.fail('sweep.axes.person', 'the scenarios of axes.scenario are in '
                          f'different worlds ({", ".join(sorted(worlds))}): give one world '
                          'with the world axis')

    def world(self, value: Any, key: str) -> str:
        """Return a world name, or a world file made absolute."""
        if not isinstance(value, str) or not value.strip():
            self.fail(key, f'must be a world name or file, not {value!r}')
        if '/' in value or value.endswith(('.yaml', '.yml')):
            path = Path(value).expanduser()
            path = path if path.is_absolute() else self.path.parent / path
            if not path.is_file():
                self.fail(key, f'no world file {value!r} (looked for {path})')
            return str(path.resolve())
        return value

    def pose(self, value: Any, key: str) -> Dict[str, float]:
        """Return {x, y, yaw} (yaw optional, 0)."""
        raw = self.mapping(value, key, ('x', 'y'), ('yaw',))
        return {'x': self.number(raw['x'], f'{key}.x'), 'y': self.number(raw['y'], f'{key}.y'),
                'yaw': self.number(raw.get('yaw', 0.0), f'{key}.yaw')}

    def person(self, value: Any, key: str) -> Dict[str, Any]:
        """Return the changes to a world moving obstacle (checked again with the world)."""
        raw = self.mapping(value, key, (), PERSON_KEYS)
        if not raw:
            self.fail(key, f'must change at least one of {", ".join(PERSON_KEYS[1:])}')
        changes = dict(raw)
        if 'speed_m_s' in raw:
            self.positive(raw['speed_m_s'], f'{key}.speed_m_s')
        if 'name' in raw and (not isinstance(raw['name'], str) or not raw['name']):
            self.fail(f'{key}.name', f'must be a moving obstacle name, not {raw["name"]!r}')
        return changes

    def goal_subset(self, value: Any, key: str, goal_count: int) -> List[int]:
        """Return a non-empty list of distinct goal indices in order."""
        if not isinstance(value, list) or not value:
            self.fail(key, f'must be a non-empty list of goal indices, not {value!r}')
        indices = [self.integer(item, f'{key}[{i}]', 0) for i, item in enumerate(value)]
        for index in indices:
            if index >= goal_count:
                self.fail(key, f'goal index {index}, but the scenario has {goal_count} '
                          'goal steps (indices from 0)')
        if indices != sorted(set(indices)):
            self.fail(key, f'must be distinct indices in increasing order, not {value!r}')
        return indices


def goal_steps(document: Dict[str, Any]) -> int:
    """Return the number of goal steps of a scenario document."""
    return sum(1 for step in document['scenario'].get('steps') or []
               if isinstance(step, dict) and 'goal' in step)


def input_files(sweep: Sweep) -> Dict[str, Path]:
    """
    Return the files the sweep's variants read: {absolute path: path}.

    The sweep file, each scenario file, the world file and map (YAML and image) each
    scenario uses, and the worlds of a world axis. A variant's verdict depends on their
    contents, not their names: a results store keeps their digests (input_digests) and
    refuses to resume when one changed.
    """
    from mecanum_bringup.scenario_loader import load_scenario
    from mecanum_map_server.map_io import find_map_file, MapError
    from robot_simulation.world import find_world, WorldError
    files: Dict[str, Path] = {}

    def add(path: Path) -> None:
        path = Path(path).resolve()
        files[str(path)] = path

    add(sweep.source)
    scenario_files = ([path for path, _ in sweep.scenarios.values()] if sweep.scenarios
                      else [sweep.scenario_file])
    for path in scenario_files:
        add(path)
        scenario = load_scenario(path)
        add(scenario.world_file)
        try:
            map_file = find_map_file(scenario.map_name)
        except MapError:
            continue
        add(map_file)
        try:
            image = yaml.safe_load(map_file.read_text(encoding='utf-8')).get('image')
        except (OSError, yaml.YAMLError, AttributeError):
            image = None
        if isinstance(image, str):
            add(map_file.parent / image)
    for value in sweep.axes.get('world', []) if isinstance(sweep.axes.get('world'), list) \
            else []:
        try:
            add(find_world(str(value)))
        except WorldError:
            pass
    return files


def input_digests(sweep: Sweep) -> Dict[str, str]:
    """Return {absolute path: SHA-256 of its bytes ('missing' if gone)} of input_files."""
    digests = {}
    for name, path in input_files(sweep).items():
        try:
            digests[name] = hashlib.sha256(path.read_bytes()).hexdigest()
        except OSError:
            digests[name] = 'missing'
    return digests


def _world_of(path: Path, document: Dict[str, Any]) -> str:
    """Return a scenario document's world: its name, or its file made absolute."""
    value = str(document['scenario'].get('world'))
    if '/' in value or value.endswith(('.yaml', '.yml')):
        return str((path.parent / Path(value).expanduser()).resolve())
    return value


def _absolute(scenario: Dict[str, Any], folder: Path) -> None:
    """Make a scenario document's world and map files absolute (relative to folder)."""
    for key in ('world', 'map'):
        value = scenario.get(key)
        if isinstance(value, str) and ('/' in value or value.endswith(('.yaml', '.yml'))) \
                and not value.startswith('package://') and not Path(value).is_absolute():
            scenario[key] = str((folder / Path(value).expanduser()).resolve())


def shipped_scenarios_folder() -> Path:
    """Return mecanum_bringup's installed scenarios folder."""
    from ament_index_python.packages import get_package_share_directory
    return Path(get_package_share_directory('mecanum_bringup')) / 'scenarios'


# --- the variants --------------------------------------------------------------------

def variant_count(sweep: Sweep) -> int:
    """Return how many variants the sweep has."""
    if sweep.mode in DRAWN_MODES:
        return sweep.samples
    return math.prod(len(values) for values in sweep.axes.values())


def variants(sweep: Sweep) -> List[Variant]:
    """
    Return the sweep's variants, in order (the same for the same file, always).

    A search's variants depend on the results: mecanum_bringup.sweep_search draws them a
    round at a time (ValueError here).
    """
    if sweep.mode == 'search':
        raise ValueError(f'{sweep.name}: a search draws its variants a round at a time '
                         '(mecanum_bringup.sweep_search.round_variants)')
    if sweep.mode == 'grid':
        names = list(sweep.axes)
        return [Variant(index, dict(zip(names, combination))) for index, combination in
                enumerate(itertools.product(*(sweep.axes[name] for name in names)))]
    return [Variant(index, {axis: draw_value(axis, spec, sweep, index)
                            for axis, spec in sweep.axes.items()})
            for index in range(sweep.samples)]


def draw_value(axis: str, spec: Any, sweep: Sweep, index: int) -> Any:
    """Draw one axis's value for variant index (its own generator: master seed, index)."""
    rng = random.Random(f'{sweep.master_seed}/{index}/{axis}')
    if isinstance(spec, list):
        return copy.deepcopy(spec[rng.randrange(len(spec))])
    if 'range' in spec:
        return rng.randrange(*spec['range'])
    if 'uniform' in spec:
        return round(rng.uniform(*spec['uniform']), 4)
    return sorted(rng.sample(range(sweep.goal_count), spec['sample']))


def variant_documents(sweep: Sweep, variant: Variant,
                      world_document: Optional[Dict[str, Any]] = None
                      ) -> Tuple[Dict[str, Any], Optional[Dict[str, Any]]]:
    """
    Return the variant's scenario document and, for the person axis, its world document.

    world_document is the (base) world file's document, needed for the person axis: the
    named moving obstacle (default 'person') gets the variant's changes; the runner writes
    the returned world document to a file and points the scenario's world at it. Raise
    SweepError when the person axis names an obstacle the world does not have.

    The scenario axis picks the scenario (its world and map files made absolute); the
    fault axis puts a fault step first, with the fault_onset_s axis's onset.
    """
    values = variant.values
    if 'scenario' in values:
        path, document = sweep.scenarios[values['scenario']]
        doc = copy.deepcopy(document)
        _absolute(doc['scenario'], path.parent)
    else:
        doc = copy.deepcopy(sweep.scenario_document)
    scenario = doc['scenario']
    scenario['name'] = variant.name(sweep.name)
    if 'seed' in values:
        scenario['seed'] = values['seed']
    if 'world' in values:
        scenario['world'] = values['world']
    if 'floor_friction_coefficient' in values:
        scenario['floor_friction_coefficient'] = values['floor_friction_coefficient']
    if 'sensor_noise_scale' in values:
        scenario['sensor_noise_scale'] = values['sensor_noise_scale']
    if 'spawn' in values:
        scenario['spawn'] = dict(values['spawn'])
        scenario['initial_pose'] = dict(values['spawn'])
    if 'goals' in values:
        keep, goal_index, steps = set(values['goals']), 0, []
        for step in scenario['steps']:
            if isinstance(step, dict) and 'goal' in step:
                if goal_index in keep:
                    steps.append(step)
                goal_index += 1
            else:
                steps.append(step)
        scenario['steps'] = steps
    if values.get('fault') is not None:
        fault = dict(values['fault'])
        if 'fault_onset_s' in values:
            fault['onset_s'] = values['fault_onset_s']
        scenario['steps'] = [{'fault': fault}] + list(scenario['steps'])
    world = None
    if 'person' in values:
        if world_document is None:
            raise SweepError(f'{sweep.source.name}: axes.person: the world document is '
                             'needed to change a moving obstacle')
        world = copy.deepcopy(world_document)
        changes = dict(values['person'])
        name = changes.pop('name', 'person')
        movers = world.get('world', {}).get('moving_obstacles') or []
        matching = [m for m in movers if isinstance(m, dict) and m.get('name') == name]
        if not matching:
            raise SweepError(f'{sweep.source.name}: axes.person: the world has no moving '
                             f'obstacle named {name!r} (it has '
                             f'{", ".join(repr(m.get("name")) for m in movers) or "none"})')
        matching[0].update(changes)
    return doc, world
