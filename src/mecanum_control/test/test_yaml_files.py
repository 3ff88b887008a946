"""mecanum_control.yaml_files on real files: documents, node lines and error messages."""

import os

from mecanum_control.yaml_files import load_yaml_file, load_yaml_file_with_nodes
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
