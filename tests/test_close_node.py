"""
close_node leaves nothing of a node behind, action servers included (real rclpy, DDS).

rclpy's destroy_node leaves a node's waitables (action servers and clients), and each
holds the node's handle: the node stayed in the graph, its action server answering,
as long as anything referenced it. A reload (warm stacks) then had two /navigator
nodes, the old one still serving navigate_to_pose.
"""

import time

from mecanum_bringup.isolation import lease_domain_id
from mecanum_control.node_main import close_node
from nav2_msgs.action import NavigateToPose
import pytest
import rclpy
from rclpy.action import ActionServer
from rclpy.node import Node


class ServingNode(Node):
    """A node with an action server, kept as an attribute (as the navigator keeps its own)."""

    def __init__(self, **options):
        super().__init__('serving_node', **options)
        self.server = ActionServer(self, NavigateToPose, 'navigate_to_pose',
                                   lambda handle: NavigateToPose.Result())


@pytest.fixture
def context():
    with lease_domain_id() as lease:
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=lease.domain_id)
        yield context
        context.try_shutdown()


def names_settle(node: Node, predicate, timeout_s: float = 10.0) -> bool:
    """Wait until predicate(node names in the graph) holds (graph updates take a moment)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate(node.get_node_names()):
            return True
        time.sleep(0.05)
    return False


def test_a_closed_node_with_an_action_server_leaves_the_graph(context):
    probe = rclpy.create_node('probe', context=context)
    serving = ServingNode(context=context)
    still_referenced = [serving]    # as the navigator's container held it
    assert names_settle(probe, lambda names: 'serving_node' in names)
    close_node(serving)
    assert names_settle(probe, lambda names: 'serving_node' not in names), \
        'the closed node is still in the graph'
    probe.destroy_node()
    still_referenced.clear()
