"""
A component container for this workspace's Python nodes: several nodes, one process.

rclcpp_components loads C++ nodes only; this does for rclpy what Nav2's
``use_composition`` does for Nav2: the nodes of one container share a process, a DDS
participant and an executor (rclpy's EventsExecutor, as every node here). A message
for five nodes of a container then reaches the process once instead of waking five
processes; on simulated time that matters for /clock alone (50 Hz to every node).

Usage (the launch runner builds this command when asked to compose; see
:mod:`mecanum_bringup.composition`)::

    node_container '[{"label": "navigator", "package": "mecanum_navigation",
                      "executable": "navigator", "ros_args": ["--ros-args", ...]}, ...]'

Each node gets exactly the ``--ros-args`` it would get as its own process (name,
parameter files, parameters, remappings) and ignores the process's global arguments,
so a node behaves the same composed or not. The node class is found from the
executable's console_scripts entry point: the one rclpy Node subclass defined in that
module (one node class per file), whose constructor passes ``**node_options`` on to
rclpy's Node. Ctrl-C or SIGTERM closes every node (its ``close()``,
if it has one, e.g. a final zero command) in reverse order. A node that fails to start
(bad parameter) is logged as fatal and the container exits with code 2.
"""

import importlib
from importlib import metadata
import inspect
import json
import os
import sys
from typing import Dict, List, Optional, Tuple

from mecanum_control import node_reload
from mecanum_control.node_main import (
    close_for_good, close_node, close_watchdog, hold_participant, leave_process,
    raise_keyboard_interrupt_on_signals, spin_waking, TEARDOWN_VARIABLE, unload_and_wait)
import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions


class CompositionError(ValueError):
    """A container specification that cannot be run (names the node and the problem)."""


def node_class(package: str, executable: str) -> type:
    """Return the rclpy Node subclass behind PACKAGE's console script EXECUTABLE."""
    try:
        distribution = metadata.distribution(package)
    except metadata.PackageNotFoundError:
        try:
            distribution = metadata.distribution(package.replace('_', '-'))
        except metadata.PackageNotFoundError:
            raise CompositionError(f'package {package!r} is not installed') from None
    points = [p for p in distribution.entry_points
              if p.group == 'console_scripts' and p.name == executable]
    if not points:
        raise CompositionError(f'{package} has no executable {executable!r}')
    module = importlib.import_module(points[0].module)
    classes = [value for value in vars(module).values()
               if isinstance(value, type) and issubclass(value, Node)
               and value.__module__ == module.__name__]
    if len(classes) != 1:
        raise CompositionError(
            f'{package}/{executable}: {points[0].module} defines {len(classes)} node classes; '
            'a composable executable has exactly one')
    if not getattr(classes[0], 'composable', True):
        raise CompositionError(
            f'{package}/{executable}: {classes[0].__name__} drives its own loop, so it '
            'cannot run in a container')
    parameters = inspect.signature(classes[0].__init__).parameters.values()
    if not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters):
        raise CompositionError(
            f'{package}/{executable}: {classes[0].__name__}() takes no node options '
            '(**node_options for rclpy Node), so it cannot run in a container')
    return classes[0]


def parse_spec(text: str) -> List[Dict]:
    """Return the node list of a container specification (JSON), validated."""
    try:
        nodes = json.loads(text)
    except json.JSONDecodeError as error:
        raise CompositionError(f'the node list is not JSON: {error}') from None
    if not isinstance(nodes, list) or not nodes:
        raise CompositionError('the node list must be a non-empty JSON list')
    for index, node in enumerate(nodes):
        if not isinstance(node, dict):
            raise CompositionError(f'node {index}: expected an object, got {node!r}')
        for key in ('label', 'package', 'executable'):
            if not isinstance(node.get(key), str) or not node[key]:
                raise CompositionError(f'node {index}: {key!r} must be a non-empty string')
        ros_args = node.get('ros_args', [])
        if not isinstance(ros_args, list) or not all(isinstance(a, str) for a in ros_args):
            raise CompositionError(f'node {node["label"]}: ros_args must be a list of strings')
    return nodes


def load_specs(argv: List[str]) -> Tuple[List[Dict], List[type]]:
    """Return the node specifications and classes of the container's arguments."""
    own = rclpy.utilities.remove_ros_args(['node_container', *argv])[1:]
    if len(own) != 1:
        raise CompositionError('usage: node_container NODE_LIST_JSON')
    specs = parse_spec(own[0])
    return specs, [node_class(s['package'], s['executable']) for s in specs]


def make_nodes(specs: List[Dict], classes: List[type]) -> List[Node]:
    """
    Make the nodes, each with its own arguments.

    On a bad parameter: log it (fatal), destroy the nodes made so far and raise
    CompositionError.
    """
    nodes: List[Node] = []
    for spec, cls in zip(specs, classes):
        try:
            nodes.append(cls(cli_args=spec.get('ros_args', []), use_global_arguments=False))
        except (ValueError, ParameterException) as error:
            rclpy.logging.get_logger(spec['label']).fatal(f'{error}')
            for node in reversed(nodes):
                close_node(node)
            raise CompositionError(f'{spec["label"]}: {error}') from None
    return nodes


def main(argv: Optional[List[str]] = None) -> int:
    """Run the container until Ctrl-C or SIGTERM; return an error's exit code, else leave (0)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    logger = rclpy.logging.get_logger('node_container')
    try:
        specs, classes = load_specs(argv)
    except CompositionError as error:
        logger.fatal(str(error))
        return 2
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    raise_keyboard_interrupt_on_signals()
    leaving = os.environ.get(TEARDOWN_VARIABLE, '') != 'full'
    if leaving:
        hold_participant('node_container')
    channel = node_reload.reload_channel()
    until = channel.unload_requested if channel is not None else None
    nodes: List[Node] = []
    reloading = False
    try:
        while True:
            try:
                nodes = make_nodes(specs, classes)
            except CompositionError as error:
                if reloading:
                    node_reload.say(f'{node_reload.FAILED_PREFIX}{error}')
                return 2
            logger.info(f'{len(nodes)} nodes in one process: '
                        + ', '.join(node.get_name() for node in nodes))
            if reloading:
                node_reload.say(node_reload.LOADED_LINE)
            spin_waking(*nodes, until=until)
            if until is None or not until.is_set():
                break
            # A reload: these nodes go, new ones come from the next load's arguments.
            closing, nodes = nodes, []
            argv = unload_and_wait('node_container', closing, channel)
            if argv is None:
                break
            reloading = True
            try:
                specs, classes = load_specs(argv)
            except CompositionError as error:
                logger.fatal(str(error))
                node_reload.say(f'{node_reload.FAILED_PREFIX}{error}')
                return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        close_for_good('node_container', nodes)
    if leaving:
        with close_watchdog('node_container'):
            leave_process(0)   # without the interpreter's teardown (node_main.leave_process)
    return 0


if __name__ == '__main__':
    sys.exit(main())
