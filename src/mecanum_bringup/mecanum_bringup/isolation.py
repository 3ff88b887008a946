"""
Keep ROS 2 systems of this workspace from seeing each other or the network.

Two mechanisms, both standard ROS 2 Jazzy environment variables:

* ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``: DDS discovery stays on this
  machine unless the user configured something else (secure by default).
* ``ROS_DOMAIN_ID``: systems in different domains never exchange messages.
  :func:`lease_domain_id` hands out a domain no other cooperating process on
  this machine holds (a lock file per domain, released when the process ends),
  so parallel test runs and scenarios never see each other.
"""

import fcntl
import os
from pathlib import Path
import random
import tempfile
from typing import Dict, List, Mapping, Optional

# Domain IDs that are valid on Linux with the default DDS port mapping; 0 (the
# default everyone uses) is left out so leased domains never meet stray nodes.
LEASABLE_DOMAIN_IDS = range(1, 102)
LOCK_DIR = Path(tempfile.gettempdir()) / 'mecanum_ros_domains'


class DomainLease:
    """An exclusive claim on one ROS_DOMAIN_ID, held until released or process exit."""

    def __init__(self, domain_id: int, lock_file):
        self.domain_id = domain_id
        self._lock_file = lock_file

    def release(self) -> None:
        """Give the domain back."""
        if self._lock_file is not None:
            fcntl.flock(self._lock_file, fcntl.LOCK_UN)
            self._lock_file.close()
            self._lock_file = None

    def __enter__(self) -> 'DomainLease':
        return self

    def __exit__(self, *exc_info) -> None:
        self.release()


def lease_domain_id(rng: Optional[random.Random] = None) -> DomainLease:
    """
    Claim a ROS_DOMAIN_ID no other process on this machine has claimed.

    Raises RuntimeError when every leasable domain is taken.
    """
    LOCK_DIR.mkdir(parents=True, exist_ok=True)
    candidates = list(LEASABLE_DOMAIN_IDS)
    (rng or random.Random()).shuffle(candidates)
    for domain_id in candidates:
        lock_file = open(LOCK_DIR / f'domain_{domain_id}.lock', 'a')
        try:
            fcntl.flock(lock_file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            lock_file.close()
            continue
        return DomainLease(domain_id, lock_file)
    raise RuntimeError(f'all {len(candidates)} ROS domain IDs are leased by other processes')


def isolated_environment(base: Mapping[str, str], domain_id: Optional[int] = None
                         ) -> Dict[str, str]:
    """Return base with localhost-only discovery (unless already chosen) and a domain."""
    env = dict(base)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    if domain_id is not None:
        env['ROS_DOMAIN_ID'] = str(domain_id)
    return env


def current_domain_id(environ: Mapping[str, str] = os.environ) -> int:
    """Return the ROS_DOMAIN_ID in effect (0 when unset)."""
    return int(environ.get('ROS_DOMAIN_ID', '0') or 0)


def processes_with_variable(name: str, value: Optional[str] = None) -> List[int]:
    """
    Return the PIDs of live processes (not zombies, not this one) with name=value set.

    value None: name set to anything. A run marks its processes this way (a variable in
    the environment they inherit) so that whatever survives it can be found and killed.
    """
    prefix = f'{name}='.encode()
    needle = prefix + value.encode() if value is not None else None
    found = []
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            variables = (entry / 'environ').read_bytes().split(b'\0')
            if needle in variables if needle is not None else any(
                    v.startswith(prefix) for v in variables):
                state = (entry / 'stat').read_text().rsplit(')', 1)[1].split()[0]
                if state != 'Z':
                    found.append(int(entry.name))
        except (FileNotFoundError, ProcessLookupError, PermissionError):
            continue
    return found
