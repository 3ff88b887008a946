"""
The fault vocabulary of the simulated robot (pure, no ROS): what can be injected, and where.

One vocabulary for scenario files (the ``fault:`` step), sweep files (the ``fault`` axis)
and the simulator, which injects each fault where the real one arises: the simulated
sensors (lidar, IMU, encoders), the simulated wheels and body, and the simulated board's
serial line. Faults of the processes (a node frozen or killed) and of the operator (the
e-stop) are applied by the scenario runner; they are part of the same vocabulary so that a
sweep can draw any of them.

A fault is a :class:`FaultSpec`: a kind (one of :data:`FAULT_KINDS`), an onset (simulated
s; absolute in the simulator, relative to its step in a scenario file), a duration
(simulated s; ``None``: until the end of the run) and the kind's parameters (units in
their names). ``parse_fault`` checks a plain mapping (from YAML or JSON) and names the
offending key in its error. Wheel names follow the robot's wheel order FL, FR, RL, RR.
"""

from dataclasses import dataclass, field
import math
from typing import Any, Dict, Mapping, Optional, Tuple

#: Where each kind is injected: 'simulator' (sensors, wheels, body, serial line),
#: 'runner' (processes and the operator's e-stop, by the scenario runner).
SIMULATOR = 'simulator'
RUNNER = 'runner'

WHEELS = ('FL', 'FR', 'RL', 'RR')


@dataclass(frozen=True)
class FaultKind:
    """One kind of fault: where it is injected, its parameters and their defaults."""

    name: str
    where: str
    description: str
    #: parameter name -> default (None: required). Numbers are floats; 'wheel' and
    #: 'node' are strings.
    params: Dict[str, Any] = field(default_factory=dict)
    #: True when the fault is an instant (kidnap, node_killed, amcl_diverged): its
    #: duration must be 0.
    instant: bool = False


FAULT_KINDS: Dict[str, FaultKind] = {kind.name: kind for kind in (
    FaultKind('lidar_blinded', SIMULATOR,
              'every range of every scan is +inf (a covered or dazzled lidar)'),
    FaultKind('lidar_frozen', SIMULATOR,
              'the scan taken at onset is published again and again, with new stamps'),
    FaultKind('lidar_silent', SIMULATOR, 'no scan is published (an unplugged lidar)'),
    FaultKind('scan_stamp_skew', SIMULATOR,
              'scans are stamped offset_s later (> 0: in the future) than taken',
              {'offset_s': None}),
    FaultKind('imu_silent', SIMULATOR, 'the board reports no IMU sample'),
    FaultKind('imu_bias', SIMULATOR, 'constant biases are added to the IMU samples',
              {'gyro_z_rad_s': 0.0, 'accel_x_m_s2': 0.0, 'accel_y_m_s2': 0.0}),
    FaultKind('encoder_stuck', SIMULATOR, "one wheel's encoder count stops changing",
              {'wheel': None}),
    FaultKind('wheel_slip', SIMULATOR,
              "one wheel's grip is traction_factor of the floor's: it slips once its force "
              'exceeds that share of the friction limit',
              {'wheel': None, 'traction_factor': 0.2}),
    FaultKind('kidnap', SIMULATOR,
              'the true robot is moved by (dx_m, dy_m, dyaw_rad) in the world at onset; '
              'no sensor or estimate is told', {'dx_m': 0.0, 'dy_m': 0.0, 'dyaw_rad': 0.0},
              instant=True),
    FaultKind('serial_bit_flips', SIMULATOR,
              'each byte on the board link (both ways) has one bit flipped with '
              'probability rate', {'rate': None}),
    FaultKind('serial_drop_bytes', SIMULATOR,
              'each byte on the board link (both ways) is lost with probability rate',
              {'rate': None}),
    FaultKind('serial_latency', SIMULATOR,
              'every byte on the board link arrives latency_s late', {'latency_s': None}),
    FaultKind('node_frozen', RUNNER, 'the process running node is stopped (SIGSTOP)',
              {'node': None}),
    FaultKind('node_killed', RUNNER, 'the process running node is killed (SIGKILL)',
              {'node': None}, instant=True),
    FaultKind('amcl_diverged', RUNNER,
              "amcl's particles are spread over the whole map (its "
              'reinitialize_global_localization service): the covariance explodes and the '
              'estimate wanders until the particles converge again, maybe elsewhere',
              instant=True),
    FaultKind('estop', RUNNER,
              'the operator presses the e-stop (emergency_stop true) and releases it '
              '(false) duration_s later'),
)}


class FaultError(ValueError):
    """A fault that is not in the vocabulary, or whose parameters are wrong."""


@dataclass(frozen=True)
class FaultSpec:
    """A fault of kind from onset_s for duration_s (None: to the end), with its params."""

    kind: str
    onset_s: float = 0.0
    duration_s: Optional[float] = None
    params: Tuple[Tuple[str, Any], ...] = ()

    @property
    def where(self) -> str:
        """Return who injects it: SIMULATOR or RUNNER."""
        return FAULT_KINDS[self.kind].where

    def param(self, name: str) -> Any:
        """Return the value of one parameter (its default when not given)."""
        return dict(self.params).get(name, FAULT_KINDS[self.kind].params.get(name))

    def active(self, now_s: float) -> bool:
        """Tell whether the fault acts at simulated time now_s."""
        if now_s < self.onset_s:
            return False
        return self.duration_s is None or now_s < self.onset_s + self.duration_s

    def as_dict(self) -> Dict[str, Any]:
        """Return the plain mapping parse_fault reads (for JSON, YAML and reports)."""
        out: Dict[str, Any] = {'kind': self.kind, 'onset_s': self.onset_s,
                               'duration_s': self.duration_s}
        out.update(dict(self.params))
        return out

    def describe(self) -> str:
        """Return a short text such as 'lidar_blinded at 5 s for 3 s'."""
        params = ', '.join(f'{name} {value}' for name, value in self.params)
        span = ('' if FAULT_KINDS[self.kind].instant else
                ' to the end' if self.duration_s is None else f' for {self.duration_s:g} s')
        return (f'{self.kind}{f" ({params})" if params else ""} at {self.onset_s:g} s'
                f'{span}')


def parse_fault(raw: Mapping[str, Any], where: str = 'fault') -> FaultSpec:
    """
    Return the FaultSpec of a mapping {kind, onset_s?, duration_s?, <params>}.

    Raises FaultError naming ``where`` and the key for an unknown kind or key, a missing
    parameter, a non-finite or negative time, or a bad value.
    """
    if not isinstance(raw, Mapping):
        raise FaultError(f'{where}: must be a mapping with a kind, not {raw!r}')
    kind_name = raw.get('kind')
    if not isinstance(kind_name, str) or kind_name not in FAULT_KINDS:
        raise FaultError(f'{where}.kind: must be one of {", ".join(FAULT_KINDS)}, '
                         f'not {kind_name!r}')
    kind = FAULT_KINDS[kind_name]
    allowed = ('kind', 'onset_s', 'duration_s') + tuple(kind.params)
    for key in raw:
        if key not in allowed:
            raise FaultError(f'{where}.{key}: unknown key for {kind_name} '
                             f'(allowed: {", ".join(allowed)})')
    onset = _time(raw.get('onset_s', 0.0), f'{where}.onset_s')
    duration = raw.get('duration_s')
    if kind.instant:
        if duration not in (None, 0, 0.0):
            raise FaultError(f'{where}.duration_s: {kind_name} is an instant, not {duration!r}')
        duration = 0.0
    elif duration is not None:
        duration = _time(duration, f'{where}.duration_s')
        if duration <= 0.0:
            raise FaultError(f'{where}.duration_s: must be > 0 (or null: to the end), '
                             f'not {duration:g}')
    params = []
    for name, default in kind.params.items():
        value = raw.get(name, default)
        key = f'{where}.{name}'
        if value is None:
            raise FaultError(f'{key}: required for {kind_name}')
        params.append((name, _param(name, value, key)))
    return FaultSpec(kind_name, onset, duration, tuple(params))


def _time(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(
            value) or value < 0.0:
        raise FaultError(f'{key}: must be a finite number of seconds >= 0, not {value!r}')
    return float(value)


def _param(name: str, value: Any, key: str) -> Any:
    if name == 'wheel':
        if value not in WHEELS:
            raise FaultError(f'{key}: must be one of {", ".join(WHEELS)}, not {value!r}')
        return value
    if name == 'node':
        if not isinstance(value, str) or not value.strip():
            raise FaultError(f'{key}: must be a node name, not {value!r}')
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(
            value):
        raise FaultError(f'{key}: must be a finite number, not {value!r}')
    value = float(value)
    if name == 'rate' and not 0.0 < value <= 1.0:
        raise FaultError(f'{key}: must be a probability in (0, 1], not {value:g}')
    if name == 'traction_factor' and not 0.0 <= value < 1.0:
        raise FaultError(f'{key}: must be in [0, 1), not {value:g}')
    if name == 'latency_s' and not 0.0 < value <= 1.0:
        raise FaultError(f'{key}: must be in (0, 1] s, not {value:g}')
    return value
