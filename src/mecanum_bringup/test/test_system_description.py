"""Tests of the launch YAML reader, on real files in a temporary folder."""

import os
from pathlib import Path
import re
import sys
import textwrap

from mecanum_bringup.system_description import (
    load_system, parse_launch_arguments, SystemDescriptionError, yaml_scalar)
import pytest
import yaml


@pytest.fixture
def packages(tmp_path):
    """Two package share folders, found through an explicit lookup table."""
    shares = {name: tmp_path / 'share' / name for name in ('pkg_a', 'pkg_b')}
    for share in shares.values():
        (share / 'launch').mkdir(parents=True)
        (share / 'config').mkdir()

    def find(name):
        if name not in shares:
            raise LookupError(f'package {name!r} not found')
        return str(shares[name])
    return shares, find


def write(path: Path, text: str) -> Path:
    path.write_text(textwrap.dedent(text))
    return path


def test_node_command_line_matches_launch_ros(packages):
    shares, find = packages
    params = write(shares['pkg_a'] / 'config' / 'a.yaml', 'node_a:\n  ros__parameters: {k: 1}\n')
    launch = write(shares['pkg_a'] / 'launch' / 'a.launch.yaml', """
        launch:
        - arg: {name: use_sim_time, default: 'false'}
        - node:
            pkg: pkg_a
            exec: exe_a
            name: node_a
            namespace: robot1
            param:
            - from: $(find-pkg-share pkg_a)/config/a.yaml
            - {name: use_sim_time, value: $(var use_sim_time)}
            - {name: speeds, value: [1.5, 2.0]}
            - {name: label, value: 'two words'}
            remap: [{from: cmd_vel, to: /robot1/cmd_vel_safe}]
            respawn: 'True'
            respawn_delay: 2.5
            launch-prefix: xterm -title 'node a' -e
        """)
    system = load_system(launch, {'use_sim_time': 'true'}, find, environ={})
    (node,) = system.nodes
    assert node.ros_args() == [
        '--ros-args', '-r', '__node:=node_a', '-r', '__ns:=/robot1',
        '--params-file', str(params), '-p', 'use_sim_time:=true', '-p', 'speeds:=[1.5, 2.0]',
        '-p', 'label:=two words', '-r', 'cmd_vel:=/robot1/cmd_vel_safe']
    assert node.respawn and node.respawn_delay_s == 2.5 and not node.shutdown_on_exit
    assert node.launch_prefix == ['xterm', '-title', 'node a', '-e']
    assert system.arguments == {'use_sim_time': 'true'}


def test_parameter_values_take_the_types_ros2_launch_gives_them(packages, tmp_path):
    """
    Values with a substitution are read as YAML, quoted text without one stays text.

    The expected types are those the real launch_ros 0.26.6 gave the same entries
    (evaluate_parameters on this file's node, 2026-11-26): 'true' stays the string
    'true', on which a node declaring use_sim_time a bool dies.
    """
    _, find = packages
    path = write(tmp_path / 'types.launch.yaml', """
        launch:
        - arg: {name: x, default: 'true'}
        - node:
            pkg: pkg_a
            exec: talker
            param:
            - {name: a, value: 'true'}
            - {name: b, value: $(var x)}
            - {name: c, value: true}
            - {name: d, value: '1.5'}
            - {name: e, value: 'x$(var x)'}
            - {name: f, value: '$(var x)'}
        """)
    (node,) = load_system(path, {}, find, environ={}).nodes
    assert node.parameters == [('a', 'true'), ('b', True), ('c', True), ('d', '1.5'),
                               ('e', 'xtrue'), ('f', True)]


def test_include_passes_arguments_and_scopes_set_env(packages):
    shares, find = packages
    write(shares['pkg_b'] / 'launch' / 'inner.launch.yaml', """
        launch:
        - arg: {name: robot, default: 'default_robot'}
        - arg: {name: world, default: 'lab'}
        - set_env: {name: INNER_ONLY, value: '1'}
        - node: {pkg: pkg_b, exec: sim, name: $(var robot)_sim, args: '--world $(var world)'}
        """)
    outer = write(shares['pkg_a'] / 'launch' / 'outer.launch.yaml', """
        launch:
        - arg: {name: robot_name, default: 'r2'}
        - set_env: {name: RANGE, value: $(env RANGE LOCALHOST)}
        - include:
            file: $(find-pkg-share pkg_b)/launch/inner.launch.py
            arg: [{name: robot, value: $(var robot_name)}]
        - node: {pkg: pkg_a, exec: ctl, on_exit: shutdown}
        """)
    # world is declared only by the included file, yet settable from the command
    # line, as in ros2 launch.
    system = load_system(outer, {'world': 'apartment'}, find, environ={})
    sim, ctl = system.nodes
    assert sim.name == 'r2_sim' and sim.arguments == ['--world', 'apartment']
    assert sim.env == {'RANGE': 'LOCALHOST', 'INNER_ONLY': '1'}
    assert ctl.env == {'RANGE': 'LOCALHOST'}           # the include's set_env stayed inside
    assert ctl.shutdown_on_exit and ctl.label == 'ctl'
    assert system.arguments == {'robot_name': 'r2', 'robot': 'r2', 'world': 'apartment'}


@pytest.mark.parametrize('body, message', [
    ('launch: {node: {}}', 'holding a list'),
    ('launch:\n- node: {pkg: pkg_a}', 'missing "exec"'),
    ('launch:\n- group: {}', 'unsupported entry "group"'),
    ('launch:\n- node: {pkg: pkg_a, exec: x, colour: red}', "unknown key(s) ['colour']"),
    ('launch:\n- node: {pkg: pkg_a, exec: x, name: $(var nope)}', 'not a declared'),
    ('launch:\n- node: {pkg: pkg_a, exec: x, name: $(find-pkg-share pkg_z)}', 'pkg_z'),
    ('launch:\n- node: {pkg: pkg_a, exec: x, param: [{from: /no/such.yaml}]}',
     'does not exist'),
    ('launch:\n- node: {pkg: pkg_a, exec: x, respawn: maybe}', 'expected true or false'),
    ('launch:\n- node: {pkg: pkg_a, exec: x, respawn_delay: soon}', 'must be a number'),
    ('launch:\n- node: {pkg: pkg_a, exec: x, respawn_delay: -1.0}', 'must be >= 0'),
    # What ROS 2 launch's YAML frontend rejects (it checks types and never coerces).
    ("launch:\n- node: {pkg: pkg_a, exec: x, respawn_delay: '1.0'}", 'decimal point, unquoted'),
    ('launch:\n- node: {pkg: pkg_a, exec: x, respawn_delay: 1}', 'decimal point, unquoted'),
    ('launch:\n- node: {pkg: pkg_a, exec: x, respawn: true}', 'respawn must be text'),
    ('launch:\n- node: {pkg: pkg_a, exec: x, name: 5}', 'name must be text'),
    ('launch:\n- node: {pkg: pkg_a, exec: x, on_exit: restart}', 'only "shutdown"'),
    ('launch:\n- arg: {name: a}\n- node: {pkg: pkg_a, exec: x}', 'has no default'),
    ('launch:\n- arg: {name: a, default: x, choices: [y, z]}\n- node: {pkg: p, exec: x}',
     'not one of'),
    ('launch:\n- node: {pkg: pkg_a, exec: x, name: $(unknown thing)}', 'unsupported'),
    ('launch:\n- node: {pkg: pkg_a, exec: x, name: $(anon)}', 'unsupported'),
    ('launch:\n- node: {pkg: pkg_a, exec: x, name: $(anon a b)}', 'unsupported'),
    ('launch:\n- node: {pkg: pkg_a, exec: x, name: $(env NOT_SET_ANYWHERE)}', 'not set'),
    ('launch: [', 'not valid YAML'),
    ('launch: []', 'has no nodes'),
    ('launch:\n- include: {file: /no/such.launch.yaml}', 'does not exist'),
])
def test_bad_files_get_clear_errors(packages, tmp_path, body, message):
    _, find = packages
    path = write(tmp_path / 'bad.launch.yaml', body + '\n')
    with pytest.raises(SystemDescriptionError) as error:
        load_system(path, {}, find, environ={})
    assert message in str(error.value)
    assert 'bad.launch.yaml' in str(error.value) or '/no/such' in str(error.value)


def test_unknown_command_line_argument_is_an_error(packages, tmp_path):
    _, find = packages
    path = write(tmp_path / 'x.launch.yaml', """
        launch:
        - arg: {name: a, default: '1'}
        - node: {pkg: pkg_a, exec: x}
        """)
    with pytest.raises(SystemDescriptionError, match='unknown launch argument'):
        load_system(path, {'b': '2'}, find, environ={})


def test_bad_parameter_file_is_reported(packages, tmp_path):
    _, find = packages
    write(tmp_path / 'p.yaml', 'just a string\n')
    path = write(tmp_path / 'x.launch.yaml', """
        launch:
        - node: {pkg: pkg_a, exec: x, param: [{from: $(dirname)/p.yaml}]}
        """)
    with pytest.raises(SystemDescriptionError, match='must map node names'):
        load_system(path, {}, find, environ={})


def test_recursive_include_is_reported(tmp_path):
    path = write(tmp_path / 'loop.launch.yaml', """
        launch:
        - include: {file: $(dirname)/loop.launch.yaml}
        """)
    with pytest.raises(SystemDescriptionError, match='recursively'):
        load_system(path, {}, lambda name: '', environ={})


def test_same_file_included_twice_side_by_side(tmp_path):
    """Two robots from one file is not recursion: both are loaded."""
    write(tmp_path / 'robot.launch.yaml', """
        launch:
        - arg: {name: ns}
        - node: {pkg: pkg_a, exec: x, namespace: $(var ns)}
        """)
    path = write(tmp_path / 'two.launch.yaml', """
        launch:
        - include: {file: $(dirname)/robot.launch.py, arg: [{name: ns, value: r1}]}
        - include: {file: $(dirname)/robot.launch.yaml, arg: [{name: ns, value: r2}]}
        """)
    system = load_system(path, {}, lambda name: '', environ={})
    assert [node.namespace for node in system.nodes] == ['r1', 'r2']


def test_if_and_unless_choose_entries(tmp_path):
    """ROS launch's if / unless on includes, nodes and set_env; arguments decide."""
    write(tmp_path / 'part.launch.yaml', """
        launch:
        - node: {pkg: pkg_a, exec: included}
        """)
    path = write(tmp_path / 'top.launch.yaml', """
        launch:
        - arg: {name: slam, default: 'false'}
        - include: {file: $(dirname)/part.launch.yaml, if: $(var slam)}
        - node: {pkg: pkg_a, exec: amcl, unless: $(var slam)}
        - node: {pkg: pkg_a, exec: slam, if: $(var slam)}
        - node: {pkg: pkg_a, exec: both, if: 'true', unless: 'false'}
        - set_env: {name: MODE, value: mapping, if: $(var slam)}
        - node: {pkg: pkg_a, exec: env_check}
        """)
    system = load_system(path, {}, lambda name: '', environ={})
    assert [node.executable for node in system.nodes] == ['amcl', 'both', 'env_check']
    assert 'MODE' not in system.nodes[-1].env
    system = load_system(path, {'slam': 'True'}, lambda name: '', environ={})
    assert [node.executable for node in system.nodes] == ['included', 'slam', 'both',
                                                          'env_check']
    assert system.nodes[-1].env['MODE'] == 'mapping'
    with pytest.raises(SystemDescriptionError, match='"if": expected true or false'):
        load_system(path, {'slam': 'maybe'}, lambda name: '', environ={})


def test_anon_is_one_name_per_launch_and_name(tmp_path):
    """
    $(anon NAME) is launch's AnonName: NAME_<host>_<pid>_<random>, '.', '-', ':' as '_'.

    The same NAME gives the same name everywhere in one launch (here in an argument's
    default, a node and an included file), another NAME another one, the next launch
    new ones.
    """
    write(tmp_path / 'inner.launch.yaml', """
        launch:
        - node: {pkg: pkg_a, exec: inner, args: $(anon amcl)}
        """)
    path = write(tmp_path / 'top.launch.yaml', """
        launch:
        - arg: {name: state_file, default: /tmp/amcl_pose_$(anon amcl).yaml}
        - node: {pkg: pkg_a, exec: a, args: $(var state_file) $(anon amcl) $(anon my-node.x)}
        - include: {file: $(dirname)/inner.launch.yaml}
        """)
    system = load_system(path, {}, lambda name: '', environ={})
    state_file, amcl, other = system.nodes[0].arguments
    assert system.nodes[1].arguments == [amcl]
    assert state_file == f'/tmp/amcl_pose_{amcl}.yaml'
    assert re.fullmatch(rf'amcl_\w+_{os.getpid()}_\d+', amcl), amcl
    assert re.fullmatch(rf'my_node_x_\w+_{os.getpid()}_\d+', other), other
    assert other.rsplit('_', 1)[1] != amcl.rsplit('_', 1)[1]
    again = load_system(path, {}, lambda name: '', environ={})
    assert again.nodes[0].arguments[1] != amcl


@pytest.mark.parametrize('argv, expected', [
    ([], {}),
    (['a:=1', 'b_2:=x:=y', 'c:='], {'a': '1', 'b_2': 'x:=y', 'c': ''}),
])
def test_parse_launch_arguments(argv, expected):
    assert parse_launch_arguments(argv) == expected


@pytest.mark.parametrize('bad', ['a=1', ':=1', '1a:=2', 'a b:=1'])
def test_parse_launch_arguments_rejects(bad):
    with pytest.raises(SystemDescriptionError):
        parse_launch_arguments([bad])


@pytest.mark.parametrize('value, text', [
    (True, 'true'), (3, '3'), (0.5, '0.5'), ('x', 'x'), ('a b', 'a b'),
    ([1, 2], '[1, 2]'), ('true', "'true'"), ('', "''"),
])
def test_yaml_scalar(value, text):
    assert yaml_scalar(value) == text


# --- $(command ...) ---------------------------------------------------------------------

ECHO_SCRIPT = """
import os, sys
sys.stdout.write('|'.join(sys.argv[1:]))
if os.environ.get('ECHO_STDERR'):
    sys.stderr.write(os.environ['ECHO_STDERR'])
sys.exit(int(os.environ.get('ECHO_EXIT', '0')))
"""


@pytest.fixture
def echo(tmp_path):
    """Return the command line of a script printing its arguments joined by '|'."""
    script = tmp_path / 'echo_args.py'
    script.write_text(ECHO_SCRIPT)
    return f'{sys.executable} {script}'


def command_system(tmp_path, find, value, environ=None, arguments=None):
    """Load a one-node system whose node name is value; return the name it got."""
    path = tmp_path / 'c.launch.yaml'
    path.write_text(yaml.safe_dump({'launch': [
        {'arg': {'name': 'word', 'default': 'plain'}},
        {'set_env': {'name': 'FROM_SET_ENV', 'value': 'set'}},
        {'node': {'pkg': 'pkg_a', 'exec': 'x', 'name': value}}]}))
    system = load_system(path, arguments or {}, find, environ=dict(environ or {}))
    return system.nodes[0].name


def test_command_output_with_quoted_arguments_and_nested_substitutions(
        packages, tmp_path, echo):
    _, find = packages
    value = (f"$(command '{echo} \"two words\" $(var word) "
             "$(find-pkg-share pkg_a)/urdf/robot.xacro')")
    assert command_system(tmp_path, find, value, arguments={'word': 'given'}) == \
        f'two words|given|{find("pkg_a")}/urdf/robot.xacro'


def test_command_runs_in_the_launch_environment_without_a_shell(packages, tmp_path, echo):
    _, find = packages
    # $HOME and ; are not expanded or interpreted: there is no shell. The environment
    # (with set_env entries) is the command's.
    assert command_system(tmp_path, find, f"$(command '{echo} $HOME ;')") == '$HOME|;'
    assert command_system(tmp_path, find, f"$(command '{echo} out' ignore)",
                          environ={'ECHO_STDERR': 'ignored'}) == 'out'
    script = tmp_path / 'env.py'
    script.write_text('import os; print(os.environ["FROM_SET_ENV"])')
    assert command_system(tmp_path, find, f"$(command '{sys.executable} {script}')") == 'set\n'


def test_command_output_as_a_parameter_stays_one_string(packages, tmp_path):
    _, find = packages
    script = tmp_path / 'urdf.py'
    script.write_text("print('<robot name=\"r\">\\n  <link name=\"a\"/>\\n</robot>')")
    path = tmp_path / 'p.launch.yaml'
    path.write_text(yaml.safe_dump({'launch': [{'node': {
        'pkg': 'pkg_a', 'exec': 'x', 'param': [
            {'name': 'robot_description',
             'value': f"$(command '{sys.executable} {script}')"}]}}]}))
    (node,) = load_system(path, {}, find, environ={}).nodes
    (name, value), = node.parameters
    assert name == 'robot_description'
    # Read as YAML, as launch_ros does: the lines fold into one string.
    assert value == '<robot name="r"> <link name="a"/> </robot>'


@pytest.mark.parametrize('on_stderr, expected', [
    ('ignore', 'out'), ('warn', 'out'), ('capture', 'outerr')])
def test_command_standard_error_options(packages, tmp_path, echo, capsys, on_stderr,
                                        expected):
    _, find = packages
    value = f"$(command '{echo} out' {on_stderr})"
    assert command_system(tmp_path, find, value, environ={'ECHO_STDERR': 'err'}) == expected
    warned = 'wrote to standard error' in capsys.readouterr().err
    assert warned == (on_stderr == 'warn')


@pytest.mark.parametrize('value, environ, message', [
    ("$(command '{echo} x')", {'ECHO_EXIT': '3'}, 'failed with exit code 3'),
    ("$(command '{echo} x')", {'ECHO_EXIT': '1', 'ECHO_STDERR': 'xacro: no such file'},
     'failed with exit code 1:\nxacro: no such file'),
    ("$(command '{echo} x')", {'ECHO_STDERR': 'a warning'},
     "wrote to standard error (add 'ignore'"),
    ("$(command '{echo}' loudly)", {}, 'on_stderr must be one of'),
    ("$(command 'no_such_program_anywhere --flag')", {},
     "program 'no_such_program_anywhere' not found"),
    ("$(command '')", {}, 'the command is empty'),
    ("$(command 'echo \"unbalanced')", {}, 'cannot split the command'),
    ("$(command '{echo} x", {}, 'is not closed'),
    ('$(command {echo}', {}, 'has no closing ")"'),
    ('$(var word)x)', {}, None),
    ('$(var)', {}, 'unsupported substitution'),
    ('$( var word)', {}, 'not followed by a substitution name'),
    ("$(var 'word'x)", {}, 'expected a space or ")"'),
])
def test_command_and_syntax_errors_name_the_file(packages, tmp_path, echo, value, environ,
                                                 message):
    _, find = packages
    value = value.replace('{echo}', echo)
    if message is None:         # not an error: text after a substitution is kept
        assert command_system(tmp_path, find, value, environ) == 'plainx)'
        return
    with pytest.raises(SystemDescriptionError) as error:
        command_system(tmp_path, find, value, environ)
    assert message in str(error.value)
    assert 'c.launch.yaml' in str(error.value)


def test_escapes_in_quoted_arguments(packages, tmp_path, echo):
    _, find = packages
    value = f"$(command '{echo} \\'it\\'\\\\s \\$(var word)')"
    # In the argument: \' is a quote, \\ a backslash, \$ a dollar (no substitution);
    # then shlex joins 'it' and \s, and keeps $(var word) literal.
    assert command_system(tmp_path, find, value) == 'its|$(var|word)'
