"""The Docker image sets the workspace up as the README says and runs its demo by default.

No Docker engine is needed (nor ROS): these tests read the Dockerfile, .dockerignore,
requirements.txt, the Makefile and the README, and fail when they drift apart; and they run
tools/docker_check.sh (`make docker-check`) against stand-ins for docker where there is
none, or it fails to start, or the base image is missing.
`make docker-check` itself builds and runs the image where a Docker engine answers.
"""

import ast
import json
import os
from pathlib import Path
import re
import shlex
import shutil
import subprocess

from pip._internal.network.session import PipSession
from pip._internal.req.req_file import parse_requirements
import pytest

REPO = Path(__file__).resolve().parents[1]
DOCKERFILE = REPO / 'Dockerfile'
DOCKER_CHECK = REPO / 'tools' / 'docker_check.sh'
EXIT_NO_DOCKER, EXIT_NO_BASE = 77, 78  # the check script's skips
README = (REPO / 'README.md').read_text()
# Packages an image based on the official python image has without installing them: its
# Python comes with venv and its C headers, which Debian splits into these two.
PYTHON_IMAGE_PROVIDES = {'python3-venv', 'python3-dev'}
COMPILERS = ({'build-essential'}, {'gcc', 'g++'})


def parse_dockerfile(text: str) -> list:
    """Return the Dockerfile's instructions as (INSTRUCTION, arguments) pairs."""
    instructions, current = [], ''
    for line in text.splitlines():
        if line.lstrip().startswith('#'):
            continue  # comments, also inside a continued instruction, as Docker does
        if line.endswith('\\'):
            current += line[:-1]
            continue
        current += line
        if current.strip():
            keyword, _, arguments = current.strip().partition(' ')
            instructions.append((keyword.upper(), arguments.strip()))
        current = ''
    return instructions


INSTRUCTIONS = parse_dockerfile(DOCKERFILE.read_text())


def arguments_of(keyword: str) -> list:
    """Return the arguments of every instruction of one kind, in order."""
    return [arguments for name, arguments in INSTRUCTIONS if name == keyword]


def exec_form(keyword: str) -> list:
    """Return the last CMD or ENTRYPOINT, which must be in exec (JSON) form."""
    found = arguments_of(keyword)
    if not found:
        return []
    command = json.loads(found[-1])
    assert isinstance(command, list), f'{keyword} must be in exec form: {found[-1]}'
    return command


def base_image_python() -> tuple:
    """Return the base image's name and Python (major, minor) from its pinned FROM tag."""
    images = arguments_of('FROM')
    assert len(images) == 1, images
    match = re.fullmatch(r'(python):(\d+)\.(\d+)\.\d+-slim-bookworm(?:@sha256:\w+)?'
                         r'|(debian):bookworm(?:-[\w.-]+)?(?:@sha256:\w+)?', images[0])
    assert match, f'base image {images[0]!r}: want a pinned python:3.X.Y-slim-bookworm or ' \
                  'debian:bookworm'
    if match.group(1):
        return 'python', (int(match.group(2)), int(match.group(3)))
    return 'debian', (3, 11)  # bookworm's python3


def quick_start_commands() -> list:
    """Return the commands of the README's Quick start code block, comments stripped."""
    block = re.search(r'^## Quick start\n+```bash\n(.*?)^```', README, re.M | re.S)
    assert block, 'README has no Quick start code block'
    commands = [line.split('#', 1)[0].strip() for line in block.group(1).splitlines()]
    return [command for command in commands if command]


def quick_start_command(word: str) -> str:
    """Return the one Quick start command that contains word (demo or test)."""
    matching = [command for command in quick_start_commands() if word in command.split()]
    assert len(matching) == 1, (word, quick_start_commands())
    return matching[0]


def readme_section(title: str) -> str:
    """Return the text of one '## ' section of the README."""
    match = re.search(rf'^## {re.escape(title)}\n(.*?)(?=^## |\Z)', README, re.M | re.S)
    assert match, f'README has no "## {title}" section'
    return match.group(1)


def apt_packages() -> set:
    """Return the packages that the RUN steps install with apt-get."""
    packages = set()
    for run in (run for run in arguments_of('RUN') if 'apt-get install' in run):
        for step in re.split(r'&&|;|\|\|', run):
            words = shlex.split(step)
            if words[:2] == ['apt-get', 'install']:
                assert '--no-install-recommends' in words, step
                packages |= {word for word in words[2:] if not word.startswith('-')}
                assert 'rm -rf /var/lib/apt/lists/*' in run, f'apt lists left in the image: {run}'
    return packages


def bootstrap_main_steps() -> list:
    """Return the names of the functions tools/bootstrap.py's main() calls, in order."""
    module = ast.parse((REPO / 'tools' / 'bootstrap.py').read_text())
    main = next(node for node in module.body
                if isinstance(node, ast.FunctionDef) and node.name == 'main')
    calls = [node for node in ast.walk(main)
             if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)]
    calls.sort(key=lambda node: (node.lineno, node.col_offset))
    defined = {node.name for node in module.body if isinstance(node, ast.FunctionDef)}
    return [node.func.id for node in calls if node.func.id in defined]


def dockerignore_excludes(path: str, patterns: list = None) -> bool:
    """Tell whether .dockerignore keeps path out of the build context (Docker's rules).

    Patterns are relative to the context root; ``*`` and ``?`` stay within one path
    element, ``**`` spans any number of them; a path whose parent is excluded is too;
    the last matching pattern wins, and ``!`` re-includes.
    """
    if patterns is None:
        patterns = (REPO / '.dockerignore').read_text().splitlines()
    parts = path.split('/')
    candidates = ['/'.join(parts[:end]) for end in range(1, len(parts) + 1)]
    excluded = False
    for line in (line.strip() for line in patterns):
        if not line or line.startswith('#'):
            continue
        negated = line.startswith('!')
        pattern = line.lstrip('!').strip().strip('/')
        regex = ''
        while pattern:
            for token, replacement in (('**/', '(?:.*/)?'), ('**', '.*'), ('*', '[^/]*'),
                                       ('?', '[^/]')):
                if pattern.startswith(token):
                    regex += replacement
                    pattern = pattern[len(token):]
                    break
            else:
                regex += re.escape(pattern[0])
                pattern = pattern[1:]
        if any(re.fullmatch(regex, candidate) for candidate in candidates):
            excluded = not negated
    return excluded


def test_base_image_python_has_a_lock_and_is_supported():
    """The image's Python is one the README supports and that has its own lock file."""
    _, version = base_image_python()
    assert (3, 10) <= version <= (3, 13)
    assert '3.10 to 3.13' in readme_section('Quick start')
    lock = REPO / 'requirements' / f'ros-jazzy-pip.py{version[0]}{version[1]}.lock.txt'
    assert lock.is_file(), f"no lock file for the image's Python: {lock}"


def test_requirements_txt_is_the_lock_of_the_image_python():
    """requirements.txt includes exactly the image Python's lock, and pip reads it so."""
    _, version = base_image_python()
    lock = f'requirements/ros-jazzy-pip.py{version[0]}{version[1]}.lock.txt'
    lines = [line.strip() for line in (REPO / 'requirements.txt').read_text().splitlines()]
    entries = [line for line in lines if line and not line.startswith('#')]
    assert entries == [f'-r {lock}']

    def pinned(path: Path) -> set:
        return {parsed.requirement for parsed in parse_requirements(
            str(path), session=PipSession())}

    from_requirements = pinned(REPO / 'requirements.txt')
    assert from_requirements == pinned(REPO / lock)
    assert len(from_requirements) > 100
    assert all(re.fullmatch(r'[\w.-]+==[\w.+]+', pin) for pin in from_requirements)


def test_apt_packages_cover_the_readme_prerequisites():
    """The README's Debian prerequisites (and make) are installed, or come with the image."""
    base, _ = base_image_python()
    prerequisites = re.search(r'Debian/Ubuntu: `apt-get install ([^`]+)`',
                              readme_section('Quick start'))
    assert prerequisites, 'README lists no Debian prerequisites'
    wanted = set(prerequisites.group(1).split()) | {'make'}
    assert {'cmake', 'build-essential'} <= wanted  # what the README says today
    installed = apt_packages()
    if base == 'python':
        wanted -= PYTHON_IMAGE_PROVIDES
    else:
        wanted |= {'python3-venv', 'python3-dev'}  # Python.h: rosidl_generator_py needs it
    if any(compilers <= installed for compilers in COMPILERS):
        wanted -= {'build-essential'}
    missing = wanted - installed
    if 'build-essential' in installed:
        missing -= {'make'}  # build-essential depends on it
    assert not missing, f'the image lacks the README prerequisites {sorted(missing)}'


def test_setup_steps_are_the_readme_setup():
    """Sources in, then `make setup`; before it at most bootstrap.py's own first steps."""
    makefile = (REPO / 'Makefile').read_text()
    assert re.search(r'^setup:\n\t@?\$\(PYTHON\) tools/bootstrap\.py$', makefile, re.M)
    demo_target = quick_start_command('demo').split()[1]
    assert (re.search(rf'^{demo_target}:.*\bsetup\b', makefile, re.M)
            or re.search(rf'^{demo_target}:\n\t@?\$\(PYTHON\) tools/bootstrap\.py', makefile,
                         re.M)), 'the demo no longer sets up first'
    assert 'tools/bootstrap.py' in readme_section('Quick start')

    steps = [(name, arguments) for name, arguments in INSTRUCTIONS if name in ('COPY', 'RUN')]
    whole_copy = [index for index, (name, arguments) in enumerate(steps)
                  if name == 'COPY' and arguments.split()[-2:] == ['.', '.']]
    assert len(whole_copy) == 1, 'the repository must be copied in once, as `COPY . .`'
    after = steps[whole_copy[0] + 1:]
    assert after == [('RUN', 'make setup')], after
    assert arguments_of('WORKDIR')[-1] == '/work'

    # Any earlier setup RUN may only run the first steps of bootstrap.py, in its order.
    main_steps = bootstrap_main_steps()
    assert main_steps[:2] == ['check_python', 'ensure_venv'], main_steps
    copied_before = []
    for name, arguments in steps[:whole_copy[0]]:
        if name == 'COPY':
            copied_before += [source.rstrip('/') for source in arguments.split()[:-1]
                              if not source.startswith('--')]
        elif 'bootstrap' in arguments:
            called = re.findall(r'bootstrap\.(\w+)\(\)', arguments)
            assert called == main_steps[:len(called)], (called, main_steps)
            assert 'ensure_workspace' not in called
            assert {'requirements', 'tools/bootstrap.py'} <= set(copied_before), copied_before
        else:
            assert 'apt-get' in arguments or 'useradd' in arguments, \
                f'a setup step the README does not have: {arguments}'


def test_default_command_is_the_readme_demo():
    """The container runs the README's demo unless told otherwise."""
    assert exec_form('CMD') == shlex.split(quick_start_command('demo'))
    entrypoint = exec_form('ENTRYPOINT')
    if entrypoint:  # only an init that runs the command it is given
        assert Path(entrypoint[0]).name in ('tini', 'dumb-init'), entrypoint
        assert entrypoint[-1] == '--', entrypoint


def test_readme_docker_section_runs_what_the_image_has():
    """The README's Docker commands mount reports/ where the demo writes, and run the tests."""
    section = readme_section('Docker')
    assert README.index('## Working in the workspace') < README.index('## Docker')
    commands = [line.split('  #', 1)[0].strip() for line in section.splitlines()
                if line.startswith('docker ')]
    assert any(command.startswith('docker build ') for command in commands), commands
    workdir = arguments_of('WORKDIR')[-1]
    runs = [shlex.split(command) for command in commands if command.startswith('docker run ')]
    mounts = [run[run.index('-v') + 1] for run in runs if '-v' in run]
    assert f'$PWD/reports:{workdir}/reports' in mounts, mounts
    test_command = shlex.split(quick_start_command('test'))
    assert any(run[-len(test_command):] == test_command for run in runs), runs


@pytest.mark.parametrize('path', [
    'build', 'build/mecanum_control/setup.py', 'install/setup.bash', 'log/latest',
    '.venv/bin/python', 'reports/demo_20250101_000000/report.md', 'bench/results/a.csv',
    '.git/HEAD', 'src/mecanum_control/mecanum_control/__pycache__/pid.cpython-312.pyc',
    '.bootstrap.lock', 'src/robot_controller/robot_controller.egg-info/PKG-INFO',
    '.pytest_cache/README.md', '.hypothesis/examples/x',
])
def test_dockerignore_keeps_host_builds_and_outputs_out(path):
    """What the host built or ran, caches and git history stay out of the image."""
    assert dockerignore_excludes(path)


@pytest.mark.parametrize('path', [
    'Makefile', 'mecanum', 'pytest.ini', 'requirements.txt', 'ros_pip_overlay/COLCON_IGNORE',
    'ros_pip_overlay/tf2_msgs/package.xml', 'src/mecanum_map_server/maps/apartment.yaml',
])
def test_dockerignore_keeps_what_the_setup_and_tests_need(path):
    """The files `make setup`, the demo and the tests need go into the image."""
    assert (REPO / path).exists()
    assert not dockerignore_excludes(path)


def test_dockerignore_keeps_every_source_file():
    """Every file of the sources, tools, locks, tests and benchmarks goes into the image."""
    kept_trees = ['src', 'ros_pip_overlay', 'requirements', 'tools', 'tests', 'bench', 'docs']
    caches = {'__pycache__', '.pytest_cache', '.hypothesis'}
    files = [path.relative_to(REPO) for tree in kept_trees for path in (REPO / tree).rglob('*')
             if path.is_file()]
    files = [path for path in files if path.parts[:2] != ('bench', 'results')
             and not any(part in caches or part.endswith('.egg-info') for part in path.parts)]
    assert len(files) > 100
    excluded = [str(path) for path in files if dockerignore_excludes(str(path))]
    assert not excluded


@pytest.mark.parametrize('path, patterns, expected', [
    ('build/a/b', ['build'], True),
    ('src/build/a', ['build'], False),  # anchored at the context root
    ('src/a/__pycache__/b.pyc', ['**/__pycache__'], True),
    ('__pycache__/b.pyc', ['**/__pycache__'], True),
    ('reports/a.md', ['reports/'], True),
    ('reports.py', ['reports'], False),
    ('log/keep.txt', ['log', '!log/keep.txt'], False),
    ('log/other.txt', ['log', '!log/keep.txt'], True),
    ('a/b.pyc', ['*.pyc'], False),  # * stays within one path element
    ('a/b.pyc', ['**/*.pyc'], True),
])
def test_dockerignore_matcher_follows_docker_rules(path, patterns, expected):
    """The matcher these tests use reads patterns as Docker does."""
    assert dockerignore_excludes(path, patterns) == expected


def fake_docker(tmp_path: Path, answers: str) -> Path:
    """Write a stand-in for the docker command: a shell case over its first argument."""
    calls = tmp_path / 'docker_calls'
    docker = tmp_path / 'docker'
    docker.write_text(f'#!/bin/sh\necho "$*" >> {shlex.quote(str(calls))}\n'
                      f'case "$1" in\n{answers}\n*) echo "unexpected: $*" >&2; exit 99 ;;\nesac\n')
    docker.chmod(0o755)
    return docker


def run_docker_check(docker, *args, **env) -> subprocess.CompletedProcess:
    """Run tools/docker_check.sh with DOCKER=docker (and env); return the finished process."""
    clean = {key: value for key, value in os.environ.items() if not key.startswith('DOCKER')}
    return subprocess.run([str(DOCKER_CHECK), *args],
                          env=dict(clean, DOCKER=str(docker), **env),
                          capture_output=True, text=True, timeout=60)


# A docker whose engine answers, with the base image here, that builds, and whose
# containers print what the demo and pytest print: DEMO_LINE, DEMO_STATUS, TESTS_LINE.
ENGINE = """info) exit 0 ;;
image) exit 0 ;;
build) echo "Successfully built"; exit 0 ;;
run) case "$*" in
     *--entrypoint*) exit 0 ;;
     *'make test'*) echo "$TESTS_LINE"; exit 0 ;;
     *) echo "$DEMO_LINE"; exit "$DEMO_STATUS" ;;
     esac ;;"""
GIT_WORK_TREE = pytest.mark.skipif(
    not (REPO / '.git').exists() or shutil.which('git') is None,
    reason='not a git work tree (the check builds from the committed HEAD)')


def test_make_docker_check_runs_the_check_script_without_setup():
    """`make docker-check` is a phony target that runs the script alone, with its arguments."""
    makefile = (REPO / 'Makefile').read_text()
    phony = re.search(r'^\.PHONY:(.*)$', makefile, re.M)
    assert phony and 'docker-check' in phony.group(1).split()
    env = {key: value for key, value in os.environ.items()
           if key not in ('MAKEFLAGS', 'MAKELEVEL', 'MFLAGS')}  # when run by `make test`
    dry_run = subprocess.run(['make', '-n', '--no-print-directory', 'docker-check',
                              'DOCKER_CHECK_ARGS=--make-base'], cwd=REPO, env=env,
                             capture_output=True, text=True, timeout=60)
    assert dry_run.returncode == 0, dry_run.stderr
    # Only the script: no `make setup` first (it needs git and docker, not the workspace).
    assert dry_run.stdout.splitlines() == ['tools/docker_check.sh --make-base'], dry_run.stdout


def test_docker_check_script_is_executable_and_parses():
    """The script runs as a command and bash reads it without a syntax error."""
    assert os.access(DOCKER_CHECK, os.X_OK)
    assert DOCKER_CHECK.read_text().startswith('#!/usr/bin/env bash\n')
    parsed = subprocess.run(['bash', '-n', str(DOCKER_CHECK)], capture_output=True, text=True)
    assert parsed.returncode == 0, parsed.stderr


@pytest.mark.skipif(shutil.which('shellcheck') is None, reason='shellcheck is not installed')
def test_docker_check_script_passes_shellcheck():
    """No shellcheck warnings (quoting, word splitting, unset variables)."""
    checked = subprocess.run(['shellcheck', str(DOCKER_CHECK)], capture_output=True, text=True)
    assert checked.returncode == 0, checked.stdout


def test_docker_check_skips_without_a_docker_command(tmp_path):
    """No docker command: a clear 'SKIPPED' and exit 77, not a failure."""
    checked = run_docker_check(tmp_path / 'no_such_docker')
    assert checked.returncode == EXIT_NO_DOCKER, checked
    assert 'SKIPPED' in checked.stdout and 'no_such_docker' in checked.stdout


def test_docker_check_skips_when_no_engine_answers(tmp_path):
    """A docker command whose engine does not answer: its error, 'SKIPPED' and exit 77."""
    docker = fake_docker(
        tmp_path, 'info) echo "Cannot connect to the Docker daemon" >&2; exit 1 ;;')
    checked = run_docker_check(docker)
    assert checked.returncode == EXIT_NO_DOCKER, checked
    assert 'SKIPPED: no Docker engine answers' in checked.stdout
    assert 'Cannot connect to the Docker daemon' in checked.stdout
    assert (tmp_path / 'docker_calls').read_text().split() == ['info']


def test_docker_check_usage_error(tmp_path):
    """An unknown argument is a usage error (exit 2), before docker is asked anything."""
    docker = fake_docker(tmp_path, '')
    checked = run_docker_check(docker, '--no-such-option')
    assert checked.returncode == 2, checked
    assert 'usage:' in checked.stderr
    assert not (tmp_path / 'docker_calls').exists()


@GIT_WORK_TREE
def test_docker_check_without_base_image_prints_the_recipe_and_builds_nothing(tmp_path):
    """Base image neither here nor pullable: the stand-in recipe for it, exit 78, no build."""
    docker = fake_docker(tmp_path, '\n'.join([
        'info) exit 0 ;;',
        'image) exit 1 ;;',  # image inspect: no such image
        'pull) echo "dial tcp: lookup registry-1.docker.io: no such host" >&2; exit 1 ;;']))
    checked = run_docker_check(docker)
    assert checked.returncode == EXIT_NO_BASE, checked
    committed = subprocess.run(['git', '-C', str(REPO), 'show', 'HEAD:Dockerfile'],
                               capture_output=True, text=True, check=True).stdout
    base = next(arguments for name, arguments in parse_dockerfile(committed) if name == 'FROM')
    assert f'SKIPPED: no base image {base}' in checked.stdout
    assert 'mmdebstrap --variant=minbase' in checked.stdout
    assert f'docker build --network host -t {base} /tmp/ctx' in checked.stdout
    assert '--make-base' in checked.stdout
    calls = [line.split()[0] for line in (tmp_path / 'docker_calls').read_text().splitlines()]
    assert calls == ['info', 'image', 'pull'], calls


def test_readme_docker_section_has_the_check():
    """The README's Docker section gives the check's commands, with and without the tests."""
    section = readme_section('Docker')
    commands = [line.split('  #', 1)[0].strip() for line in section.splitlines()]
    assert 'make docker-check' in commands, commands
    assert 'DOCKER_CHECK_TESTS=1 make docker-check' in commands, commands
    assert 'DOCKER_CHECK_TESTS' in DOCKER_CHECK.read_text()


@GIT_WORK_TREE
def test_docker_check_passes_with_its_table(tmp_path):
    """Build, demo and tests pass: a table with the demo's verdict and the test counts, exit 0."""
    docker = fake_docker(tmp_path, ENGINE)
    checked = run_docker_check(
        docker, '--tests', DOCKER_CHECK_OUT=str(tmp_path / 'out'),
        DEMO_LINE='demo: PASS: 12 of 12 goals reached, 0 collisions, 47.33 m in 252.66 s',
        DEMO_STATUS='0', TESTS_LINE='===== 2441 passed, 21 skipped in 835.19s (0:13:55) =====')
    assert checked.returncode == 0, checked
    rows = {line.split()[0]: line for line in checked.stdout.splitlines()
            if line.split()[:1] in (['build'], ['demo'], ['tests'])}
    assert rows['build'].split()[1] == 'ok'
    assert 'PASS: 12 of 12 goals reached, 0 collisions' in rows['demo']
    assert '2441 passed, 21 skipped' in rows['tests']
    assert 'PASSED' in checked.stdout
    calls = (tmp_path / 'docker_calls').read_text().splitlines()
    build = next(call.split() for call in calls if call.startswith('build'))
    assert build[:3] == ['build', '--network=host', '-t'] and build[3] == 'mecanum_robot:check'
    clone = Path(build[4])
    assert not clone.exists(), 'the clean clone is left behind'
    demo, tests = [call for call in calls if call.startswith('run') and 'chmod' not in call]
    assert '-v' in demo.split() and f'{tmp_path}/out/reports:/work/reports' in demo
    assert '--network=bridge' in demo and tests.endswith('mecanum_robot:check make test')
    assert (tmp_path / 'out' / 'demo.log').read_text().startswith('demo: PASS')


@GIT_WORK_TREE
def test_docker_check_fails_on_a_failed_demo_and_skips_the_tests(tmp_path):
    """A failing demo: its verdict and log tail, no test run, exit 1."""
    docker = fake_docker(tmp_path, ENGINE)
    checked = run_docker_check(
        docker, DOCKER_CHECK_OUT=str(tmp_path / 'out'), DOCKER_CHECK_TESTS='1',
        DEMO_LINE='demo: FAIL: 11 of 12 goals reached, 0 collisions, 50.08 m in 356.22 s',
        DEMO_STATUS='2', TESTS_LINE='===== 1 passed in 1.00s =====')
    assert checked.returncode == 1, checked
    demo_row = next(line for line in checked.stdout.splitlines() if line.startswith('demo '))
    assert 'FAILED (exit 2) FAIL: 11 of 12 goals reached, 0 collisions' in demo_row
    assert not any('make test' in call
                   for call in (tmp_path / 'docker_calls').read_text().splitlines())
    assert 'FAILED: logs in' in checked.stdout
