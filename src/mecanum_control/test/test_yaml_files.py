"""mecanum_control.yaml_files: documents, node lines, error messages and DocumentChecker."""

import math
import os

from mecanum_control.yaml_files import (
    DocumentChecker, join_key, key_lines, load_yaml_file, load_yaml_file_with_nodes,
    parent_key)
import pytest


class FileError(ValueError):
    """The caller's error type."""


def test_a_document_and_its_key_lines(tmp_path):
    path = tmp_path / 'a.yaml'
    path.write_text('sweep:\n  name: x\n  samples: 3\n')
    assert load_yaml_file(path, 'sweep file', FileError) == {'sweep': {'name': 'x', 'samples': 3}}
    doc, node = load_yaml_file_with_nodes(path, 'sweep file', FileError)
    assert doc == {'sweep': {'name': 'x', 'samples': 3}}
    inner = node.value[0][1]
    assert [(key.value, key.start_mark.line + 1) for key, _ in inner.value] == [
        ('name', 2), ('samples', 3)]


def test_an_empty_file_is_none(tmp_path):
    path = tmp_path / 'empty.yaml'
    path.write_text('# nothing\n')
    assert load_yaml_file(path, 'world file', FileError) is None
    assert load_yaml_file_with_nodes(path, 'world file', FileError) == (None, None)


@pytest.mark.parametrize('with_nodes', [False, True])
def test_errors_name_the_file_and_the_line(tmp_path, with_nodes):
    load = load_yaml_file_with_nodes if with_nodes else load_yaml_file
    with pytest.raises(FileError, match=f'^{tmp_path}/missing.yaml: no such scenario file$'):
        load(tmp_path / 'missing.yaml', 'scenario file', FileError)
    with pytest.raises(FileError, match=r'cannot read scenario file: .*Is a directory'):
        load(tmp_path, 'scenario file', FileError)
    binary = tmp_path / 'binary.yaml'
    binary.write_bytes(b'\xff\xfe\x00')
    with pytest.raises(FileError, match=r'binary.yaml: cannot read scenario file: .*utf-8'):
        load(binary, 'scenario file', FileError)
    bad = tmp_path / 'bad.yaml'
    bad.write_text('a: 1\nb: [2,\nc: 3\n')
    expected = r'^bad.yaml: YAML syntax error at line 4, column 1: did not find expected'
    with pytest.raises(FileError, match=expected):
        load(bad, 'scenario file', FileError)
    two = tmp_path / 'two.yaml'
    two.write_text('a: 1\n---\nb: 2\n')
    with pytest.raises(FileError, match=r'^two.yaml: YAML syntax error at line 2'):
        load(two, 'scenario file', FileError)


@pytest.mark.skipif(os.geteuid() == 0, reason='root reads a file without read permission')
def test_an_unreadable_file(tmp_path):
    path = tmp_path / 'locked.yaml'
    path.write_text('a: 1\n')
    path.chmod(0)
    with pytest.raises(FileError, match='cannot read world file: .*Permission denied'):
        load_yaml_file(path, 'world file', FileError)


# --- key paths and their lines -------------------------------------------------------


def test_key_paths_join_and_split():
    assert join_key('', 'sweep') == 'sweep'
    assert join_key('sweep.axes', 'seed') == 'sweep.axes.seed'
    assert join_key('steps[0]', 3) == 'steps[0].3'
    assert parent_key('sweep.axes.seed[1]') == 'sweep.axes.seed'
    assert parent_key('sweep.axes.seed') == 'sweep.axes'
    assert parent_key('steps[2]') == 'steps'
    assert parent_key('sweep') == ''
    assert parent_key("walls[0] 'north'") == ''   # not a key path: no parent


def test_key_lines_of_a_file(tmp_path):
    path = tmp_path / 'a.yaml'
    path.write_text('sweep:\n  name: x\n  axes:\n    seed: [1,\n      2]\n'
                    '    spawn:\n    - {x: 1, y: 2}\n')
    _, node = load_yaml_file_with_nodes(path, 'sweep file', FileError)
    assert key_lines(node) == {
        '': 1, 'sweep': 1, 'sweep.name': 2, 'sweep.axes': 3, 'sweep.axes.seed': 4,
        'sweep.axes.seed[0]': 4, 'sweep.axes.seed[1]': 5, 'sweep.axes.spawn': 6,
        'sweep.axes.spawn[0]': 7, 'sweep.axes.spawn[0].x': 7, 'sweep.axes.spawn[0].y': 7}
    assert key_lines(None) == {}


# --- DocumentChecker -----------------------------------------------------------------


def checker(**options) -> DocumentChecker:
    return DocumentChecker(FileError, 'doc.yaml', **options)


def message(check, *args, **kwargs) -> str:
    """Return the message of the FileError that check(*args, **kwargs) raises."""
    with pytest.raises(FileError) as caught:
        check(*args, **kwargs)
    return str(caught.value)


def test_fail_names_the_file_the_key_and_the_nearest_line():
    assert message(checker().fail, 'steps[0].goal', 'bad') == 'doc.yaml: steps[0].goal: bad'
    assert message(checker().fail, '', 'empty') == 'doc.yaml: empty'
    lines = {'': 1, 'sweep': 1, 'sweep.axes': 5, 'sweep.axes.seed': 6}
    lined = checker(lines=lines)
    assert message(lined.fail, 'sweep.axes.seed', 'x') == 'doc.yaml:6: sweep.axes.seed: x'
    # A key not in the file (a missing or computed one): its nearest parent's line.
    assert message(lined.fail, 'sweep.axes.goals[2].x', 'x') == (
        'doc.yaml:5: sweep.axes.goals[2].x: x')
    assert message(lined.fail, 'other', 'x') == 'doc.yaml:1: other: x'
    assert lined.line('sweep.axes.seed') == 6 and checker().line('sweep') is None


def test_a_document_is_one_top_level_mapping():
    check = checker()
    assert check.document({'world': {'name': 'x'}}, 'world') == {'name': 'x'}
    for doc in (None, [1, 2], {'sweep': {}}):
        assert message(check.document, doc, 'world') == (
            'doc.yaml: expected a top-level "world:" mapping')
    assert message(check.document, {'world': {}, 'extra': 1}, 'world') == (
        'doc.yaml: extra: unknown top-level key (only "world:" is allowed)')


def test_mapping_allows_the_required_and_optional_keys_only():
    check = checker(top_key='scenario')
    value = {'x': 1, 'y': 2}
    assert check.mapping(value, 'spawn', ('x', 'y'), ('yaw',)) is value
    assert check.mapping({}, 'criteria') == {}
    assert message(check.mapping, [1], 'spawn', ('x', 'y'), ('yaw',)) == (
        'doc.yaml: spawn: must be a mapping with keys x, y, yaw, not [1]')
    assert message(check.mapping, {'x': 1, 'y': 2, 'z': 3}, 'spawn', ('x', 'y'), ('yaw',)) == (
        'doc.yaml: spawn.z: unknown key (allowed: x, y, yaw)')
    assert message(check.mapping, {'x': 1}, 'spawn', ('x', 'y')) == (
        "doc.yaml: spawn: missing key 'y'")
    # At the top, unknown keys are named alone and a missing key's place is top_key.
    assert message(check.mapping, {'colour': 1}, '', (), ('name',)) == (
        'doc.yaml: colour: unknown key (allowed: name)')
    assert message(check.mapping, {}, '', ('name',)) == "doc.yaml: scenario: missing key 'name'"
    assert message(checker().mapping, {}, '', ('name',)) == "doc.yaml: missing key 'name'"


def test_numbers_are_finite_and_within_their_bounds():
    check = checker()
    assert check.number(3, 'x') == 3.0 and isinstance(check.number(3, 'x'), float)
    assert check.number(0, 'x', minimum=0.0) == 0.0
    assert check.positive(0.5, 'x') == 0.5
    assert check.optional_positive(None, 'x') is None
    assert check.optional_positive(2, 'x') == 2.0
    assert check.integer(4, 'seed') == 4 and check.integer(1, 'n', 1) == 1
    assert message(check.number, 'north', 'yaw') == "doc.yaml: yaw: must be a number, not 'north'"
    assert message(check.number, True, 'yaw') == 'doc.yaml: yaw: must be a number, not True'
    assert message(check.number, math.nan, 'x') == 'doc.yaml: x: must be a finite number, not nan'
    assert message(check.number, -1, 'scale', minimum=0.0) == (
        'doc.yaml: scale: must be >= 0, not -1')
    assert message(check.positive, 0, 'timeout_s') == 'doc.yaml: timeout_s: must be > 0, not 0'
    assert message(check.optional_positive, -1.5, 't') == 'doc.yaml: t: must be > 0, not -1.5'
    assert message(check.integer, 1.5, 'seed') == (
        'doc.yaml: seed: must be an integer >= 0, not 1.5')
    assert message(check.integer, False, 'seed') == (
        'doc.yaml: seed: must be an integer >= 0, not False')
    assert message(check.integer, 0, 'samples', 1) == (
        'doc.yaml: samples: must be an integer >= 1, not 0')


def test_a_list_of_numbers_has_its_count():
    check = checker()
    assert check.numbers([1, 2.5], 'center', 2) == (1.0, 2.5)
    assert check.numbers((0, 0, 4, 3), 'bounds_m', 4) == (0.0, 0.0, 4.0, 3.0)
    assert message(check.numbers, [1, 2, 3], 'center', 2) == (
        'doc.yaml: center: must be 2 numbers, not [1, 2, 3]')
    assert message(check.numbers, 'here', 'center', 2) == (
        "doc.yaml: center: must be 2 numbers, not 'here'")
    assert message(check.numbers, [1, 'a'], 'center', 2) == (
        "doc.yaml: center[1]: must be a number, not 'a'")


def test_booleans_choices_texts_and_identifiers():
    check = checker()
    assert check.boolean(False, 'loop') is False
    assert check.choice('fail', 'expect', ('pass', 'fail')) == 'fail'
    assert check.text(' a ', 'name') == ' a '
    assert check.identifier('tour_2-b', 'name') == 'tour_2-b'
    assert message(check.boolean, 1, 'loop') == 'doc.yaml: loop: must be true or false, not 1'
    assert message(check.choice, 'maybe', 'expect', ('pass', 'fail')) == (
        "doc.yaml: expect: must be one of pass, fail, not 'maybe'")
    assert message(check.choice, ['pass'], 'expect', ('pass', 'fail')) == (
        "doc.yaml: expect: must be one of pass, fail, not ['pass']")
    assert message(check.text, '  ', 'name') == (
        "doc.yaml: name: must be a non-empty string, not '  '")
    assert message(check.text, 5, 'name') == 'doc.yaml: name: must be a non-empty string, not 5'
    assert message(check.identifier, 'my tour', 'name') == (
        "doc.yaml: name: must be letters, digits, _ and - only, not 'my tour'")
    assert message(check.identifier, None, 'name') == (
        'doc.yaml: name: must be letters, digits, _ and - only, not None')


def test_what_names_the_value_inside_an_entry():
    check = checker()
    where = "walls[0] 'north'"
    assert check.positive(0.1, where, 'thickness_m') == 0.1
    assert message(check.positive, 0, where, 'thickness_m') == (
        "doc.yaml: walls[0] 'north': thickness_m must be > 0, not 0")
    assert message(check.number, 'one', 'robot_start', 'x_m') == (
        "doc.yaml: robot_start: x_m must be a number, not 'one'")
    assert message(check.number, math.inf, 'walls[0]', 'thickness_m') == (
        'doc.yaml: walls[0]: thickness_m must be a finite number, not inf')
    assert message(check.numbers, [0, 0, 4], 'bounds_m', 4, '[xmin, ymin, xmax, ymax]') == (
        'doc.yaml: bounds_m: [xmin, ymin, xmax, ymax] must be 4 numbers, not [0, 0, 4]')
    # With what, a bad item is reported at the entry, under the same name.
    assert message(check.numbers, [0, math.nan], 'walls[0]', 2, 'from') == (
        'doc.yaml: walls[0]: from must be a finite number, not nan')
    assert message(check.boolean, 'yes', where, 'loop') == (
        "doc.yaml: walls[0] 'north': loop must be true or false, not 'yes'")
    assert message(check.text, '', 'walls[0]', 'name') == (
        "doc.yaml: walls[0]: name must be a non-empty string, not ''")


def test_a_subclass_adds_its_own_checks_with_its_error():
    class PoseError(ValueError):
        pass

    class PoseChecker(DocumentChecker):

        def pose(self, value, key):
            raw = self.mapping(value, key, ('x', 'y'), ('yaw',))
            return (self.number(raw['x'], join_key(key, 'x')),
                    self.number(raw['y'], join_key(key, 'y')),
                    self.number(raw.get('yaw', 0.0), join_key(key, 'yaw')))

    check = PoseChecker(PoseError, 'poses.yaml', {'start': 2, 'start.yaw': 3})
    assert check.pose({'x': 1, 'y': 2}, 'start') == (1.0, 2.0, 0.0)
    with pytest.raises(PoseError, match=r"^poses.yaml:3: start.yaw: must be a number, not 'n'$"):
        check.pose({'x': 1, 'y': 2, 'yaw': 'n'}, 'start')
    with pytest.raises(PoseError, match=r"^poses.yaml:2: start: missing key 'y'$"):
        check.pose({'x': 1}, 'start')
