"""
The upstream ROS 2 Jazzy packages the pip setup builds: the `ros2` command and `ros2 launch`.

ros2cli (the `ros2` command and its verbs topic, node, param, service, action, interface,
pkg, run), rosidl_runtime_py (which they need), launch, launch_yaml, launch_xml,
launch_ros and ros2launch are pure Python but not on PyPI. tools/bootstrap.py builds them
with colcon into ``.venv/ros2cli/install`` from their upstream sources, pinned below by
commit and by a digest of their files, taken from the first of:

1. ``$MECANUM_ROS2_SOURCES``: a folder holding the tarballs named below (``git archive``
   of each package's folder at its commit, as ``../shared/vendor`` has them);
2. a ``shared/vendor`` folder beside the repository or in a folder above it;
3. GitHub: ``https://codeload.github.com/<owner>/<repo>/tar.gz/<commit>`` (cached in
   ``.venv/ros2cli/downloads``).

A source whose files do not match the pinned digest is refused, naming the package. An
apt ROS install has all of these already and never runs this. Only the standard library.
"""

from dataclasses import dataclass
import hashlib
import os
from pathlib import Path
import shutil
import tarfile
from typing import Dict, Iterable, List, Optional, Tuple
import urllib.error
import urllib.request


@dataclass(frozen=True)
class UpstreamPackage:
    """One ament_python package: where upstream keeps it, and what its files must be."""

    name: str
    repo: str            # owner/name on GitHub
    folder: str          # the package's folder in the repository ('' = the root)
    commit: str
    tarball: str         # the local tarball's file name (git archive of the folder)
    tree_sha256: str     # tree_digest() of the package's files


_LAUNCH = '09403fcebedb68dd259e9ab6b35bd8712b6596ec'
_LAUNCH_ROS = '62c56e53e86812023697fe330c83d327f54e7b18'
_ROS2CLI = 'de6cd27284937044d8dff47a617581c28865210c'
_RUNTIME_PY = 'df2361f64ecb85f65f4bf22e804424e0f1ac4197'

PACKAGES: Tuple[UpstreamPackage, ...] = (
    UpstreamPackage('rosidl_runtime_py', 'ros2/rosidl_runtime_py', '', _RUNTIME_PY,
                    'ros2-rosidl_runtime_py-jazzy-0.13.1.tar.gz',
                    '5d7c36b77376a799dbbee545bbf899013da3a37d447add344d6c6067b8873ebc'),
    UpstreamPackage('ros2cli', 'ros2/ros2cli', 'ros2cli', _ROS2CLI,
                    'ros2-ros2cli-ros2cli-jazzy-0.32.2.tar.gz',
                    'de1728309e5ed21a32a8f2a8dec971cb5efc7744fad3ede36575078bf3b0ae64'),
    UpstreamPackage('ros2topic', 'ros2/ros2cli', 'ros2topic', _ROS2CLI,
                    'ros2-ros2cli-ros2topic-jazzy-0.32.2.tar.gz',
                    'd96e3bb8c7584ac44551ca1979b7aaf65b2967603a44acefe89e8f9bdb94d8db'),
    UpstreamPackage('ros2node', 'ros2/ros2cli', 'ros2node', _ROS2CLI,
                    'ros2-ros2cli-ros2node-jazzy-0.32.2.tar.gz',
                    'c50401afb521851ec83fe8e6906c280c397252435df58af8c7bbbba5ce811610'),
    UpstreamPackage('ros2param', 'ros2/ros2cli', 'ros2param', _ROS2CLI,
                    'ros2-ros2cli-ros2param-jazzy-0.32.2.tar.gz',
                    '1918917fa55e7c719b9dce41fcb1456086f5c06094464a759fe854ae0f9fac0d'),
    UpstreamPackage('ros2service', 'ros2/ros2cli', 'ros2service', _ROS2CLI,
                    'ros2-ros2cli-ros2service-jazzy-0.32.2.tar.gz',
                    'a8b347b9c89ca241e3d78f63c7ba5ddf6829f91f5d85c05c53519a5594b4685a'),
    UpstreamPackage('ros2action', 'ros2/ros2cli', 'ros2action', _ROS2CLI,
                    'ros2-ros2cli-ros2action-jazzy-0.32.2.tar.gz',
                    'b3ce1bd727abe5e4d38a5be39a5096db520f8a140a6b0538f385b4406e6c5b28'),
    UpstreamPackage('ros2interface', 'ros2/ros2cli', 'ros2interface', _ROS2CLI,
                    'ros2-ros2cli-ros2interface-jazzy-0.32.2.tar.gz',
                    '4f8b3f26f3d93527f5d0175b2426900b280701c24cb1c619f5ab9b2eaafc472a'),
    UpstreamPackage('ros2pkg', 'ros2/ros2cli', 'ros2pkg', _ROS2CLI,
                    'ros2-ros2cli-ros2pkg-jazzy-0.32.2.tar.gz',
                    '4f221602467c21c5cc88da4fc180b1aa381fa0e0cb72ab87e4cfe20e20fbdb6d'),
    UpstreamPackage('ros2run', 'ros2/ros2cli', 'ros2run', _ROS2CLI,
                    'ros2-ros2cli-ros2run-jazzy-0.32.2.tar.gz',
                    '7e582cb14531a6d03373b26aee8acc46fedb87e6b23246bccbb4f62179fdb054'),
    UpstreamPackage('launch', 'ros2/launch', 'launch', _LAUNCH,
                    'ros2-launch-jazzy-3.4.3.tar.gz',
                    'c9da23cea2eedfa49d0c31b149a55c9ddfee8479f2de74fb5f47ab1c5cc93542'),
    UpstreamPackage('launch_yaml', 'ros2/launch', 'launch_yaml', _LAUNCH,
                    'ros2-launch_yaml-jazzy-3.4.3.tar.gz',
                    '7e48717caf43c5fc4a9c7a93063741cfb6dd80406257cb564ac4913c19da951f'),
    UpstreamPackage('launch_xml', 'ros2/launch', 'launch_xml', _LAUNCH,
                    'ros2-launch_xml-jazzy-3.4.3.tar.gz',
                    '1688ed97dd1cab6599fa568ec9ebc944d8dcc70820cd0a297fe648a2159512e2'),
    UpstreamPackage('launch_ros', 'ros2/launch_ros', 'launch_ros', _LAUNCH_ROS,
                    'ros2-launch_ros-jazzy-0.26.6.tar.gz',
                    '0a3ec633b75cc65b1278f491f29e97afbd9acb4383a17421111952dcd5ed673e'),
    UpstreamPackage('ros2launch', 'ros2/launch_ros', 'ros2launch', _LAUNCH_ROS,
                    'ros2-launch_ros-ros2launch-jazzy-0.26.6.tar.gz',
                    '67c74871a3e4c33fb9e61b4740968fc2ae545ad36d16f5c7e30c358775ce1d46'),
)

#: The environment variable naming a local folder of the tarballs.
SOURCES_VARIABLE = 'MECANUM_ROS2_SOURCES'
#: Seconds to wait for GitHub before giving up on a download.
DOWNLOAD_TIMEOUT_S = 30.0


class SourceError(RuntimeError):
    """No usable source for a package (the message says where it looked and why)."""


def tree_digest(files: Dict[str, bytes]) -> str:
    """Return the SHA-256 of a package's files: sorted (relative path, SHA-256 of bytes)."""
    sha = hashlib.sha256()
    for name in sorted(files):
        sha.update(name.encode() + b'\0' + hashlib.sha256(files[name]).digest())
    return sha.hexdigest()


def tarball_files(path: Path, prefix: str) -> Dict[str, bytes]:
    """Return {path below prefix: bytes} of the regular files under prefix in a tarball."""
    files = {}
    prefix = prefix.strip('/') + '/'
    with tarfile.open(path) as archive:
        for member in archive.getmembers():
            if member.isfile() and member.name.startswith(prefix):
                files[member.name[len(prefix):]] = archive.extractfile(member).read()
    return files


def local_folders(root: Path) -> List[Path]:
    """Return the local tarball folders to try, in order ($MECANUM_ROS2_SOURCES first)."""
    folders = []
    if os.environ.get(SOURCES_VARIABLE):
        folders.append(Path(os.environ[SOURCES_VARIABLE]))
    for parent in [root, *root.parents]:
        candidate = parent / 'shared' / 'vendor'
        if candidate.is_dir():
            folders.append(candidate)
            break
    return folders


def _local_files(package: UpstreamPackage, folders: Iterable[Path]) -> Optional[
        Tuple[Dict[str, bytes], str]]:
    for folder in folders:
        path = folder / package.tarball
        if path.is_file():
            # git archive of the package's folder: the files are under '<folder name>/'.
            top = package.folder or package.name
            return tarball_files(path, top), str(path)
    return None


def _downloaded_files(package: UpstreamPackage, cache: Path) -> Tuple[Dict[str, bytes], str]:
    owner, repo = package.repo.split('/')
    cache.mkdir(parents=True, exist_ok=True)
    path = cache / f'{repo}-{package.commit}.tar.gz'
    url = f'https://codeload.github.com/{package.repo}/tar.gz/{package.commit}'
    if not path.is_file():
        partial = path.with_suffix('.part')
        try:
            with urllib.request.urlopen(url, timeout=DOWNLOAD_TIMEOUT_S) as answer, \
                    open(partial, 'wb') as out:
                shutil.copyfileobj(answer, out)
        except (urllib.error.URLError, OSError) as error:
            partial.unlink(missing_ok=True)
            raise SourceError(f'{package.name}: cannot download {url}: {error}') from None
        partial.rename(path)
    prefix = f'{repo}-{package.commit}' + (f'/{package.folder}' if package.folder else '')
    return tarball_files(path, prefix), url


def fetch_sources(root: Path, cache: Path, destination: Path,
                  say=print) -> List[Tuple[UpstreamPackage, str]]:
    """
    Write every package's checked files under destination/<name>; return (package, origin).

    Raises SourceError naming the package when no source has it or a source's files do
    not match its pinned digest.
    """
    folders = local_folders(root)
    fetched = []
    for package in PACKAGES:
        found = _local_files(package, folders)
        if found is None:
            where = ', '.join(str(f) for f in folders) or 'no local folder'
            say(f'{package.name}: not in {where}; downloading commit {package.commit[:12]} '
                f'of {package.repo}')
            found = _downloaded_files(package, cache)
        files, origin = found
        digest = tree_digest(files)
        if digest != package.tree_sha256:
            raise SourceError(
                f'{package.name}: the files of {origin} ({len(files)} files) are not those '
                f'of commit {package.commit[:12]} of {package.repo} (digest {digest[:16]}, '
                f'expected {package.tree_sha256[:16]})')
        target = destination / package.name
        if target.exists():
            shutil.rmtree(target)
        for name, data in files.items():
            path = target / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
        fetched.append((package, origin))
    return fetched
