"""
The file format pages (docs/scenario_format.md, docs/sweep_format.md) stay true to the code.

Every key, kind, axis, distribution, option and store column the code defines must
appear on its page as code (`` `key` ``), and every YAML example must parse; a complete
example (a block whose document is ``scenario:`` or ``sweep:``) must also load as a
scenario or sweep file. A partial snippet starts with the line ``# (part of a file)``.
The key lists come from the code itself: its constants, or the 'allowed: ...' list a
loader gives for an unknown key (so a key added to a loader fails here until documented).
"""

from dataclasses import replace
from pathlib import Path
import re
import sqlite3

from mecanum_bringup import scenario_runner, sweep_runner
from mecanum_bringup.scenario_judge import judge
from mecanum_bringup.scenario_loader import (
    command_sources, CRITERIA_KEYS, load_scenario, SCENARIO_KEYS, ScenarioError)
from mecanum_bringup.scenario_model import (
    COMMAND_EXPECTATIONS, Criteria, GOAL_EXPECTATIONS, NAVIGATE_TO_POSE_ERRORS, RunRecord,
    STEP_KINDS, VERDICTS)
from mecanum_bringup.sweep import (
    AXES, load_sweep, MAX_VARIANTS, MODES, PERSON_KEYS, SWEEP_KEYS, SweepError, variants)
from mecanum_bringup.sweep_report import VARIANT_SCENARIO
from mecanum_bringup.sweep_store import ResultsStore
import pytest
from robot_simulation.faults import FAULT_KINDS
import yaml

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / 'docs'
SCENARIO_PAGE = DOCS / 'scenario_format.md'
SWEEP_PAGE = DOCS / 'sweep_format.md'
README = REPO / 'src' / 'mecanum_bringup' / 'README.md'
SCENARIOS = REPO / 'src' / 'mecanum_bringup' / 'scenarios'
#: The first line of a YAML block that is only part of a file.
PART = '# (part of a file)'
_YAML_BLOCK = re.compile(r'^```yaml\n(.*?)^```', re.MULTILINE | re.DOTALL)
_ALLOWED = re.compile(r'allowed: ([^)]*)\)')

#: A step of each kind with an unknown key, where the loader names that kind's keys.
STEP_PROBES = {
    'goal': {'goal': {'_probe': 1}},
    'waypoints': {'waypoints': {'_probe': 1}},
    'command': {'command': 'stop', '_probe': 1},
    'cmd_vel': {'cmd_vel': {'_probe': 1}},
    'wait': {'wait': {'_probe': 1}},
    'freeze': {'freeze': {'_probe': 1}},
    'fault': {'fault': {'kind': 'estop', '_probe': 1}},
}


def page(path: Path) -> str:
    """Return a page's text."""
    return path.read_text(encoding='utf-8')


def code_spans(text: str) -> set:
    """Return every inline code span's text, and its first word (`--out DIR`: --out)."""
    spans = set(re.findall(r'`([^`\n]+)`', text))
    return spans | {span.split()[0] for span in spans if span.split()}


def missing(names, text: str) -> list:
    """Return the names that are not a code span of text."""
    spans = code_spans(text)
    return [name for name in names if name not in spans]


def headings(text: str) -> list:
    """Return (offset, level, title) of each Markdown heading outside code blocks."""
    found, offset, fenced = [], 0, False
    for line in text.splitlines(keepends=True):
        if line.startswith('```'):
            fenced = not fenced
        match = None if fenced else re.match(r'(#+) (.+)$', line.rstrip('\n'))
        if match:
            found.append((offset, len(match.group(1)), match.group(2).strip()))
        offset += len(line)
    return found


def section(text: str, heading: str) -> str:
    """Return the part of text from the heading to the next heading of its level or above."""
    marks, title = heading.split(' ', 1)
    found = headings(text)
    index = next(i for i, (_, level, name) in enumerate(found)
                 if level == len(marks) and name == title)
    end = next((offset for offset, level, _ in found[index + 1:] if level <= len(marks)),
               len(text))
    return text[found[index][0]:end]


def allowed_keys(message: str) -> list:
    """Return the keys of a loader's 'unknown key (allowed: a, b, c)' message."""
    match = _ALLOWED.search(message)
    assert match, f'no list of allowed keys in {message!r}'
    return [key.strip() for key in match.group(1).split(',')]


def scenario_error(tmp_path: Path, **changes) -> str:
    """Return the ScenarioError message of a minimal scenario with changes."""
    document = {'name': 'probe', 'world': 'apartment', 'steps': [{'wait': {'duration_s': 1}}]}
    document.update(changes)
    path = tmp_path / 'probe.yaml'
    path.write_text(yaml.safe_dump({'scenario': document}), encoding='utf-8')
    with pytest.raises(ScenarioError) as error:
        load_scenario(path)
    return str(error.value)


def help_options(main, capsys) -> list:
    """Return the --options of a command line's --help (without --help)."""
    with pytest.raises(SystemExit) as done:
        main(['--help'])
    assert done.value.code == 0
    options = re.findall(r'(?<![\w-])(--[a-z][a-z-]*)', capsys.readouterr().out)
    return sorted(set(options) - {'--help'})


def yaml_examples():
    """Return (id, page, block text) for every YAML block of the two pages."""
    found = []
    for path in (SCENARIO_PAGE, SWEEP_PAGE):
        for index, match in enumerate(_YAML_BLOCK.finditer(page(path))):
            found.append((f'{path.stem}[{index}]', path, match.group(1)))
    return found


EXAMPLES = yaml_examples()


# --- the scenario page -------------------------------------------------------------------

def test_the_scenario_page_names_every_top_level_and_criteria_key():
    text = page(SCENARIO_PAGE)
    assert missing(SCENARIO_KEYS, text) == []
    assert missing(CRITERIA_KEYS, text) == []
    assert missing(['scenario:'], text) == []


def test_the_scenario_page_names_every_step_kind_and_its_keys(tmp_path):
    text = page(SCENARIO_PAGE)
    assert set(STEP_PROBES) == set(STEP_KINDS), 'a new step kind needs a probe here'
    assert missing(STEP_KINDS, text) == []
    for kind in STEP_KINDS:
        message = scenario_error(tmp_path, steps=[STEP_PROBES[kind]])
        keys = allowed_keys(message)
        assert keys, kind
        # Each kind's keys are in its own section (a fault's in the fault section).
        part = section(text, next(f'### {title}' for _, level, title in headings(text)
                                  if level == 3 and title.startswith(f'`{kind}`')))
        assert missing(keys, part) == [], f'{kind}: {message}'


def test_the_scenario_page_names_every_value_the_loader_takes(tmp_path):
    text = page(SCENARIO_PAGE)
    assert missing(GOAL_EXPECTATIONS, text) == []
    assert missing(COMMAND_EXPECTATIONS, text) == []
    assert missing(VERDICTS, text) == []
    assert missing(NAVIGATE_TO_POSE_ERRORS, text) == []
    assert missing(command_sources(), text) == []
    moving = allowed_keys(scenario_error(tmp_path, moving_obstacles=[{'_probe': 1}]))
    assert missing(moving, section(text, '## Moving obstacles')) == []


def test_the_scenario_page_names_every_fault_kind_and_parameter():
    text = section(page(SCENARIO_PAGE), '### `fault`: one fault of the fault vocabulary')
    assert missing(FAULT_KINDS, text) == []
    for kind in FAULT_KINDS.values():
        assert missing(kind.params, text) == [], kind.name
    assert missing(['kind', 'onset_s', 'duration_s'], text) == []


def test_the_scenario_page_names_every_line_of_a_verdict():
    scenario = load_scenario(SCENARIOS / 'slippery_floor.yaml')
    # Every criterion on: the judge gives each its line, whatever the (empty) record.
    every = replace(scenario, criteria=Criteria(max_duration_s=1.0,
                                                max_localization_error_m=1.0,
                                                fault_reactions=True))
    names = [line.name for line in judge(every, RunRecord()).criteria]
    others = [name for name in names if not name.startswith('step ')]
    assert set(others) == {'completed', 'max_duration_s', 'no_collision', 'stay_in_zone',
                           'max_localization_error_m', 'fault_reaction'}
    assert missing(others + ['step 1'], page(SCENARIO_PAGE)) == []


def test_the_scenario_page_names_every_run_scenarios_option(capsys):
    options = help_options(scenario_runner.main, capsys)
    assert '--jobs' in options
    assert missing(options, section(page(SCENARIO_PAGE), '## Running scenarios')) == []
    assert 'make scenarios' in page(SCENARIO_PAGE)


# --- the sweep page -----------------------------------------------------------------------

def sweep_error(tmp_path: Path, **changes) -> str:
    """Return the SweepError message of a minimal random sweep with changes."""
    document = {'name': 'probe', 'scenario': 'apartment_tour', 'mode': 'random',
                'samples': 1, 'master_seed': 0, 'axes': {'seed': [0]}}
    document.update(changes)
    document = {key: value for key, value in document.items() if value is not None}
    path = tmp_path / 'probe_sweep.yaml'
    path.write_text(yaml.safe_dump({'sweep': document}), encoding='utf-8')
    with pytest.raises(SweepError) as error:
        load_sweep(path)
    return str(error.value)


def distributions(tmp_path: Path) -> dict:
    """Return {axis: its distribution's name, or None}, as the sweep loader says."""
    found = {}
    for axis in AXES:
        message = sweep_error(tmp_path, axes={axis: {'_probe': [0, 1]}},
                              scenario=None if axis == 'scenario' else 'apartment_tour')
        found[axis] = allowed_keys(message)[0] if 'allowed:' in message else None
    return found


def test_the_sweep_page_names_every_key_mode_and_axis():
    text = page(SWEEP_PAGE)
    assert missing(SWEEP_KEYS, text) == []
    assert missing(MODES, text) == []
    assert missing(AXES, text) == []
    assert missing(PERSON_KEYS, section(text, '### `person`')) == []
    assert missing(['sweep:', 'MAX_VARIANTS'], text) == []
    assert f'at most {MAX_VARIANTS} variants' in text


def test_the_axes_table_lists_the_axes_in_grid_order_with_their_distributions(tmp_path):
    table = section(page(SWEEP_PAGE), '## Axes')
    rows = re.findall(r'^\| `([a-z_]+)` \|(.*)$', table, re.MULTILINE)
    assert [axis for axis, _ in rows] == list(AXES)
    kinds = distributions(tmp_path)
    assert kinds['seed'] == 'range' and kinds['goals'] == 'sample'
    for axis, cells in rows:
        distribution = cells.split('|')[1].strip()
        assert distribution == (f'`{kinds[axis]}`' if kinds[axis] else 'none'), axis
    assert missing({kind for kind in kinds.values() if kind}, section(
        page(SWEEP_PAGE), '## Modes')) == []


def test_the_sweep_page_names_every_store_column_and_file(tmp_path):
    text = page(SWEEP_PAGE)
    with ResultsStore(tmp_path / 'results.sqlite', 'probe', 'fingerprint', {}):
        pass
    db = sqlite3.connect(str(tmp_path / 'results.sqlite'))
    try:
        columns = [row[1] for row in db.execute('PRAGMA table_info(variants)')]
        meta = [key for (key,) in db.execute('SELECT key FROM sweep')]
    finally:
        db.close()
    assert 'min_zone_clearance_m' in columns and 'inputs' in meta
    assert missing(columns, section(text, '## Results folder')) == []
    assert missing(meta, section(text, '## Results folder')) == []
    assert missing(['results.sqlite', 'report.html', 'rates.png', 'junit.xml',
                    VARIANT_SCENARIO, 'variant_world.yaml'], text) == []


def test_the_sweep_page_names_every_run_sweep_option(capsys):
    options = help_options(sweep_runner.main, capsys)
    assert {'--jobs', '--ray', '--out'} <= set(options)
    assert missing(options, section(page(SWEEP_PAGE), '## Running a sweep')) == []
    assert help_options(sweep_runner.compare_main, capsys) == []
    assert missing(['compare_sweeps'], page(SWEEP_PAGE)) == []


# --- links -------------------------------------------------------------------------------

def anchors(text: str) -> set:
    """Return the GitHub anchors of a page's headings."""
    return {re.sub(r'[^\w\- ]', '', title.lower()).replace(' ', '-')
            for _, _, title in headings(text)}


@pytest.mark.parametrize('path', [SCENARIO_PAGE, SWEEP_PAGE])
def test_the_pages_link_each_other_and_the_failure_modes(path):
    text = page(path)
    other = SWEEP_PAGE if path == SCENARIO_PAGE else SCENARIO_PAGE
    assert f']({other.name}' in text
    assert '](failure_modes.md' in text
    for target, anchor in re.findall(r'\]\(([\w.]*\.md|)#([^)]+)\)', text):
        linked = page(DOCS / target) if target else text
        assert anchor in anchors(linked), f'{path.name}: no heading for {target}#{anchor}'


def test_the_readme_points_to_both_pages():
    text = page(README)
    assert 'docs/scenario_format.md' in text and 'docs/sweep_format.md' in text


# --- the examples ---------------------------------------------------------------------------

def test_both_pages_have_complete_examples():
    kinds = [next(iter(yaml.safe_load(text))) for _, _, text in EXAMPLES
             if not text.startswith(PART)]
    assert kinds.count('scenario') >= 4 and kinds.count('sweep') >= 2


@pytest.mark.parametrize('name, path, text', EXAMPLES, ids=[e[0] for e in EXAMPLES])
def test_every_yaml_example_parses_and_complete_ones_load(name, path, text, tmp_path):
    document = yaml.safe_load(text)
    if text.startswith(PART):
        assert document is not None
        return
    assert isinstance(document, dict) and len(document) == 1, \
        f'{name}: a complete example is one scenario: or sweep: (else mark it {PART!r})'
    kind = next(iter(document))
    assert kind in ('scenario', 'sweep'), name
    if kind == 'scenario':
        world = str(document['scenario'].get('world'))
        folder = tmp_path / 'scenarios'
        folder.mkdir()
        file = folder / f'{document["scenario"]["name"]}.yaml'
        file.write_text(text, encoding='utf-8')
        if '/' not in world and not world.endswith(('.yaml', '.yml')):   # a shipped world
            assert load_scenario(file).name == document['scenario']['name']
        return
    # A sweep: beside a link to the shipped scenarios, as in src/mecanum_bringup/sweeps.
    (tmp_path / 'scenarios').symlink_to(SCENARIOS)
    (tmp_path / 'sweeps').mkdir()
    file = tmp_path / 'sweeps' / f'{document["sweep"]["name"]}.yaml'
    file.write_text(text, encoding='utf-8')
    sweep = load_sweep(file)
    if sweep.mode == 'search':   # its first round: the later ones depend on results
        from mecanum_bringup.sweep_search import round_variants
        made = round_variants(sweep, 0, [])
        assert len(made) == min(sweep.search.batch, sweep.samples)
    else:
        made = variants(sweep)
    if sweep.mode == 'random':
        assert len(made) == sweep.samples
    assert made and all(set(v.values) == set(sweep.axes) for v in made)
