"""
A 2-D pose graph and its Levenberg-Marquardt optimiser (pure numpy + numba, no ROS).

Nodes are poses (x_m, y_m, yaw_rad) in one frame (the map, REP-105); node 0 is held
fixed (it anchors the frame). An edge (i, j, z, information) says that node j seen
from node i is at z = (dx_m, dy_m, dyaw_rad), i.e. z ~ X_i^-1 X_j, with a 3x3
information matrix (inverse covariance) in the order x, y, yaw. Its error is
``e = t2v(Z^-1 X_i^-1 X_j)``: ``e_xy = R(z_yaw)^T (R(yaw_i)^T (t_j - t_i) - z_xy)`` and
``e_yaw = wrap(yaw_j - yaw_i - z_yaw)``, wrapped to [-pi, pi), and its cost is
``rho(e^T information e)``: rho(s) = s without a kernel, and with kernel scale k
(whitened units, i.e. sigmas) ``'huber'``: s for s <= k^2, else 2 k sqrt(s) - k^2, or
``'cauchy'``: k^2 log(1 + s / k^2). The kernels are applied by iteratively re-weighted
least squares (the weight rho'(s) is recomputed at each iteration); Cauchy bounds the
pull of an edge whose error is many sigmas, so one wrong loop closure cannot drag the
map along.

The normal equations are solved exactly: the nodes are put in reverse Cuthill-McKee
order (neighbours in the graph get nearby indices, which keeps the band of a long
chain with loop closures narrow) and the system is factored by an envelope (skyline)
Cholesky decomposition, whose fill stays inside each row's first non-zero column.
"""

from dataclasses import dataclass
import math
from typing import Sequence, Tuple

from mecanum_control.angles import wrap_angle
from numba import njit
import numpy as np

Pose = Tuple[float, float, float]

#: Kernel codes used in the compiled kernels.
KERNELS = {None: 0, 'none': 0, 'huber': 1, 'cauchy': 2}


def compose(a: Sequence[float], b: Sequence[float]) -> Pose:
    """Return the pose a * b: b (given in a's frame) expressed in a's parent frame."""
    cos_a, sin_a = math.cos(a[2]), math.sin(a[2])
    return (a[0] + cos_a * b[0] - sin_a * b[1],
            a[1] + sin_a * b[0] + cos_a * b[1],
            wrap_angle(a[2] + b[2]))


def inverse(a: Sequence[float]) -> Pose:
    """Return the pose a^-1 (the parent frame seen from a)."""
    cos_a, sin_a = math.cos(a[2]), math.sin(a[2])
    return (-cos_a * a[0] - sin_a * a[1], sin_a * a[0] - cos_a * a[1], wrap_angle(-a[2]))


def relative(a: Sequence[float], b: Sequence[float]) -> Pose:
    """Return a^-1 * b: pose b expressed in the frame of pose a."""
    return compose(inverse(a), b)


@dataclass(frozen=True)
class OptimizationResult:
    """What optimize() did: iterations run, robust cost before and after, convergence."""

    iterations: int
    initial_cost: float
    final_cost: float
    converged: bool


class PoseGraph:
    """Poses and relative-pose edges; optimize() moves every pose but node 0 (see module)."""

    def __init__(self) -> None:
        self._poses = np.zeros((16, 3))
        self._num_nodes = 0
        self._edge_nodes = np.zeros((16, 2), dtype=np.int64)
        self._edge_z = np.zeros((16, 3))
        self._edge_info = np.zeros((16, 3, 3))
        self._edge_kernel = np.zeros(16, dtype=np.int64)
        self._edge_scale = np.ones(16)
        self._num_edges = 0

    @property
    def num_nodes(self) -> int:
        """Return the number of nodes."""
        return self._num_nodes

    @property
    def num_edges(self) -> int:
        """Return the number of edges."""
        return self._num_edges

    def add_node(self, pose: Sequence[float]) -> int:
        """Add a node at pose (x_m, y_m, yaw_rad); return its index (0, 1, ...)."""
        value = _pose_array('pose', pose)
        if self._num_nodes == len(self._poses):
            self._poses = np.concatenate([self._poses, np.zeros_like(self._poses)])
        self._poses[self._num_nodes] = value
        self._num_nodes += 1
        return self._num_nodes - 1

    def pose(self, index: int) -> Pose:
        """Return node `index` as (x_m, y_m, yaw_rad)."""
        self._check_node('index', index)
        return tuple(float(v) for v in self._poses[index])

    def poses(self) -> np.ndarray:
        """Return all poses as a (num_nodes, 3) array (a copy)."""
        return self._poses[:self._num_nodes].copy()

    def set_pose(self, index: int, pose: Sequence[float]) -> None:
        """Move node index to pose (e.g. an initial guess); node 0 may be moved too."""
        self._check_node('index', index)
        self._poses[index] = _pose_array('pose', pose)

    def add_edge(self, i: int, j: int, measurement: Sequence[float], information,
                 kernel: str = None, kernel_scale: float = 1.0) -> int:
        """
        Add the edge i -> j: node j is at measurement (dx_m, dy_m, dyaw_rad) in node i's frame.

        information is the 3x3 symmetric positive semi-definite inverse covariance (x, y,
        yaw); kernel None, 'huber' or 'cauchy' with kernel_scale (sigmas). Returns the
        edge index. Raises ValueError for bad indices or values.
        """
        self._check_node('i', i)
        self._check_node('j', j)
        if i == j:
            raise ValueError(f'an edge must join two different nodes, got i = j = {i}')
        z = _pose_array('measurement', measurement)
        info = np.array(information, dtype=np.float64)
        if info.shape != (3, 3) or not np.all(np.isfinite(info)):
            raise ValueError(f'information must be a finite 3x3 matrix, got {information!r}')
        if not np.allclose(info, info.T, rtol=1e-9, atol=1e-12 * max(1.0, np.abs(info).max())):
            raise ValueError('information must be symmetric')
        if np.linalg.eigvalsh(info).min() < -1e-9 * max(1.0, np.abs(info).max()):
            raise ValueError('information must be positive semi-definite')
        if kernel not in KERNELS:
            raise ValueError(f"kernel must be None, 'huber' or 'cauchy', got {kernel!r}")
        if not (isinstance(kernel_scale, (int, float)) and math.isfinite(kernel_scale)
                and kernel_scale > 0.0):
            raise ValueError(f'kernel_scale must be a positive number, got {kernel_scale!r}')
        if self._num_edges == len(self._edge_z):
            grow = len(self._edge_z)
            self._edge_nodes = np.concatenate([self._edge_nodes, np.zeros((grow, 2), np.int64)])
            self._edge_z = np.concatenate([self._edge_z, np.zeros((grow, 3))])
            self._edge_info = np.concatenate([self._edge_info, np.zeros((grow, 3, 3))])
            self._edge_kernel = np.concatenate([self._edge_kernel, np.zeros(grow, np.int64)])
            self._edge_scale = np.concatenate([self._edge_scale, np.ones(grow)])
        k = self._num_edges
        self._edge_nodes[k] = (i, j)
        self._edge_z[k] = z
        self._edge_info[k] = 0.5 * (info + info.T)
        self._edge_kernel[k] = KERNELS[kernel]
        self._edge_scale[k] = float(kernel_scale)
        self._num_edges += 1
        return k

    def edge(self, index: int) -> Tuple[int, int, Pose, np.ndarray]:
        """Return edge index as (i, j, measurement, information copy)."""
        if not (isinstance(index, (int, np.integer)) and 0 <= index < self._num_edges):
            raise ValueError(f'edge index must be in [0, {self._num_edges}), got {index!r}')
        i, j = self._edge_nodes[index]
        return (int(i), int(j), tuple(float(v) for v in self._edge_z[index]),
                self._edge_info[index].copy())

    def edge_errors(self) -> np.ndarray:
        """Return each edge's error e (num_edges, 3) at the current poses (yaw wrapped)."""
        n = self._num_edges
        return _edge_errors(self._poses, self._edge_nodes[:n], self._edge_z[:n])

    def edge_chi2(self) -> np.ndarray:
        """Return each edge's e^T information e (before any kernel) at the current poses."""
        errors = self.edge_errors()
        return np.einsum('ki,kij,kj->k', errors, self._edge_info[:self._num_edges], errors)

    def cost(self) -> float:
        """Return the total robust cost sum rho(e^T information e) at the current poses."""
        n = self._num_edges
        return float(_total_cost(self._poses, self._edge_nodes[:n], self._edge_z[:n],
                                 self._edge_info[:n], self._edge_kernel[:n],
                                 self._edge_scale[:n]))

    def optimize(self, max_iterations: int = 30,
                 relative_tolerance: float = 1e-6) -> OptimizationResult:
        """
        Minimise the robust cost over every pose but node 0 with Levenberg-Marquardt.

        Stops after max_iterations accepted or rejected steps, or when an accepted step
        lowers the cost by less than relative_tolerance (relative) -- converged. Raises
        ValueError when a node is not connected to node 0 by edges (its pose would be
        undetermined). The poses are updated in place.
        """
        if not (isinstance(max_iterations, int) and not isinstance(max_iterations, bool)
                and max_iterations >= 0):
            raise ValueError(f'max_iterations must be an integer >= 0, got {max_iterations!r}')
        if not _is_positive(relative_tolerance):
            raise ValueError('relative_tolerance must be a positive number, got '
                             f'{relative_tolerance!r}')
        n, m = self._num_nodes, self._num_edges
        if n == 0:
            return OptimizationResult(0, 0.0, 0.0, True)
        nodes = self._edge_nodes[:m]
        position, first, offsets = _structure(n, nodes)
        if n > 1 and np.any(position[1:] < 0):
            missing = int(np.nonzero(position[1:] < 0)[0][0]) + 1
            raise ValueError(f'node {missing} is not connected to node 0 by any chain of edges')
        poses, iterations, initial, final, converged = _levenberg_marquardt(
            self._poses[:n].copy(), nodes, self._edge_z[:m], self._edge_info[:m],
            self._edge_kernel[:m], self._edge_scale[:m], position, first, offsets,
            max_iterations, float(relative_tolerance))
        self._poses[:n] = poses
        return OptimizationResult(int(iterations), float(initial), float(final), bool(converged))

    def _check_node(self, name: str, index) -> None:
        """Raise ValueError unless index names an existing node."""
        if not (isinstance(index, (int, np.integer)) and not isinstance(index, bool)
                and 0 <= index < self._num_nodes):
            raise ValueError(f'{name} must be a node index in [0, {self._num_nodes}), '
                             f'got {index!r}')


def _is_positive(value) -> bool:
    """Return True for a positive finite int or float (not bool)."""
    return (isinstance(value, (int, float, np.integer, np.floating))
            and not isinstance(value, (bool, np.bool_)) and math.isfinite(value) and value > 0)


def _pose_array(name: str, pose) -> np.ndarray:
    """Return pose as a finite (3,) float64 array with yaw wrapped, or raise ValueError."""
    try:
        value = np.array(pose, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be 3 finite numbers (x, y, yaw), got {pose!r}') from None
    if value.shape != (3,) or not np.all(np.isfinite(value)):
        raise ValueError(f'{name} must be 3 finite numbers (x, y, yaw), got {pose!r}')
    value[2] = wrap_angle(value[2])
    return value


def _structure(n: int, nodes: np.ndarray):
    """
    Return (position, first, offsets) of the envelope system for n nodes and these edges.

    position[node] is the node's block in the system (-1 for node 0, the fixed one, and
    for nodes not connected to it); first[r] is the first stored column of scalar row
    r; row r's entries (first[r] .. r) start at offsets[r] of the flat storage.
    """
    order = _reverse_cuthill_mckee(n, nodes)
    position = np.full(n, -1, dtype=np.int64)
    reachable = _reachable_from_zero(n, nodes)
    count = 0
    for node in order:
        if node != 0 and reachable[node]:
            position[node] = count
            count += 1
    first_block = np.arange(count, dtype=np.int64)
    if len(nodes):
        pi, pj = position[nodes[:, 0]], position[nodes[:, 1]]
        both = (pi >= 0) & (pj >= 0)
        low, high = np.minimum(pi[both], pj[both]), np.maximum(pi[both], pj[both])
        np.minimum.at(first_block, high, low)
    first = np.repeat(3 * first_block, 3)
    lengths = np.arange(3 * count, dtype=np.int64) - first + 1
    offsets = np.zeros(3 * count + 1, dtype=np.int64)
    np.cumsum(lengths, out=offsets[1:])
    return position, first, offsets


def _reachable_from_zero(n: int, nodes: np.ndarray) -> np.ndarray:
    """Return a boolean mask of the nodes connected to node 0 (node 0 included)."""
    ptr, adjacency = _adjacency(n, nodes)
    return _bfs_mask(ptr, adjacency, 0)


def _adjacency(n: int, nodes: np.ndarray):
    """Return the graph's adjacency in CSR form (ptr, neighbours), both directions."""
    if len(nodes) == 0:
        return np.zeros(n + 1, dtype=np.int64), np.zeros(0, dtype=np.int64)
    sources = np.concatenate([nodes[:, 0], nodes[:, 1]])
    targets = np.concatenate([nodes[:, 1], nodes[:, 0]])
    order = np.lexsort((targets, sources))
    sources, targets = sources[order], targets[order]
    keep = np.ones(len(sources), dtype=bool)
    keep[1:] = (sources[1:] != sources[:-1]) | (targets[1:] != targets[:-1])
    sources, targets = sources[keep], targets[keep]
    ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(sources, minlength=n), out=ptr[1:])
    return ptr, targets.astype(np.int64)


def _reverse_cuthill_mckee(n: int, nodes: np.ndarray) -> np.ndarray:
    """Return the nodes in reverse Cuthill-McKee order (every component, BFS by degree)."""
    ptr, adjacency = _adjacency(n, nodes)
    return _rcm(ptr, adjacency)


@njit(cache=True)
def _bfs_mask(ptr, adjacency, start):
    """Return the mask of nodes reachable from start."""
    n = ptr.shape[0] - 1
    seen = np.zeros(n, dtype=np.bool_)
    queue = np.empty(n, dtype=np.int64)
    seen[start] = True
    queue[0] = start
    head, tail = 0, 1
    while head < tail:
        node = queue[head]
        head += 1
        for k in range(ptr[node], ptr[node + 1]):
            other = adjacency[k]
            if not seen[other]:
                seen[other] = True
                queue[tail] = other
                tail += 1
    return seen


@njit(cache=True)
def _bfs_order(ptr, adjacency, degree, start, visited, order, count):
    """Append the BFS of start's component to order (neighbours by rising degree)."""
    visited[start] = True
    order[count] = start
    head = count
    tail = count + 1
    buffer = np.empty(ptr.shape[0], dtype=np.int64)
    while head < tail:
        node = order[head]
        head += 1
        size = 0
        for k in range(ptr[node], ptr[node + 1]):
            other = adjacency[k]
            if not visited[other]:
                visited[other] = True
                # Insertion sort by degree (neighbour lists are short).
                i = size
                while i > 0 and degree[buffer[i - 1]] > degree[other]:
                    buffer[i] = buffer[i - 1]
                    i -= 1
                buffer[i] = other
                size += 1
        for i in range(size):
            order[tail] = buffer[i]
            tail += 1
    return tail


@njit(cache=True)
def _rcm(ptr, adjacency):
    """Reverse Cuthill-McKee order of all nodes; each component starts pseudo-peripheral."""
    n = ptr.shape[0] - 1
    degree = ptr[1:] - ptr[:-1]
    visited = np.zeros(n, dtype=np.bool_)
    order = np.empty(n, dtype=np.int64)
    count = 0
    while count < n:
        start = -1
        for node in range(n):
            if not visited[node] and (start < 0 or degree[node] < degree[start]):
                start = node
        # Two BFS sweeps to find a far (pseudo-peripheral) start node.
        for _ in range(2):
            probe = np.zeros(n, dtype=np.bool_)
            scratch = np.empty(n, dtype=np.int64)
            end = _bfs_order(ptr, adjacency, degree, start, probe, scratch, 0)
            start = scratch[end - 1]
        count = _bfs_order(ptr, adjacency, degree, start, visited, order, count)
    return order[::-1].copy()


#: mecanum_control.angles.wrap_angle compiled for the kernels: [-pi, pi), one definition.
#: (numba's cache of a kernel calling it is not invalidated by an edit of angles.py.)
_wrap = njit(cache=True)(wrap_angle)


@njit(cache=True)
def _edge_error_jacobian(pose_i, pose_j, z, error, jac_i, jac_j):
    """Fill error (3,) and the Jacobians (3x3) of the edge error w.r.t. poses i and j."""
    ci, si = math.cos(pose_i[2]), math.sin(pose_i[2])
    cz, sz = math.cos(z[2]), math.sin(z[2])
    dx, dy = pose_j[0] - pose_i[0], pose_j[1] - pose_i[1]
    # m = R_i^T (t_j - t_i) and its derivative w.r.t. yaw_i.
    mx, my = ci * dx + si * dy, -si * dx + ci * dy
    dmx, dmy = -si * dx + ci * dy, -ci * dx - si * dy
    ux, uy = mx - z[0], my - z[1]
    error[0] = cz * ux + sz * uy
    error[1] = -sz * ux + cz * uy
    error[2] = _wrap(pose_j[2] - pose_i[2] - z[2])
    # A = R_z^T R_i^T: d e_xy / d t_j = A, d e_xy / d t_i = -A.
    a00, a01 = cz * ci - sz * si, cz * si + sz * ci
    a10, a11 = -sz * ci - cz * si, -sz * si + cz * ci
    jac_j[0, 0], jac_j[0, 1], jac_j[0, 2] = a00, a01, 0.0
    jac_j[1, 0], jac_j[1, 1], jac_j[1, 2] = a10, a11, 0.0
    jac_j[2, 0], jac_j[2, 1], jac_j[2, 2] = 0.0, 0.0, 1.0
    jac_i[0, 0], jac_i[0, 1], jac_i[0, 2] = -a00, -a01, cz * dmx + sz * dmy
    jac_i[1, 0], jac_i[1, 1], jac_i[1, 2] = -a10, -a11, -sz * dmx + cz * dmy
    jac_i[2, 0], jac_i[2, 1], jac_i[2, 2] = 0.0, 0.0, -1.0


@njit(cache=True)
def _edge_errors(poses, nodes, z):
    """Return the (m, 3) edge errors."""
    m = nodes.shape[0]
    errors = np.empty((m, 3))
    jac_i = np.empty((3, 3))
    jac_j = np.empty((3, 3))
    for k in range(m):
        _edge_error_jacobian(poses[nodes[k, 0]], poses[nodes[k, 1]], z[k], errors[k],
                             jac_i, jac_j)
    return errors


@njit(cache=True)
def _rho(s, kernel, scale):
    """Return (rho(s), rho'(s)) of a kernel at squared whitened error s."""
    if kernel == 1:
        k2 = scale * scale
        if s <= k2:
            return s, 1.0
        root = math.sqrt(s)
        return 2.0 * scale * root - k2, scale / root
    if kernel == 2:
        k2 = scale * scale
        return k2 * math.log1p(s / k2), 1.0 / (1.0 + s / k2)
    return s, 1.0


@njit(cache=True)
def _total_cost(poses, nodes, z, info, kernel, scale):
    """Return the total robust cost."""
    errors = _edge_errors(poses, nodes, z)
    total = 0.0
    for k in range(nodes.shape[0]):
        e = errors[k]
        s = 0.0
        for a in range(3):
            for b in range(3):
                s += e[a] * info[k, a, b] * e[b]
        total += _rho(max(s, 0.0), kernel[k], scale[k])[0]
    return total


@njit(cache=True)
def _add_block(values, first, offsets, row_block, col_block, block, transpose):
    """Add a 3x3 block at block (row_block, col_block), row_block >= col_block (lower part)."""
    for a in range(3):
        r = 3 * row_block + a
        for b in range(3):
            c = 3 * col_block + b
            if c > r:
                continue
            v = block[b, a] if transpose else block[a, b]
            values[offsets[r] + c - first[r]] += v


@njit(cache=True)
def _matmul(a, b, transpose_a):
    """Return a b (or a^T b) of 3x3 matrices (numba's @ would need scipy's BLAS)."""
    out = np.zeros((3, 3))
    for r in range(3):
        for c in range(3):
            s = 0.0
            for k in range(3):
                s += (a[k, r] if transpose_a else a[r, k]) * b[k, c]
            out[r, c] = s
    return out


@njit(cache=True)
def _build_system(poses, nodes, z, info, kernel, scale, position, first, offsets):
    """Return (values, gradient, cost): the weighted normal equations in envelope storage."""
    size = first.shape[0]
    values = np.zeros(offsets[size])
    gradient = np.zeros(size)
    error = np.empty(3)
    jac_i = np.empty((3, 3))
    jac_j = np.empty((3, 3))
    cost = 0.0
    for k in range(nodes.shape[0]):
        i, j = nodes[k, 0], nodes[k, 1]
        _edge_error_jacobian(poses[i], poses[j], z[k], error, jac_i, jac_j)
        omega = info[k]
        s = 0.0
        for a in range(3):
            for b in range(3):
                s += error[a] * omega[a, b] * error[b]
        rho, weight = _rho(max(s, 0.0), kernel[k], scale[k])
        cost += rho
        wo = weight * omega
        pi, pj = position[i], position[j]
        oj_i = _matmul(wo, jac_i, False)
        oj_j = _matmul(wo, jac_j, False)
        we = np.zeros(3)
        for a in range(3):
            for b in range(3):
                we[a] += wo[a, b] * error[b]
        if pi >= 0:
            for a in range(3):
                for b in range(3):
                    gradient[3 * pi + a] += jac_i[b, a] * we[b]
            _add_block(values, first, offsets, pi, pi, _matmul(jac_i, oj_i, True), False)
        if pj >= 0:
            for a in range(3):
                for b in range(3):
                    gradient[3 * pj + a] += jac_j[b, a] * we[b]
            _add_block(values, first, offsets, pj, pj, _matmul(jac_j, oj_j, True), False)
        if pi >= 0 and pj >= 0:
            cross = _matmul(jac_i, oj_j, True)   # block (i, j) of the Hessian
            if pi > pj:
                _add_block(values, first, offsets, pi, pj, cross, False)
            else:
                _add_block(values, first, offsets, pj, pi, cross, True)
    return values, gradient, cost


@njit(cache=True)
def _envelope_cholesky(values, first, offsets):
    """Factor in place into L (same storage); return False on a non-positive pivot."""
    size = first.shape[0]
    for r in range(size):
        fr = first[r]
        base_r = offsets[r] - fr
        for c in range(fr, r + 1):
            fc = first[c]
            base_c = offsets[c] - fc
            start = fr if fr > fc else fc
            s = values[base_r + c]
            for m in range(start, c):
                s -= values[base_r + m] * values[base_c + m]
            if c < r:
                values[base_r + c] = s / values[base_c + c]
            else:
                if not (s > 0.0) or not math.isfinite(s):
                    return False
                values[base_r + r] = math.sqrt(s)
    return True


@njit(cache=True)
def _envelope_solve(values, first, offsets, rhs):
    """Solve L L^T x = rhs with the factor from _envelope_cholesky; return x."""
    size = first.shape[0]
    y = rhs.copy()
    for r in range(size):
        base = offsets[r] - first[r]
        s = y[r]
        for m in range(first[r], r):
            s -= values[base + m] * y[m]
        y[r] = s / values[base + r]
    for r in range(size - 1, -1, -1):
        base = offsets[r] - first[r]
        y[r] /= values[base + r]
        xr = y[r]
        for m in range(first[r], r):
            y[m] -= values[base + m] * xr
    return y


@njit(cache=True)
def _apply_step(poses, position, step):
    """Return poses moved by step (yaw wrapped)."""
    moved = poses.copy()
    for node in range(poses.shape[0]):
        p = position[node]
        if p >= 0:
            moved[node, 0] += step[3 * p]
            moved[node, 1] += step[3 * p + 1]
            moved[node, 2] = _wrap(moved[node, 2] + step[3 * p + 2])
    return moved


@njit(cache=True)
def _levenberg_marquardt(poses, nodes, z, info, kernel, scale, position, first, offsets,
                         max_iterations, relative_tolerance):
    """Run LM on the robust cost; return (poses, iterations, initial, final, converged)."""
    size = first.shape[0]
    values, gradient, cost = _build_system(poses, nodes, z, info, kernel, scale, position,
                                           first, offsets)
    initial = _total_cost(poses, nodes, z, info, kernel, scale)
    current = initial
    if size == 0:
        return poses, 0, initial, current, True
    diagonal_index = offsets[1:] - 1
    damping = 1e-6
    iterations = 0
    converged = False
    while iterations < max_iterations:
        iterations += 1
        damped = values.copy()
        for r in range(size):
            d = values[diagonal_index[r]]
            damped[diagonal_index[r]] = d + damping * d + 1e-12
        if not _envelope_cholesky(damped, first, offsets):
            damping *= 10.0
            if damping > 1e12:
                break
            continue
        step = _envelope_solve(damped, first, offsets, -gradient)
        candidate = _apply_step(poses, position, step)
        candidate_cost = _total_cost(candidate, nodes, z, info, kernel, scale)
        if candidate_cost <= current:
            decrease = current - candidate_cost
            poses = candidate
            current = candidate_cost
            damping = max(damping / 10.0, 1e-12)
            if decrease <= relative_tolerance * max(current, 1e-300) or current == 0.0:
                converged = True
                break
            values, gradient, cost = _build_system(poses, nodes, z, info, kernel, scale,
                                                   position, first, offsets)
        else:
            damping *= 10.0
            if damping > 1e12:
                # No descent at any damping: a (local) minimum to machine precision.
                converged = True
                break
    return poses, iterations, initial, current, converged
