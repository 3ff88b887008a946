"""
Group a system's nodes into containers (one process each), as ``use_composition`` does.

A composition file names containers and the nodes (by label: node name, else
executable) each one holds::

    containers:
      control_container: [encoder_reader, velocity_controller, ...]
      navigation_container: [map_server, amcl, navigator]

:func:`compose` turns a :class:`System` into one where the listed nodes present in it
are replaced by a ``mecanum_bringup node_container`` process each (see
:mod:`mecanum_bringup.node_container`), placed where its first node was; its nodes
start in the composition file's order. Every node
keeps its own ``--ros-args`` (name, parameters, remappings). Nodes not listed, and
listed nodes that are absent, are left alone; a node with a launch prefix or plain
command-line arguments cannot share a process and stays on its own. A container
respawns if any of its nodes would (after the longest delay) and stops the system if
any of its nodes has ``on_exit: shutdown``. This module does not import rclpy.
"""

import json
from pathlib import Path
from typing import Dict, List

from mecanum_bringup.system_description import NodeProcess, System, SystemDescriptionError
import yaml

CONTAINER_PACKAGE = 'mecanum_bringup'
CONTAINER_EXECUTABLE = 'node_container'


def load_composition(path: Path) -> Dict[str, List[str]]:
    """Read and validate a composition file; return {container name: [node labels]}."""
    try:
        document = yaml.safe_load(Path(path).read_text(encoding='utf-8'))
    except (OSError, yaml.YAMLError) as error:
        raise SystemDescriptionError(f'{path}: cannot read the composition: {error}') from None
    containers = document.get('containers') if isinstance(document, dict) else None
    if not isinstance(containers, dict) or not containers:
        raise SystemDescriptionError(
            f'{path}: expected a mapping "containers: {{NAME: [node, ...]}}"')
    owner: Dict[str, str] = {}
    result: Dict[str, List[str]] = {}
    for name, labels in containers.items():
        if not isinstance(name, str) or not name.isidentifier():
            raise SystemDescriptionError(f'{path}: container name {name!r} is not a plain name')
        if not isinstance(labels, list) or not labels or not all(
                isinstance(label, str) and label for label in labels):
            raise SystemDescriptionError(
                f'{path}: containers.{name} must be a non-empty list of node names')
        for label in labels:
            if label in owner:
                raise SystemDescriptionError(
                    f'{path}: node {label!r} is in both {owner[label]} and {name}')
            owner[label] = name
        result[name] = list(labels)
    return result


def composable(node: NodeProcess) -> bool:
    """Tell whether a node can run in a container (no launch prefix, no plain arguments)."""
    return not node.launch_prefix and not node.arguments


def compose(system: System, containers: Dict[str, List[str]]) -> System:
    """Return a copy of system with the containers' nodes grouped into containers."""
    by_label = {node.label: node for node in system.nodes if composable(node)}
    members: Dict[str, List[NodeProcess]] = {}
    for name, labels in containers.items():
        present = [by_label[label] for label in labels if label in by_label]
        if present:
            members[name] = present
    container_of = {id(node): name for name, nodes in members.items() for node in nodes}
    nodes: List[NodeProcess] = []
    placed = set()
    for node in system.nodes:
        name = container_of.get(id(node))
        if name is None:
            nodes.append(node)
        elif name not in placed:
            placed.add(name)
            nodes.append(_container(name, members[name]))
    return System(nodes=nodes, files=list(system.files), arguments=dict(system.arguments))


def _container(name: str, members: List[NodeProcess]) -> NodeProcess:
    envs = {tuple(sorted(node.env.items())) for node in members}
    if len(envs) != 1:
        raise SystemDescriptionError(
            f'container {name}: its nodes ({", ".join(n.label for n in members)}) do not '
            'share one environment (set_env/env entries); they cannot share a process')
    spec = [{'label': node.label, 'package': node.package, 'executable': node.executable,
             'ros_args': node.ros_args()} for node in members]
    return NodeProcess(
        package=CONTAINER_PACKAGE, executable=CONTAINER_EXECUTABLE,
        arguments=[json.dumps(spec, separators=(',', ':'))],
        name=name, env=dict(members[0].env),
        respawn=any(node.respawn for node in members),
        respawn_delay_s=max(node.respawn_delay_s for node in members),
        shutdown_on_exit=any(node.shutdown_on_exit for node in members))
