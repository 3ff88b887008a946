"""
Parameters a running node takes at once (``ros2 param set``); every other one read-only.

A node declares its run-time parameters through :class:`RuntimeParameters`, each with
its check (the function the node uses at start-up) and an apply function, adds joint
rules for parameters that are checked or applied together, and calls
:meth:`RuntimeParameters.start` at the end of its constructor::

    runtime = RuntimeParameters(self, {'zone_file': 'restart to change the zone'})
    self.speed = runtime.declare('speed_mps', 0.2, check=positive,
                                 apply=lambda value: setattr(self, 'speed', value))
    runtime.joint(('low', 'high'), check=check_bounds, apply=self.set_bounds)
    runtime.start()

From then on:

* A set of run-time parameters is checked, all parameters of one call together, and
  applied only if every one is valid: all of them or none. ``ros2 param set`` (the
  ``~/set_parameters`` service) sets one parameter per call; set several that a joint
  rule ties together (e.g. robot_controller's blocked_time_s and chain_start_timeout_s,
  which must stay >= it) in one ``set_parameters_atomically`` call, or one at a time in
  an order that keeps the rule. Each change is logged at INFO (``linear_speed_mps 0.2
  -> 0.3``) and applied once rclpy has stored the values (a post-set callback), so a
  call that another callback refuses changes nothing.
* An invalid value is refused with the reason, the start-up check's words:
  ``linear_speed_mps must be > 0, got -1.0``. A value of another type is converted as
  at start-up (an integer for a float, a whole float for an integer) or refused.
* Every other parameter the node has declared when it calls ``start()`` is read-only:
  a set is refused with the node's reason (``wheel_radius_m is read-only: the robot's
  geometry from motor_params.yaml, ...``), and ``ros2 param describe`` shows ``Read
  only: true`` with the reason as the description. ``use_sim_time`` stays settable
  (rclpy's time source takes it).

rclpy refuses a set of a read-only parameter before any callback runs, with its own
words ("Trying to set a read-only parameter"); to give the reason instead, ``start()``
puts a check in front of the node's ``set_parameters`` and ``set_parameters_atomically``
(which the parameter services call) that refuses read-only parameters first.

The decisions are plain functions, unit-tested without ROS: :func:`plan_update`,
:func:`read_only_reason`, :func:`change_text`.
"""

from array import array
from copy import deepcopy
from dataclasses import dataclass, field
from fnmatch import fnmatchcase
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

from mecanum_control.parameters import robot_config_read_only_reason, typed_value
from mecanum_control.robot_config import PARAMETER_KINDS
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.exceptions import ParameterException

#: Parameters neither run-time nor read-only here: rclpy's time source handles them.
EXEMPT = frozenset({'use_sim_time'})
#: Why a parameter declared by rclpy itself is read-only.
RCLPY_REASONS = (
    ('start_type_description_service',
     "rclpy's own setting (the type description service), read when the node starts"),
    ('qos_overrides.*', "rclpy's QoS override, read when the publisher or subscription is "
                        'made'),
)
#: The reason of a read-only parameter that the node gives none for.
DEFAULT_REASON = 'read once when the node starts; restart the node to change it'
#: Reasons the nodes share.
WIRING_REASON = ('a topic, frame or mode the node wired up when it started (subscriptions, '
                 'publishers, transform lookups); restart the node to change it')
PUBLISHER_CHECK_REASON = ('which nodes may publish the topics this node takes (set by the '
                          "launch file for the system's wiring; publisher_check); restart "
                          'to change it')
#: Prefix of a run-time parameter's description (ros2 param describe).
RUNTIME_DESCRIPTION = 'settable at run time (ros2 param set)'

Check = Callable[[str, Any], Any]


def reason_text(error: Exception) -> str:
    """Return an error's text without the start-up messages' 'parameter ' prefix."""
    text = str(error)
    return text[len('parameter '):] if text.startswith('parameter ') else text


def read_only_refusal(name: str, reason: str) -> str:
    """Return the refusal of a set of the read-only parameter name."""
    return f'{name} is read-only: {reason}'


def read_only_reason(name: str, reasons: Iterable[Tuple[str, str]] = ()) -> str:
    """
    Return why parameter name is read-only.

    reasons: (pattern, reason) pairs, fnmatch patterns ('zone_file', 'scan.*'), the
    first that matches wins; then the motor_params.yaml parameters' reasons
    (:func:`mecanum_control.parameters.robot_config_read_only_reason`), rclpy's own
    parameters, and DEFAULT_REASON.
    """
    for pattern, reason in reasons:
        if fnmatchcase(name, pattern):
            return reason
    if name in PARAMETER_KINDS:
        return robot_config_read_only_reason(name)
    for pattern, reason in RCLPY_REASONS:
        if fnmatchcase(name, pattern):
            return reason
    return DEFAULT_REASON


def show_value(value) -> str:
    """Return a parameter value as a log line shows it: 0.3, True, 'map', [1.0, 2.0]."""
    return repr(value) if isinstance(value, str) else str(value)


def change_text(changes: Sequence[Tuple[str, Any, Any]]) -> str:
    """Return the log line of applied changes: 'linear_speed_mps 0.2 -> 0.3, ...'."""
    return ', '.join(f'{name} {show_value(old)} -> {show_value(new)}'
                     for name, old, new in changes)


@dataclass(frozen=True)
class RuntimeParameter:
    """
    A parameter the node takes while it runs.

    kind: float, int, bool, str or list, checked and converted as at start-up
    (:func:`mecanum_control.parameters.typed_value`); None: any value, also none at
    start-up (the check or a joint rule decides). check(name, value): the start-up
    check; returns the value to use (None: the value as it is) or raises ValueError
    saying why not. apply(value): makes the node use the checked value (called only
    with valid values; it must not fail).
    """

    name: str
    kind: Optional[type] = float
    check: Optional[Check] = None
    apply: Optional[Callable[[Any], None]] = None

    def validate(self, value):
        """Return the value to use, or raise ValueError saying why value is refused."""
        if value is None and self.kind is not None:
            raise ValueError(f'parameter {self.name} must be set')
        if isinstance(value, (array, tuple)):   # rclpy's numeric arrays: array('d', ...)
            value = list(value)
        if self.kind is not None:
            value = typed_value(self.name, value, self.kind)
        if self.check is not None:
            checked = self.check(self.name, value)
            if checked is not None:
                value = checked
        return value


@dataclass(frozen=True)
class JointRule:
    """
    Run-time parameters checked or applied together.

    check(values): values maps each of names to its value after the set (the new value
    of those set, the current one of the others); raises ValueError saying why they do
    not go together (e.g. max_margin_m >= margin_m). apply(values): called once per set
    that changes one of names, after the parameters' own apply functions.
    """

    names: Tuple[str, ...]
    check: Optional[Callable[[Dict[str, Any]], Any]] = None
    apply: Optional[Callable[[Dict[str, Any]], None]] = None

    def values(self, values: Mapping[str, Any]) -> Dict[str, Any]:
        """Return this rule's parameters' values from all the run-time values."""
        return {name: values[name] for name in self.names}


@dataclass(frozen=True)
class Update:
    """
    The outcome of one set (:func:`plan_update`).

    reason: why it is refused ('' when it is not). changes: (name, old, new) of the
    parameters whose value changes, in the order of the set. values: every run-time
    parameter's value after it. rules: the joint rules whose parameters change.
    """

    reason: str = ''
    changes: Tuple[Tuple[str, Any, Any], ...] = ()
    values: Dict[str, Any] = field(default_factory=dict)
    rules: Tuple[JointRule, ...] = ()

    @property
    def successful(self) -> bool:
        """Whether the set is accepted."""
        return not self.reason


def plan_update(requests: Sequence[Tuple[str, Any]],
                parameters: Mapping[str, RuntimeParameter],
                values: Mapping[str, Any],
                read_only: Mapping[str, str],
                rules: Sequence[JointRule] = (),
                exempt: Iterable[str] = EXEMPT) -> Update:
    """
    Decide one set of parameters: refuse it (the reason) or say what changes.

    requests: (name, value) in the set's order (value None: unset). parameters: the
    run-time parameters; values: their current values; read_only: name -> reason of
    each read-only parameter. A set naming a read-only parameter, or giving a run-time
    parameter a value its check or a joint rule refuses, is refused as a whole (the
    first problem's reason). Exempt names (use_sim_time) and names the node declared
    after it started (neither run-time nor read-only: rclpy's own rules) are left out.
    """
    exempt = frozenset(exempt)
    new = dict(values)
    requested: List[str] = []
    for name, value in requests:
        if name in exempt:
            continue
        if name in read_only:
            return Update(read_only_refusal(name, read_only[name]), values=dict(values))
        parameter = parameters.get(name)
        if parameter is None:
            continue
        if value is None:   # rclpy would undeclare it
            return Update(f'{name} cannot be unset', values=dict(values))
        try:
            new[name] = parameter.validate(value)
        except ValueError as error:
            return Update(reason_text(error), values=dict(values))
        if name not in requested:
            requested.append(name)
    for rule in rules:
        if rule.check is not None and any(name in requested for name in rule.names):
            try:
                rule.check(rule.values(new))
            except ValueError as error:
                return Update(reason_text(error), values=dict(values))
    changes = tuple((name, values[name], new[name]) for name in requested
                    if not _same(values[name], new[name]))
    changed = {name for name, _, _ in changes}
    touched = tuple(rule for rule in rules if changed.intersection(rule.names))
    return Update('', changes, new, touched)


def _same(old, new) -> bool:
    """Whether a value is unchanged (1 and 1.0 are; True and 1 are not)."""
    return type(old) is type(new) and old == new


class RuntimeParameters:
    """
    The run-time parameters of one node, and the read-only status of the others.

    reasons: (pattern, reason) pairs or a {pattern: reason} mapping, why the node's
    other parameters are read-only (:func:`read_only_reason`; fnmatch patterns).
    """

    def __init__(self, node, reasons=(), exempt: Iterable[str] = EXEMPT):
        """Keep the node; declare() and joint() next, then start()."""
        self.node = node
        self.reasons = tuple(reasons.items() if isinstance(reasons, Mapping) else reasons)
        self.exempt = frozenset(exempt)
        self.parameters: Dict[str, RuntimeParameter] = {}
        self.rules: List[JointRule] = []
        self.values: Dict[str, Any] = {}
        self.read_only: Dict[str, str] = {}
        self.started = False

    def declare(self, name: str, default, check: Optional[Check] = None,
                apply: Optional[Callable[[Any], None]] = None, kind: Any = 'default',
                description: str = ''):
        """
        Declare a run-time parameter and return its start value, checked.

        kind: as RuntimeParameter's; by default the default's type (None for a list or
        None default). The value given at launch is checked as a set is: the check's
        ValueError stops the node (start-up messages say 'parameter NAME ...'; a refused
        set gives the reason without 'parameter ').
        """
        if self.started:
            raise RuntimeError(f'run-time parameter {name} declared after start()')
        if kind == 'default':
            kind = _kind_of(default)
        descriptor = ParameterDescriptor(dynamic_typing=True,
                                         description=_runtime_description(description))
        value = self.node.declare_parameter(name, default, descriptor).value
        parameter = RuntimeParameter(name, kind, check, apply)
        value = parameter.validate(value)   # ValueError: the node does not start
        self.parameters[name] = parameter
        self.values[name] = value
        return value

    def joint(self, names: Sequence[str], check: Optional[Callable[[Dict], Any]] = None,
              apply: Optional[Callable[[Dict], None]] = None) -> None:
        """Add a joint rule of run-time parameters; check their start values with it."""
        rule = JointRule(tuple(names), check, apply)
        missing = [name for name in rule.names if name not in self.parameters]
        if missing:
            raise RuntimeError(f'joint rule of parameters that are not run-time: {missing}')
        if check is not None:
            check(rule.values(self.values))   # ValueError: the node does not start
        self.rules.append(rule)

    def add_reasons(self, reasons) -> None:
        """Add (pattern, reason) pairs or a {pattern: reason} mapping, after those given."""
        self.reasons += tuple(reasons.items() if isinstance(reasons, Mapping) else reasons)

    def reason(self, name: str) -> str:
        """Return why parameter name is read-only."""
        return read_only_reason(name, self.reasons)

    def start(self) -> None:
        """
        Make every other declared parameter read-only; take sets from now on.

        Call it at the end of the constructor, once every parameter is declared.
        """
        node = self.node
        names = node.list_parameters([], 0).names   # depth 0, no prefix: every one
        for name in names:
            if name in self.exempt or name in self.parameters:
                continue
            self.read_only[name] = self.reason(name)
            self._mark_read_only(name, self.read_only[name])
        node.add_on_set_parameters_callback(self._on_set)
        node.add_post_set_parameters_callback(self._on_post_set)
        node.set_parameters_atomically = self._guard_atomically(node.set_parameters_atomically)
        node.set_parameters = self._guard_each(node.set_parameters)
        self.started = True

    # -- rclpy's side ----------------------------------------------------------------

    def plan(self, parameters) -> Update:
        """Decide a set of rclpy Parameters (:func:`plan_update`)."""
        return plan_update([(p.name, p.value) for p in parameters], self.parameters,
                           self.values, self.read_only, self.rules, self.exempt)

    def _mark_read_only(self, name: str, reason: str) -> None:
        """Make name's descriptor read-only, its description the reason (ros2 param describe)."""
        descriptor = deepcopy(self.node.describe_parameter(name))
        if descriptor.read_only:
            return   # rclpy keeps it as declared (motor_params.yaml's say why already)
        descriptor.read_only = True
        descriptor.description = f'read-only: {reason}'
        try:
            self.node.set_descriptor(name, descriptor)
        except ParameterException:
            pass     # e.g. uninitialized: sets are refused all the same (_guard)

    @staticmethod
    def _result(reason: str = '') -> SetParametersResult:
        return SetParametersResult(successful=not reason, reason=reason)

    def _on_set(self, parameters):
        """Accept or refuse a set (rclpy's on-set callback); nothing is applied yet."""
        return self._result(self.plan(parameters).reason)

    def _on_post_set(self, parameters) -> None:
        """Apply an accepted set (rclpy has stored the values) and log it."""
        update = self.plan(parameters)
        if not update.successful or not update.changes:
            return
        try:
            for name, _, value in update.changes:
                apply = self.parameters[name].apply
                if apply is not None:
                    apply(value)
            for rule in update.rules:
                if rule.apply is not None:
                    rule.apply(rule.values(update.values))
        except Exception as error:  # noqa: B902 - a bug: say so, keep the node running
            self.node.get_logger().error(
                f'applying {change_text(update.changes)} failed: {error!r}')
            return
        self.values = update.values
        self.node.get_logger().info(change_text(update.changes))

    def _refusal(self, parameters) -> str:
        """Return why a set is refused before rclpy looks at it ('' if it is not)."""
        for parameter in parameters:
            if parameter.name in self.read_only:
                return read_only_refusal(parameter.name, self.read_only[parameter.name])
        return ''

    def _guard_atomically(self, set_atomically):
        def guarded(parameter_list):
            reason = self._refusal(parameter_list)
            return self._result(reason) if reason else set_atomically(parameter_list)
        return guarded

    def _guard_each(self, set_each):
        def guarded(parameter_list):
            results = []
            for parameter in parameter_list:
                reason = self._refusal([parameter])
                results.append(self._result(reason) if reason else set_each([parameter])[0])
            return results
        return guarded


def _kind_of(default) -> Optional[type]:
    """Return the kind of a parameter from its default (None: any, the check decides)."""
    if isinstance(default, bool):
        return bool
    if isinstance(default, (int, float, str)):
        return type(default)
    return None


def _runtime_description(description: str) -> str:
    return f'{RUNTIME_DESCRIPTION}: {description}' if description else RUNTIME_DESCRIPTION


def read_only_parameters(node, reasons=()) -> RuntimeParameters:
    """
    Make every parameter node has declared read-only, each set refused with its reason.

    For nodes that take no parameter at run time: without it a ``ros2 param set`` would
    be accepted and change nothing. Call it at the end of the constructor.
    """
    runtime = RuntimeParameters(node, reasons)
    runtime.start()
    return runtime
