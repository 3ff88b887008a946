"""
Fault injection in the simulator (pure, no ROS): which faults act when, and what they do.

The simulator takes the 'simulator' faults of :mod:`robot_simulation.faults` (onset
absolute in simulated seconds) and injects each where the real one arises: the
simulation core (:mod:`robot_simulation.simulator`) hands the lidar's ranges to
:class:`ScanFaults`, the IMU and encoder faults to the simulated board's hardware
layer, the traction factors to the physics and the byte faults to the board's serial
line; the node stamps the scans and logs and publishes what changed.

:class:`FaultSchedule` keeps the faults to come and those acting. Its
``next_change_s`` is the next onset or end (``inf``: none), so the simulator's step
costs one comparison while nothing changes, and nothing at all without faults.
:meth:`FaultSchedule.update` returns a :class:`FaultChange` (what started, ended, the
instants due, and the :class:`FaultEffects` of all faults acting now).

How faults of the same kind acting together combine (:func:`effects_of`): the lidar's
and the IMU's silence, blindness and freeze are flags; stamp offsets, IMU biases and
latencies add up; stuck wheels gather; traction factors of one wheel multiply; the
byte drop and bit flip probabilities combine as independent events,
1 - (1 - p1)(1 - p2). A silent lidar publishes nothing; a blinded one +inf everywhere
(also when frozen); a frozen one the scan taken at the freeze's onset.
"""

from dataclasses import dataclass, field
import json
import math
from typing import Any, Dict, FrozenSet, Iterable, List, Mapping, Optional, Sequence, Tuple

import numpy as np
from robot_simulation.faults import (
    FAULT_KINDS, FaultError, FaultSpec, parse_fault, SIMULATOR, WHEELS)

#: An onset taken this much (s) after its time is logged with its time (a late message).
LATE_ONSET_S = 0.05


@dataclass(frozen=True)
class FaultEffects:
    """What the faults acting at one time do together (the defaults: nothing)."""

    lidar_silent: bool = False
    lidar_blinded: bool = False
    lidar_frozen: bool = False
    #: Added to every scan's stamp (s; > 0: in the future).
    scan_stamp_offset_s: float = 0.0
    imu_silent: bool = False
    #: Added to the IMU samples: (gyro z rad/s, accel x m/s^2, accel y m/s^2).
    imu_bias: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: Indices (FL 0, FR 1, RL 2, RR 3) of the wheels whose encoder count holds still.
    stuck_wheels: FrozenSet[int] = frozenset()
    #: Each wheel's share of the floor's friction, FL FR RL RR.
    traction_factors: Tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    #: Per byte on the board's serial line, both ways: lost, one bit flipped.
    serial_drop_rate: float = 0.0
    serial_flip_rate: float = 0.0
    #: Delay of every byte on the board's serial line (s).
    serial_latency_s: float = 0.0

    def imu_bias_sample(self) -> Optional[Tuple[float, ...]]:
        """Return the bias of a (ax, ay, az, gx, gy, gz) sample, None when there is none."""
        gyro_z, accel_x, accel_y = self.imu_bias
        if gyro_z == accel_x == accel_y == 0.0:
            return None
        return (accel_x, accel_y, 0.0, 0.0, 0.0, gyro_z)


#: No fault acting.
NO_EFFECTS = FaultEffects()


def effects_of(faults: Iterable[FaultSpec]) -> FaultEffects:
    """Return what these (acting) faults do together; instants (kidnap) do nothing here."""
    flags = set()
    offset = 0.0
    bias = [0.0, 0.0, 0.0]
    stuck = set()
    traction = [1.0, 1.0, 1.0, 1.0]
    keep_drop = keep_flip = 1.0
    latency = 0.0
    for fault in faults:
        kind = fault.kind
        if kind in ('lidar_silent', 'lidar_blinded', 'lidar_frozen', 'imu_silent'):
            flags.add(kind)
        elif kind == 'scan_stamp_skew':
            offset += fault.param('offset_s')
        elif kind == 'imu_bias':
            bias[0] += fault.param('gyro_z_rad_s')
            bias[1] += fault.param('accel_x_m_s2')
            bias[2] += fault.param('accel_y_m_s2')
        elif kind == 'encoder_stuck':
            stuck.add(WHEELS.index(fault.param('wheel')))
        elif kind == 'wheel_slip':
            traction[WHEELS.index(fault.param('wheel'))] *= fault.param('traction_factor')
        elif kind == 'serial_drop_bytes':
            keep_drop *= 1.0 - fault.param('rate')
        elif kind == 'serial_bit_flips':
            keep_flip *= 1.0 - fault.param('rate')
        elif kind == 'serial_latency':
            latency += fault.param('latency_s')
    return FaultEffects(
        lidar_silent='lidar_silent' in flags, lidar_blinded='lidar_blinded' in flags,
        lidar_frozen='lidar_frozen' in flags, scan_stamp_offset_s=offset,
        imu_silent='imu_silent' in flags, imu_bias=tuple(bias), stuck_wheels=frozenset(stuck),
        traction_factors=tuple(traction), serial_drop_rate=1.0 - keep_drop,
        serial_flip_rate=1.0 - keep_flip, serial_latency_s=latency)


class ScanFaults:
    """The lidar's faults on its output: holds the scan a freeze keeps publishing."""

    def __init__(self):
        self.frozen: Optional[np.ndarray] = None

    def apply(self, effects: FaultEffects, ranges: np.ndarray) -> Optional[np.ndarray]:
        """
        Return the ranges the faulty lidar gives for a scan of ranges (None: no scan).

        While frozen, the first scan taken (the onset's) is returned again and again;
        a freeze that ends forgets it. Blinded: every range +inf (REP-117: no return).
        """
        if effects.lidar_frozen:
            if self.frozen is None:
                self.frozen = ranges.copy()
            ranges = self.frozen
        else:
            self.frozen = None
        if effects.lidar_silent:
            return None
        if effects.lidar_blinded:
            return np.full_like(ranges, np.inf)
        return ranges


def kidnap_target(pose: Sequence[float], fault: FaultSpec) -> Tuple[float, float, float]:
    """Return the pose (x, y, yaw) a kidnap moves pose to: (dx, dy) in the world, dyaw."""
    x, y, yaw = pose
    yaw += fault.param('dyaw_rad')
    return (x + fault.param('dx_m'), y + fault.param('dy_m'),
            math.atan2(math.sin(yaw), math.cos(yaw)))


def _seconds(time_s: float) -> str:
    """Return a simulated time for a log line: to the millisecond, '12.0' for 12 s."""
    return str(round(time_s, 3))


def _label(fault: FaultSpec) -> str:
    """Return 'kind' or 'kind (param value, ...)'."""
    params = ', '.join(f'{name} {value:g}' if isinstance(value, float) else f'{name} {value}'
                       for name, value in fault.params)
    return f'{fault.kind} ({params})' if params else fault.kind


@dataclass
class FaultChange:
    """What changed at time_s: faults started, ended, instants due; effects from now on."""

    time_s: float
    started: List[FaultSpec] = field(default_factory=list)
    ended: List[FaultSpec] = field(default_factory=list)
    #: Instant faults (kidnap) due now; the simulator applies or refuses them.
    instants: List[FaultSpec] = field(default_factory=list)
    active: Tuple[FaultSpec, ...] = ()
    effects: FaultEffects = NO_EFFECTS
    #: What became of each instant: (fault, None when applied or the reason it was refused,
    #: a text saying what happened). Filled in by the simulator.
    outcomes: List[Tuple[FaultSpec, Optional[str], str]] = field(default_factory=list)

    def log_lines(self) -> List[Tuple[str, str]]:
        """Return (level 'info' or 'error', text) of each onset, end and instant."""
        now = _seconds(self.time_s)
        lines = []
        for fault in self.ended:
            lines.append(('info', f'fault {_label(fault)} off at {now} s'))
        for fault in self.started:
            span = ('until the end' if fault.duration_s is None
                    else f'for {fault.duration_s:g} s')
            late = ('' if self.time_s - fault.onset_s < LATE_ONSET_S
                    else f' (onset {_seconds(fault.onset_s)} s)')
            lines.append(('info', f'fault {_label(fault)} on at {now} s {span}{late}'))
        for fault, refused, text in self.outcomes:
            lines.append(('error' if refused else 'info', f'fault {_label(fault)} at {now} s: '
                          f'{text}'))
        return lines

    def report(self) -> Dict[str, Any]:
        """Return the plain mapping published on the simulator's active faults topic."""
        return {'time_s': round(self.time_s, 6),
                'active': [fault.as_dict() for fault in self.active],
                'started': [fault.as_dict() for fault in self.started],
                'ended': [fault.as_dict() for fault in self.ended],
                'instants': [dict(fault.as_dict(), applied=refused is None, outcome=text)
                             for fault, refused, text in self.outcomes]}


class _Entry:
    """A scheduled fault and whether its onset has been reported."""

    __slots__ = ('fault', 'started')

    def __init__(self, fault: FaultSpec):
        self.fault = fault
        self.started = False


class FaultSchedule:
    """
    The simulator's faults: those to come and those acting, in simulated time.

    :meth:`add` schedules a fault; call :meth:`update` when the simulated time has
    reached ``next_change_s``. A fault acts while ``FaultSpec.active(now)``; an
    instant fault is due once, at the first update at or after its onset.
    """

    def __init__(self):
        self._entries: List[_Entry] = []
        self.active: Tuple[FaultSpec, ...] = ()
        self.effects = NO_EFFECTS
        #: Simulated time of the next onset or end (inf: nothing scheduled).
        self.next_change_s = math.inf

    def add(self, fault: FaultSpec, now_s: float) -> Optional[str]:
        """
        Schedule a simulator fault at simulated time now_s; return None or why it is not.

        A fault whose end has passed already is not scheduled (the reason is returned);
        one whose onset has passed starts at the next update. Raises FaultError for a
        fault the simulator does not inject (a 'runner' kind).
        """
        if fault.where != SIMULATOR:
            raise FaultError(f'{fault.kind} is injected by the scenario runner, not by the '
                             'simulator')
        instant = FAULT_KINDS[fault.kind].instant
        if (not instant and fault.duration_s is not None
                and fault.onset_s + fault.duration_s <= now_s):
            return (f'fault {fault.describe()} is over already at {_seconds(now_s)} s: '
                    'not injected')
        self._entries.append(_Entry(fault))
        self.next_change_s = min(self.next_change_s, fault.onset_s)
        return None

    @property
    def pending(self) -> Tuple[FaultSpec, ...]:
        """Return the faults scheduled and not over, acting or to come, in arrival order."""
        return tuple(entry.fault for entry in self._entries)

    def update(self, now_s: float) -> Optional[FaultChange]:
        """Take the onsets, ends and instants due by now_s; None when nothing changed."""
        if now_s < self.next_change_s:
            return None
        change = FaultChange(now_s)
        kept = []
        active = []
        next_change = math.inf
        for entry in self._entries:
            fault = entry.fault
            if now_s < fault.onset_s:
                kept.append(entry)
                next_change = min(next_change, fault.onset_s)
            elif FAULT_KINDS[fault.kind].instant:
                change.instants.append(fault)
            elif fault.active(now_s):
                if not entry.started:
                    entry.started = True
                    change.started.append(fault)
                kept.append(entry)
                active.append(fault)
                if fault.duration_s is not None:
                    next_change = min(next_change, fault.onset_s + fault.duration_s)
            else:   # over (one shorter than the time between two updates starts and ends)
                if not entry.started:
                    change.started.append(fault)
                change.ended.append(fault)
        self._entries = kept
        self.next_change_s = next_change
        if not (change.started or change.ended or change.instants):
            return None
        self.active = tuple(active)
        self.effects = effects_of(active) if active else NO_EFFECTS
        change.active = self.active
        change.effects = self.effects
        return change


def parse_fault_message(text: str) -> List[FaultSpec]:
    """
    Return the faults of one control message: a JSON object or a list of them.

    Each object is parse_fault's mapping with onset_s absolute in simulated seconds.
    All or nothing: raises FaultError naming the offending fault (``faults[2].rate``)
    for bad JSON, a bad fault, or one the simulator does not inject (a 'runner' kind).
    """
    try:
        raw = json.loads(text)
    except ValueError as error:
        raise FaultError(f'not JSON ({error})') from None
    if isinstance(raw, Mapping):
        items = [('fault', raw)]
    elif isinstance(raw, list) and raw:
        items = [(f'faults[{index}]', item) for index, item in enumerate(raw)]
    else:
        raise FaultError('must be a JSON object (a fault) or a non-empty list of them, '
                         f'not {text[:80]!r}')
    faults = []
    for where, item in items:
        fault = parse_fault(item, where)
        if fault.where != SIMULATOR:
            raise FaultError(f'{where}.kind: {fault.kind} is injected by the scenario runner, '
                             'not by the simulator')
        faults.append(fault)
    return faults
