"""Tests of ROS domain leasing across real processes."""

import os
import random
import subprocess
import sys
import textwrap
import time

from mecanum_bringup.isolation import (
    current_domain_id, isolated_environment, LEASABLE_DOMAIN_IDS, lease_domain_id,
    processes_with_variable)


def test_leases_in_one_process_differ_and_are_released():
    with lease_domain_id(random.Random(1)) as first, lease_domain_id(random.Random(1)) as second:
        assert first.domain_id != second.domain_id
        assert first.domain_id in LEASABLE_DOMAIN_IDS and second.domain_id in LEASABLE_DOMAIN_IDS
        taken = first.domain_id
    # Released: the same random order hands out the same domain again.
    with lease_domain_id(random.Random(1)) as again:
        assert again.domain_id == taken


def test_domain_held_by_another_process_is_not_handed_out():
    holder = subprocess.Popen([sys.executable, '-c', textwrap.dedent("""
        import random, sys, time
        from mecanum_bringup.isolation import lease_domain_id
        lease = lease_domain_id(random.Random(7))
        print(lease.domain_id, flush=True)
        sys.stdin.read()
        """)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        held = int(holder.stdout.readline())
        with lease_domain_id(random.Random(7)) as mine:
            assert mine.domain_id != held
    finally:
        holder.stdin.close()
        holder.wait(timeout=10)


def test_isolated_environment_defaults_to_localhost_but_respects_user_choice():
    expected = {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'ROS_DOMAIN_ID': '42'}
    assert isolated_environment({}, 42) == expected
    user = {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET', 'ROS_DOMAIN_ID': '3'}
    assert isolated_environment(user) == user
    assert current_domain_id(user) == 3 and current_domain_id({}) == 0


def test_processes_are_found_by_a_variable_in_their_environment():
    env = dict(os.environ, MECANUM_ISOLATION_TEST='run-1')
    child = subprocess.Popen(['sleep', '30'], env=env)
    try:
        # Popen returns once exec has begun; the kernel fills in the new program's
        # environment a moment later (seen empty on a loaded CI machine), so wait for it.
        deadline = time.monotonic() + 10
        while not processes_with_variable('MECANUM_ISOLATION_TEST') and (
                time.monotonic() < deadline):
            time.sleep(0.01)
        assert processes_with_variable('MECANUM_ISOLATION_TEST', 'run-1') == [child.pid]
        assert processes_with_variable('MECANUM_ISOLATION_TEST') == [child.pid]
        assert processes_with_variable('MECANUM_ISOLATION_TEST', 'run-2') == []
    finally:
        child.kill()
        child.wait()
    assert processes_with_variable('MECANUM_ISOLATION_TEST') == []
