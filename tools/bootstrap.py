#!/usr/bin/env python3
"""Set up the pip-based ROS 2 Jazzy workspace from nothing, skipping what is done.

Steps, each skipped when its inputs did not change since the last run:

1. ``.venv``: a virtual environment made with the Python running this script
   (3.10 to 3.13).
2. Pinned dependencies from ``requirements/ros-jazzy-pip.py3XX.lock.txt`` (one
   per Python version), then a fix
   for a packaging bug of the ROS wheels (their exported CMake files name the
   wheel builder's include directories).
3. The pip-only interface overlay (``ros_pip_overlay/``: standard interfaces
   such as tf2_msgs that PyPI lacks), built with colcon into
   ``.venv/ros_overlay``. An apt ROS install never sees it.
4. The workspace ``src/`` built with ``colcon build --symlink-install``.
5. The ``ros2`` command and ``ros2 launch`` (ros2cli, launch and the packages they
   need: tools/ros2_upstream.py), built from their pinned upstream Jazzy sources into
   ``.venv/ros2cli``, with this project's ``ros2 bag`` (tools/ros2cli_pip): from
   ``$MECANUM_ROS2_SOURCES``, a ``shared/vendor`` folder beside or
   above the repository, or GitHub. Where none is reachable, set-up goes on and says
   that ``ros2`` is missing and why (``./mecanum launch`` and ``./mecanum run`` work).
6. The firmware tests' MicroPython (``firmware/package-lock.json``: the WebAssembly
   MicroPython 1.27 from npm), with ``npm ci`` when node and npm are installed;
   skipped with a message otherwise (those tests are then skipped too).

Only the standard library is used: this runs before the venv exists.
Usage: ``python3 tools/bootstrap.py [--force] [--no-firmware-tests]`` (``make demo``
passes the latter: the demo does not need step 6).
"""

import argparse
import fcntl
import glob
import hashlib
import os
from pathlib import Path
import re
import shutil
import subprocess
import sys
import sysconfig
import time

ROOT = Path(__file__).resolve().parents[1]
VENV = ROOT / '.venv'
# One lock per Python minor version, resolved by that interpreter.
PY_TAG = f'py{sys.version_info[0]}{sys.version_info[1]}'
LOCK_FILE = ROOT / 'requirements' / f'ros-jazzy-pip.{PY_TAG}.lock.txt'
OVERLAY_SRC = ROOT / 'ros_pip_overlay'
OVERLAY_PREFIX = VENV / 'ros_overlay'
ROS2CLI_PREFIX = VENV / 'ros2cli'
# The pip setup's own ros2cli extensions (`ros2 bag` on MCAP: rosbag2 is C++ and not on
# PyPI), built with the upstream packages. Never built on an apt install (tools/ has a
# COLCON_IGNORE), where the real ros2bag stays.
ROS2CLI_PIP_SRC = ROOT / 'tools' / 'ros2cli_pip'
STAMP_DIR = VENV / '.mecanum_stamps'
LOG_DIR = ROOT / 'log' / 'bootstrap'
# Packaging tools the lock file does not cover. setuptools stays below 80, whose new
# `develop` command breaks `colcon build --symlink-install`.
PACKAGING_PINS = ['pip==25.3', 'setuptools==75.8.2', 'wheel==0.45.1']

SUPPORTED_PYTHONS = ((3, 10), (3, 11), (3, 12), (3, 13))
# Build inputs of a package: a change to any of these needs `colcon build`.
# With --symlink-install, edits to existing Python files and data files do not.
BUILD_INPUT_NAMES = {'package.xml', 'setup.py', 'setup.cfg', 'CMakeLists.txt', 'COLCON_IGNORE'}
BUILD_INPUT_SUFFIXES = {'.msg', '.srv', '.action'}


def say(text: str) -> None:
    """Print one progress line of the bootstrap."""
    print(f'[setup] {text}', flush=True)


def fail(text: str) -> None:
    """Print an error and stop with a non-zero exit code."""
    print(f'[setup] ERROR: {text}', file=sys.stderr, flush=True)
    sys.exit(1)


def venv_python() -> Path:
    """Return the venv's interpreter path."""
    return VENV / 'bin' / 'python'


def venv_site_packages() -> Path:
    """Return the venv's site-packages directory."""
    matches = sorted((VENV / 'lib').glob('python3.*/site-packages'))
    if not matches:
        fail(f'no site-packages found under {VENV}/lib; delete .venv and run again')
    return matches[0]


def read_stamp(name: str) -> str:
    """Return the digest recorded for a step, or '' if the step never ran."""
    path = STAMP_DIR / name
    return path.read_text().strip() if path.exists() else ''


def write_stamp(name: str, digest: str) -> None:
    """Record that a step completed for the given input digest."""
    STAMP_DIR.mkdir(parents=True, exist_ok=True)
    (STAMP_DIR / name).write_text(digest + '\n')


def digest_of(paths: list, extra: str = '') -> str:
    """Hash the relative names and contents of files (order-independent)."""
    sha = hashlib.sha256(extra.encode())
    for path in sorted(paths):
        sha.update(str(path.relative_to(ROOT)).encode() + b'\0')
        sha.update(path.read_bytes() if path.is_file() else b'<missing>')
    return sha.hexdigest()


def run_logged(cmd: list, log_name: str, env: dict = None, cwd: Path = ROOT) -> None:
    """Run a command with its output in a log file; show the tail on failure."""
    LOG_DIR.mkdir(parents=True, exist_ok=True)
    log_path = LOG_DIR / f'{log_name}.log'
    with open(log_path, 'w') as log:
        result = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, cwd=cwd)
    if result.returncode != 0:
        tail = log_path.read_text().splitlines()[-40:]
        print('\n'.join(tail), file=sys.stderr)
        fail(f'`{" ".join(str(c) for c in cmd[:4])} ...` failed; full log: {log_path}')


def ros_env() -> dict:
    """Environment for colcon: the venv first on PATH, its prefix as the ROS prefix.

    The ROS wheels' bootstrapper re-executes every Python started from the venv
    with LD_LIBRARY_PATH set; setting it here once avoids that per process.
    """
    env = dict(os.environ)
    site = venv_site_packages()
    lib_dirs = [str(VENV / 'lib')] + sorted(str(p) for p in site.glob('ros_*.libs'))
    prefixes = [str(VENV)]
    if (OVERLAY_PREFIX / 'install').is_dir():
        prefixes.insert(0, str(OVERLAY_PREFIX / 'install'))
    env.update({
        'VIRTUAL_ENV': str(VENV),
        'PATH': f'{VENV / "bin"}{os.pathsep}{env.get("PATH", "")}',
        'AMENT_PREFIX_PATH': os.pathsep.join(prefixes),
        'CMAKE_PREFIX_PATH': os.pathsep.join(prefixes),
        'LD_LIBRARY_PATH': os.pathsep.join(
            lib_dirs + [p for p in env.get('LD_LIBRARY_PATH', '').split(os.pathsep) if p]),
        '_ROS_WHEELS_BOOTSTRAP_COMPLETE': '1',
        'PYTHONNOUSERSITE': '1',
    })
    env.pop('PYTHONHOME', None)
    return env


def check_python() -> None:
    """Refuse Python versions the ROS wheels are not built for."""
    if sys.version_info[:2] not in SUPPORTED_PYTHONS:
        fail(f'Python {sys.version.split()[0]} is not supported; ROS 2 Jazzy wheels exist '
             'for CPython 3.10 to 3.13. Run with e.g. `make test PYTHON=python3.12`.')
    for tool in ('cmake', 'cc', 'c++'):
        if shutil.which(tool) is None:
            fail(f'`{tool}` not found: install cmake and a C/C++ compiler '
                 '(Debian/Ubuntu: apt-get install cmake build-essential).')


def ensure_venv() -> None:
    """Create .venv, or recreate it when it was made by another Python version."""
    marker = VENV / 'pyvenv.cfg'
    wanted = f'{sys.version_info.major}.{sys.version_info.minor}'
    if marker.exists():
        version_line = re.search(r'^version(?:_info)?\s*=\s*(\d+\.\d+)', marker.read_text(), re.M)
        if version_line and version_line.group(1) == wanted and venv_python().exists():
            return
        say(f'.venv was made by another Python; recreating it with Python {wanted}')
        shutil.rmtree(VENV)
    say(f'creating .venv with Python {wanted} ({sys.executable})')
    subprocess.run([sys.executable, '-m', 'venv', str(VENV)], check=True)
    # colcon (apt-ROS users run it at the repository root) must not crawl the venv.
    (VENV / 'COLCON_IGNORE').touch()


def ensure_requirements() -> None:
    """Install the pinned dependencies and fix the wheels' CMake files."""
    digest = digest_of([LOCK_FILE], extra=sys.version + ' '.join(PACKAGING_PINS))
    if read_stamp('requirements') == digest:
        return
    say('installing pinned ROS 2 Jazzy wheels and tools into .venv (about a minute; less '
        "with pip's cache)")
    started = time.monotonic()
    env = dict(os.environ, PIP_DISABLE_PIP_VERSION_CHECK='1')
    run_logged([str(venv_python()), '-m', 'pip', 'install', *PACKAGING_PINS],
               'pip-upgrade', env=env)
    run_logged([str(venv_python()), '-m', 'pip', 'install', '-r', str(LOCK_FILE)],
               'pip-install', env=env)
    fix_wheel_cmake_paths()
    write_stamp('requirements', digest)
    say(f'dependencies installed in {time.monotonic() - started:.0f} s')


def fix_wheel_cmake_paths() -> None:
    """Point the wheels' exported CMake include dirs at this machine's paths.

    The message wheels were built in a manylinux image; their exported CMake
    targets name /opt/python/cp3XX-cp3XX/include/python3.X and that image's
    numpy include directory, which makes CMake fail at generate time.
    """
    python_include = sysconfig.get_paths()['include']
    numpy_include = subprocess.run(
        [str(venv_python()), '-c', 'import numpy; print(numpy.get_include())'],
        check=True, capture_output=True, text=True, env=ros_env()).stdout.strip()
    numpy_pattern = re.compile(r'/opt/python/cp3\d+-cp3\d+/lib/python3\.\d+/site-packages/'
                               r'numpy/(?:_core|core)/include')
    python_pattern = re.compile(r'/opt/python/cp3\d+-cp3\d+/include/python3\.\d+')
    fixed = 0
    for name in glob.glob(str(VENV / 'share' / '**' / '*.cmake'), recursive=True):
        path = Path(name)
        text = path.read_text()
        if '/opt/python/' not in text:
            continue
        new_text = python_pattern.sub(python_include, numpy_pattern.sub(numpy_include, text))
        if new_text != text:
            path.write_text(new_text)
            fixed += 1
    say(f'fixed wheel builder include paths in {fixed} CMake files')


def package_build_inputs(base: Path) -> list:
    """List the files of the packages under base.

    With --symlink-install, adding or removing any file (a module, a launch or
    config file) needs a build; editing an existing one only does for the build
    inputs named in BUILD_INPUT_NAMES and BUILD_INPUT_SUFFIXES.
    """
    inputs = []
    for dirpath, dirnames, filenames in os.walk(base):
        dirnames[:] = [d for d in dirnames if not d.startswith('.') and d != '__pycache__'
                       and not d.endswith('.egg-info')]
        for filename in filenames:
            path = Path(dirpath) / filename
            inputs.append(path)
    return inputs


def build_digest(base: Path) -> str:
    """Digest of the file list plus the contents of build-relevant files."""
    sha = hashlib.sha256(sys.version.encode())
    for path in sorted(package_build_inputs(base)):
        sha.update(str(path.relative_to(ROOT)).encode() + b'\0')
        if path.name in BUILD_INPUT_NAMES or path.suffix in BUILD_INPUT_SUFFIXES:
            sha.update(path.read_bytes())
    return sha.hexdigest()


def colcon_build(base_paths: list, build_base: Path, install_base: Path, log_name: str,
                 env: dict) -> None:
    """Run colcon build for the packages found under base_paths."""
    cmd = [str(VENV / 'bin' / 'colcon'), '--log-base', str(ROOT / 'log' / 'colcon'),
           'build', '--symlink-install',
           '--build-base', str(build_base), '--install-base', str(install_base),
           '--base-paths', *[str(p) for p in base_paths],
           '--cmake-args', f'-DPython3_EXECUTABLE={venv_python()}',
           '-DCMAKE_BUILD_TYPE=Release', '-DBUILD_TESTING=OFF',
           '--event-handlers', 'console_cohesion-', 'summary+']
    run_logged(cmd, log_name, env=env)


def ensure_overlay() -> None:
    """Build the standard interfaces PyPI lacks (tf2_msgs, ...) into .venv/ros_overlay."""
    packages = sorted(p.parent for p in OVERLAY_SRC.glob('*/package.xml'))
    digest = build_digest(OVERLAY_SRC)
    if read_stamp('overlay') == digest and (OVERLAY_PREFIX / 'install').is_dir():
        return
    say('building standard interfaces missing from PyPI: '
        + ', '.join(p.name for p in packages))
    started = time.monotonic()
    colcon_build(packages, OVERLAY_PREFIX / 'build', OVERLAY_PREFIX / 'install',
                 'colcon-overlay', ros_env())
    write_stamp('overlay', digest)
    say(f'interfaces built in {time.monotonic() - started:.0f} s')


def ensure_workspace(force: bool) -> None:
    """Build the workspace packages under src/ with colcon."""
    digest = build_digest(ROOT / 'src')
    if not force and read_stamp('workspace') == digest and (ROOT / 'install').is_dir():
        return
    say('building the workspace (src/) with colcon')
    started = time.monotonic()
    colcon_build([ROOT / 'src'], ROOT / 'build', ROOT / 'install', 'colcon-workspace',
                 ros_env())
    write_stamp('workspace', digest)
    say(f'workspace built in {time.monotonic() - started:.0f} s')


def ensure_ros2cli() -> None:
    """Build the upstream ros2cli and launch packages into .venv/ros2cli (see step 5)."""
    import ros2_upstream
    pins = repr([(p.name, p.commit, p.tree_sha256) for p in ros2_upstream.PACKAGES])
    digest = hashlib.sha256((pins + sys.version + build_digest(ROS2CLI_PIP_SRC)).encode()
                            ).hexdigest()
    if read_stamp('ros2cli') == digest and (ROS2CLI_PREFIX / 'install').is_dir():
        return
    say('building the ros2 command and ros2 launch from their upstream Jazzy sources '
        '(ros2cli, launch, launch_ros: tools/ros2_upstream.py)')
    started = time.monotonic()
    source = ROS2CLI_PREFIX / 'src'
    shutil.rmtree(source, ignore_errors=True)
    try:
        fetched = ros2_upstream.fetch_sources(ROOT, ROS2CLI_PREFIX / 'downloads', source,
                                              say=say)
    except ros2_upstream.SourceError as error:
        say(f'the ros2 command is missing: {error}. Everything else works (./mecanum '
            f'launch, ./mecanum run). To get it, set {ros2_upstream.SOURCES_VARIABLE} to a '
            'folder of the tarballs named in tools/ros2_upstream.py and run make setup '
            'again.')
        return
    origins = sorted({str(Path(origin).parent) if '://' not in origin else 'GitHub'
                      for _, origin in fetched})
    for stale in ('build', 'install'):
        shutil.rmtree(ROS2CLI_PREFIX / stale, ignore_errors=True)
    own = sorted(str(p.parent) for p in ROS2CLI_PIP_SRC.glob('*/package.xml'))
    cmd = [str(VENV / 'bin' / 'colcon'), '--log-base', str(ROOT / 'log' / 'colcon'),
           'build', '--merge-install', '--symlink-install', '--base-paths', str(source),
           *own,
           '--build-base', str(ROS2CLI_PREFIX / 'build'),
           '--install-base', str(ROS2CLI_PREFIX / 'install'),
           '--event-handlers', 'console_cohesion-', 'summary+']
    run_logged(cmd, 'colcon-ros2cli', env=ros_env())
    write_stamp('ros2cli', digest)
    say(f'ros2 and ros2 launch built from {", ".join(origins)} in '
        f'{time.monotonic() - started:.0f} s')


def ensure_firmware_micropython() -> None:
    """Install the pinned WebAssembly MicroPython for the firmware tests (npm ci)."""
    firmware = ROOT / 'firmware'
    lock = firmware / 'package-lock.json'
    if not lock.exists():
        return
    if shutil.which('node') is None or shutil.which('npm') is None:
        if read_stamp('firmware-npm') != 'no-node':
            say('node/npm not found: the firmware tests under MicroPython will be skipped '
                '(install Node.js 18 or later and run make setup again)')
            write_stamp('firmware-npm', 'no-node')
        return
    digest = digest_of([lock, firmware / 'package.json'])
    if read_stamp('firmware-npm') == digest and (firmware / 'node_modules').is_dir():
        return
    say('installing MicroPython (WebAssembly) for the firmware tests: npm ci in firmware/')
    run_logged(['npm', 'ci', '--no-audit', '--no-fund'], 'npm-firmware', cwd=firmware)
    write_stamp('firmware-npm', digest)


def main() -> None:
    """Run every setup step that is not already done."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--force', action='store_true', help='rebuild the workspace')
    parser.add_argument('--no-firmware-tests', action='store_true',
                        help="skip the firmware tests' MicroPython (npm ci): the demo "
                        'does not need it')
    args = parser.parse_args()
    check_python()
    # One setup at a time (two terminals, or tests, running `make` at once): the second
    # waits, then finds the work done.
    with open(ROOT / '.bootstrap.lock', 'w') as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        ensure_venv()
        ensure_requirements()
        ensure_overlay()
        ensure_workspace(args.force)
        ensure_ros2cli()
        if not args.no_firmware_tests:
            ensure_firmware_micropython()


if __name__ == '__main__':
    main()
