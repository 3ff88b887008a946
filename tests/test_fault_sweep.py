"""
Integration: a few variants of the fault sweep (sweeps/faults.yaml) in make test.

The whole fault sweep (126 variants) runs with `run_sweep ... --jobs 2`; here three of
its faults run the same way, through run_sweep, on the teleop-along-a-wall scenario with
the whole simulated robot in lockstep: a blinded lidar while the robot is pushed into
the wall, the zone guard killed, and the e-stop pressed and released. Each variant must
keep the safety invariants (no collision, the footprint in the zone, its least clearance
reported), and pass its fault_reaction criterion (mecanum_bringup.fault_reactions, as
docs/failure_modes.md gives it): at rest within the fault's delay and the chain stage
saying why (collision_monitor "scan blinded", twist_mux "e_stop"; the zone guard's kill
stops the wheels through motor_controller's watchdog, simulated time running on while it
is down). The system log shows what the criterion cannot see: the zone guard respawned,
motor_controller's latch.
"""

import json
from pathlib import Path
import sqlite3
import subprocess
import sys

import pytest

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
SCENARIO = REPO / 'src/mecanum_bringup/scenarios/fault_teleop_near_walls.yaml'
SWEEP = f"""
sweep:
  name: faults_in_ci
  axes:
    scenario: [{SCENARIO}]
    fault:
    - {{kind: lidar_blinded, duration_s: 5.0}}
    - {{kind: node_killed, node: zone_guard}}
    - {{kind: estop, duration_s: 3.0}}
    fault_onset_s: [2.0]
"""
#: What each variant's system log must show (docs/failure_modes.md).
REACTIONS = {
    'lidar_blinded': 'invalid source: scan blinded',
    'node_killed': 'zone_guard',
    'estop': 'EMERGENCY STOP',
}


@pytest.mark.long
def test_three_faults_keep_the_robot_safe_and_react_as_documented(tmp_path, marked_env):
    sweep = tmp_path / 'faults_in_ci.yaml'
    sweep.write_text(SWEEP)
    out = tmp_path / 'out'
    result = subprocess.run(
        [sys.executable, '-m', 'mecanum_bringup.sweep_runner', str(sweep), '--out', str(out),
         '--quiet', '--jobs', '2'], capture_output=True, text=True, timeout=900,
        env=marked_env.env)
    print(result.stdout[-3000:], result.stderr[-3000:])
    db = sqlite3.connect(out / 'results.sqlite')
    try:
        rows = db.execute('SELECT idx, status, min_zone_clearance_m FROM variants').fetchall()
    finally:
        db.close()
    assert len(rows) == 3, rows
    runs = sorted(path for path in (out / 'runs').iterdir() if path.is_dir())
    assert len(runs) == 3
    for run in runs:
        summary = json.loads((run / 'summary.json').read_text())
        criteria = {c['name']: c for c in summary['criteria']}
        assert summary['collisions'] == 0, (run.name, criteria['no_collision'])
        assert criteria['stay_in_zone']['passed'], (run.name, criteria['stay_in_zone'])
        assert summary['min_zone_clearance_m'] >= 0.0
        [fault] = summary['faults']
        assert fault['began_s'] is not None, fault
        assert criteria['fault_reaction']['passed'], (run.name, criteria['fault_reaction'])
        assert 'at rest' in criteria['fault_reaction']['detail'], run.name
        log = (run / 'system.log').read_text()
        assert REACTIONS[fault['kind']] in log, (run.name, fault['kind'])
        if fault['kind'] == 'node_killed':
            # The launch runner restarts the killed node (respawn), which starts again.
            assert log.count('Zone guard started') >= 2, run.name
    assert all(clearance is not None and clearance >= 0.0 for _, _, clearance in rows)
