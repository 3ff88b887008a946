"""Tests of mecanum_navigation.slam.pose_graph: pose algebra, edge errors, LM optimisation."""

import math

from mecanum_control.angles import wrap_angle
from mecanum_navigation.slam.pose_graph import compose, inverse, PoseGraph, relative
import numpy as np
import pytest

IDENTITY = np.eye(3)


def matrix(pose):
    """Return the homogeneous 3x3 matrix of a pose (x, y, yaw) (test reference algebra)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.array([[c, -s, pose[0]], [s, c, pose[1]], [0.0, 0.0, 1.0]])


def vector(m):
    """Return (x, y, yaw) of a homogeneous matrix."""
    return np.array([m[0, 2], m[1, 2], math.atan2(m[1, 0], m[0, 0])])


def reference_error(pose_i, pose_j, z):
    """Edge error t2v(Z^-1 X_i^-1 X_j), written with matrices, independent of the module."""
    return vector(np.linalg.inv(matrix(z)) @ np.linalg.inv(matrix(pose_i)) @ matrix(pose_j))


def reference_optimum(initial, edges, iterations=15):
    """
    Plain dense Gauss-Newton with numerical Jacobians (no kernels): node 0 fixed.

    edges: (i, j, z, information). A slow, independent reference for small graphs.
    """
    poses = np.array(initial, dtype=float)
    for _ in range(iterations):
        def residuals(x):
            trial = poses.copy()
            trial[1:] = x.reshape(-1, 3)
            out = []
            for i, j, z, info in edges:
                out.append(np.linalg.cholesky(info).T @ reference_error(trial[i], trial[j], z))
            return np.concatenate(out)

        x0 = poses[1:].ravel()
        r0 = residuals(x0)
        jac = np.empty((len(r0), len(x0)))
        for k in range(len(x0)):
            step = np.zeros(len(x0))
            step[k] = 1e-7
            jac[:, k] = (residuals(x0 + step) - residuals(x0 - step)) / 2e-7
        delta = np.linalg.solve(jac.T @ jac, -jac.T @ r0)
        poses[1:] = (x0 + delta).reshape(-1, 3)
        if np.abs(delta).max() < 1e-10:
            break
    return poses


# --- pose algebra ---------------------------------------------------------------------

def test_compose_inverse_relative_by_hand():
    # (1, 2) facing +y; one metre forward in its frame is (1, 3).
    assert compose((1.0, 2.0, math.pi / 2), (1.0, 0.0, 0.0)) == pytest.approx(
        (1.0, 3.0, math.pi / 2))
    # The origin seen from (1, 0) facing +y is 1 m to its right: (0, 1, -pi/2).
    assert inverse((1.0, 0.0, math.pi / 2)) == pytest.approx((0.0, 1.0, -math.pi / 2))
    assert compose((1.0, 0.0, math.pi / 2), inverse((1.0, 0.0, math.pi / 2))) == pytest.approx(
        (0.0, 0.0, 0.0))
    # (2, 1) seen from (1, 1) facing +y is 1 m to its right.
    assert relative((1.0, 1.0, math.pi / 2), (2.0, 1.0, math.pi / 2)) == pytest.approx(
        (0.0, -1.0, 0.0))


# --- edge errors ---------------------------------------------------------------------

def test_edge_error_by_hand():
    graph = PoseGraph()
    graph.add_node((0.0, 0.0, 0.0))
    graph.add_node((1.0, 0.1, 0.1))
    graph.add_edge(0, 1, (1.0, 0.0, 0.0), IDENTITY)
    # Node 1 is 0.1 m left of and 0.1 rad beyond where the edge puts it.
    np.testing.assert_allclose(graph.edge_errors()[0], [0.0, 0.1, 0.1], atol=1e-12)
    assert graph.edge_chi2()[0] == pytest.approx(0.02)


def test_edge_error_in_the_frame_of_the_measurement():
    graph = PoseGraph()
    graph.add_node((0.0, 0.0, math.pi / 2))     # facing +y
    graph.add_node((0.0, 1.0, math.pi / 2))     # 1 m ahead of it
    graph.add_edge(0, 1, (1.0, 0.0, 0.0), IDENTITY)
    np.testing.assert_allclose(graph.edge_errors()[0], [0.0, 0.0, 0.0], atol=1e-12)
    # The measurement says 1 m ahead and turned by +pi/2: the node sits 1 m ahead
    # but not turned, so in the measured frame the error is -pi/2 of yaw only.
    graph.add_edge(0, 1, (1.0, 0.0, math.pi / 2), IDENTITY)
    np.testing.assert_allclose(graph.edge_errors()[1], [0.0, 0.0, -math.pi / 2], atol=1e-12)


def test_edge_error_wraps_yaw_across_pi():
    graph = PoseGraph()
    graph.add_node((0.0, 0.0, 3.1))
    graph.add_node((0.0, 0.0, -3.1))
    graph.add_edge(0, 1, (0.0, 0.0, 2 * math.pi - 6.2), IDENTITY)
    assert graph.edge_errors()[0, 2] == pytest.approx(0.0, abs=1e-12)


def test_edge_errors_match_the_matrix_reference():
    rng = np.random.default_rng(4)
    graph = PoseGraph()
    poses = [tuple(rng.uniform(-3, 3, 2)) + (rng.uniform(-math.pi, math.pi),) for _ in range(6)]
    for pose in poses:
        graph.add_node(pose)
    edges = []
    for _ in range(10):
        i, j = rng.choice(6, 2, replace=False)
        z = tuple(rng.uniform(-2, 2, 2)) + (rng.uniform(-math.pi, math.pi),)
        graph.add_edge(int(i), int(j), z, IDENTITY)
        edges.append((i, j, z))
    for k, (i, j, z) in enumerate(edges):
        expected = reference_error(poses[i], poses[j], z)
        np.testing.assert_allclose(graph.edge_errors()[k], expected, atol=1e-9)


# --- optimisation ---------------------------------------------------------------------

def test_one_dimensional_loop_by_hand():
    """
    Two odometry steps of 1 m and a closure saying 1.8 m, all equally certain.

    Least squares (x1 - 1)^2 + (x2 - x1 - 1)^2 + (x2 - 1.8)^2: x2 = 2 x1 and
    2 x2 - x1 = 2.8, so x1 = 2.8 / 3 and x2 = 5.6 / 3.
    """
    graph = PoseGraph()
    graph.add_node((0.0, 0.0, 0.0))
    graph.add_node((1.2, 0.3, 0.2))      # poor initial guesses
    graph.add_node((2.5, -0.4, -0.3))
    graph.add_edge(0, 1, (1.0, 0.0, 0.0), IDENTITY)
    graph.add_edge(1, 2, (1.0, 0.0, 0.0), IDENTITY)
    graph.add_edge(0, 2, (1.8, 0.0, 0.0), IDENTITY)
    result = graph.optimize(relative_tolerance=1e-12)
    assert result.converged
    assert result.final_cost < result.initial_cost
    np.testing.assert_allclose(graph.poses(), [[0, 0, 0], [2.8 / 3, 0, 0], [5.6 / 3, 0, 0]],
                               atol=1e-7)
    # Residual cost: errors -1/15... each edge off by 1/15 m: 3 * (1/15)^2.
    assert result.final_cost == pytest.approx(3 * (0.2 / 3) ** 2, rel=1e-6)


def test_consistent_square_is_recovered_exactly_and_node_0_stays():
    graph = PoseGraph()
    graph.add_node((0.0, 0.0, 0.0))
    graph.add_node((1.1, 0.2, 1.4))
    graph.add_node((0.8, 1.3, 3.0))
    graph.add_node((-0.2, 0.9, -1.3))
    for i in range(4):
        graph.add_edge(i, (i + 1) % 4, (1.0, 0.0, math.pi / 2), IDENTITY)
    graph.optimize(relative_tolerance=1e-12)
    np.testing.assert_allclose(graph.poses(), [[0, 0, 0], [1, 0, math.pi / 2],
                                               [1, 1, -math.pi], [0, 1, -math.pi / 2]],
                               atol=1e-9)
    assert graph.cost() == pytest.approx(0.0, abs=1e-15)


def test_node_0_is_fixed_even_when_the_edges_disagree_with_it():
    graph = PoseGraph()
    graph.add_node((5.0, -2.0, 0.7))
    graph.add_node((0.0, 0.0, 0.0))
    graph.add_edge(0, 1, (1.0, 0.0, 0.0), IDENTITY)
    start = graph.pose(0)
    graph.optimize()
    assert graph.pose(0) == start == pytest.approx((5.0, -2.0, 0.7))
    assert graph.pose(1) == pytest.approx(compose((5.0, -2.0, 0.7), (1.0, 0.0, 0.0)))


def test_matches_dense_numerical_gauss_newton_on_a_random_graph():
    """A noisy chain with closures: the same optimum as an independent dense solver."""
    rng = np.random.default_rng(11)
    truth = [(math.cos(a) * 3, math.sin(a) * 3, a + math.pi / 2)
             for a in np.linspace(0, 2 * math.pi, 14, endpoint=False)]
    graph = PoseGraph()
    edges = []
    estimate = truth[0]
    graph.add_node(estimate)
    initial = [estimate]
    for k in range(1, len(truth)):
        z = np.array(relative(truth[k - 1], truth[k])) + rng.normal(0, [0.05, 0.05, 0.03])
        estimate = compose(estimate, z)
        graph.add_node(estimate)
        initial.append(estimate)
        info = np.diag([400.0, 300.0, 1000.0])
        info[0, 1] = info[1, 0] = 50.0
        graph.add_edge(k - 1, k, z, info)
        edges.append((k - 1, k, z, info))
    for i, j in ((0, 7), (3, 11), (13, 0), (5, 9)):
        z = np.array(relative(truth[i], truth[j])) + rng.normal(0, [0.02, 0.02, 0.01])
        info = np.diag([2500.0, 2500.0, 10000.0])
        graph.add_edge(i, j, z, info)
        edges.append((i, j, z, info))
    graph.optimize(relative_tolerance=1e-14)
    expected = reference_optimum(initial, edges)
    got = graph.poses()
    np.testing.assert_allclose(got[:, :2], expected[:, :2], atol=1e-6)
    np.testing.assert_allclose([wrap_angle(a - b) for a, b in zip(got[:, 2], expected[:, 2])],
                               0.0, atol=1e-6)


def drifting_loop(bad_closure, kernel):
    """
    Two laps of a 60-pose circle with drifting odometry and closures lap 2 -> lap 1.

    (No scale error: loop closures cannot observe a uniform scale.)

    Returns the RMS position error (m) after optimising, with an optional wrong closure.
    """
    n = 120
    truth = [(4 * math.cos(2 * math.pi * k / 60), 4 * math.sin(2 * math.pi * k / 60),
              2 * math.pi * k / 60 + math.pi / 2) for k in range(n)]
    graph = PoseGraph()
    estimate = truth[0]
    graph.add_node(estimate)
    odometry = np.diag([400.0, 400.0, 2500.0])
    for k in range(1, n):
        z = relative(truth[k - 1], truth[k])
        z = (z[0], z[1] + 0.01, z[2] + 0.004)     # sideways slip, yaw drift
        estimate = compose(estimate, z)
        graph.add_node(estimate)
        graph.add_edge(k - 1, k, z, odometry)
    closure = np.diag([1 / 0.03 ** 2, 1 / 0.03 ** 2, 1 / 0.02 ** 2])
    for k in range(60, n, 6):
        graph.add_edge(k - 60, k, relative(truth[k - 60], truth[k]), closure, kernel, 3.0)
    if bad_closure:
        # Claims pose 100 is 1.5 m away from pose 10 (it is at the same place).
        graph.add_edge(10, 100, (1.5, 0.5, 0.4), closure, kernel, 3.0)
    error = graph.poses()[:, :2] - np.array(truth)[:, :2]
    before = math.sqrt(np.mean(np.sum(error ** 2, axis=1)))
    graph.optimize()
    error = graph.poses()[:, :2] - np.array(truth)[:, :2]
    return before, math.sqrt(np.mean(np.sum(error ** 2, axis=1)))


def test_cauchy_kernel_keeps_one_bad_closure_from_wrecking_the_map():
    before, good = drifting_loop(bad_closure=False, kernel='cauchy')
    _, robust = drifting_loop(bad_closure=True, kernel='cauchy')
    _, plain = drifting_loop(bad_closure=True, kernel=None)
    _, plain_good = drifting_loop(bad_closure=False, kernel=None)
    assert before > 1.0
    assert good < before / 4                 # the closures undo most of the drift
    assert good == pytest.approx(plain_good, abs=0.005)   # right closures: no change
    assert robust < good + 0.02              # the bad closure changes (almost) nothing
    assert plain > 5 * good                  # without the kernel it bends the map


def test_huber_kernel_bounds_the_pull_of_a_bad_closure():
    _, huber = drifting_loop(bad_closure=True, kernel='huber')
    _, plain = drifting_loop(bad_closure=True, kernel=None)
    assert huber < plain


def test_two_thousand_nodes_optimise_to_the_least_squares_optimum():
    """
    A long noisy chain with many (correct) closures: the size the SLAM may reach.

    With all closures right, the Cauchy kernel must land where plain least squares does
    (that optimum is what the data allow), far better than the drifted start.
    """
    rng = np.random.default_rng(2)
    n = 2000
    truth = np.array([(5 * math.cos(2 * math.pi * k / 200), 5 * math.sin(2 * math.pi * k / 200),
                       2 * math.pi * k / 200 + math.pi / 2) for k in range(n)])
    robust, plain = PoseGraph(), PoseGraph()
    estimate = tuple(truth[0])
    for graph in (robust, plain):
        graph.add_node(estimate)
    for k in range(1, n):
        z = np.array(relative(truth[k - 1], truth[k])) + rng.normal(0, [0.01, 0.01, 0.002])
        estimate = compose(estimate, z)
        for graph in (robust, plain):
            graph.add_node(estimate)
            graph.add_edge(k - 1, k, z, np.diag([1e4, 1e4, 2.5e5]))
    for k in range(200, n, 5):
        z = relative(truth[k - 200], truth[k])
        robust.add_edge(k - 200, k, z, np.diag([1e4, 1e4, 1e4]), 'cauchy', 3.0)
        plain.add_edge(k - 200, k, z, np.diag([1e4, 1e4, 1e4]))

    def rms(graph):
        return math.sqrt(np.mean(np.sum((graph.poses()[:, :2] - truth[:, :2]) ** 2, axis=1)))

    before = rms(robust)
    result = robust.optimize()
    plain.optimize()
    assert result.converged
    assert before > 0.5
    assert rms(robust) < before / 5
    assert abs(rms(robust) - rms(plain)) < 0.01


# --- bad input ----------------------------------------------------------------------

def test_bad_nodes_and_edges_are_refused():
    graph = PoseGraph()
    with pytest.raises(ValueError, match='pose'):
        graph.add_node((0.0, math.nan, 0.0))
    with pytest.raises(ValueError, match='pose'):
        graph.add_node((0.0, 0.0))
    graph.add_node((0.0, 0.0, 0.0))
    graph.add_node((1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match='j must be a node index'):
        graph.add_edge(0, 2, (1.0, 0.0, 0.0), IDENTITY)
    with pytest.raises(ValueError, match='two different nodes'):
        graph.add_edge(1, 1, (1.0, 0.0, 0.0), IDENTITY)
    with pytest.raises(ValueError, match='measurement'):
        graph.add_edge(0, 1, (1.0, math.inf, 0.0), IDENTITY)
    with pytest.raises(ValueError, match='3x3'):
        graph.add_edge(0, 1, (1.0, 0.0, 0.0), np.eye(2))
    with pytest.raises(ValueError, match='symmetric'):
        graph.add_edge(0, 1, (1.0, 0.0, 0.0), [[1, 1, 0], [0, 1, 0], [0, 0, 1]])
    with pytest.raises(ValueError, match='semi-definite'):
        graph.add_edge(0, 1, (1.0, 0.0, 0.0), np.diag([1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match='kernel'):
        graph.add_edge(0, 1, (1.0, 0.0, 0.0), IDENTITY, kernel='tukey')
    with pytest.raises(ValueError, match='kernel_scale'):
        graph.add_edge(0, 1, (1.0, 0.0, 0.0), IDENTITY, kernel='huber', kernel_scale=0.0)
    assert graph.num_edges == 0


def test_a_node_without_edges_to_node_0_is_reported():
    graph = PoseGraph()
    for x in range(4):
        graph.add_node((float(x), 0.0, 0.0))
    graph.add_edge(0, 1, (1.0, 0.0, 0.0), IDENTITY)
    graph.add_edge(2, 3, (1.0, 0.0, 0.0), IDENTITY)
    with pytest.raises(ValueError, match='node 2 is not connected to node 0'):
        graph.optimize()


def test_empty_and_single_node_graphs_optimise_trivially():
    assert PoseGraph().optimize().converged
    graph = PoseGraph()
    graph.add_node((1.0, 2.0, 3.0))
    assert graph.optimize().converged
    assert graph.pose(0) == pytest.approx((1.0, 2.0, 3.0))
