"""Numba kernels for point location and standard-MPM shape functions on P1/Q1 cells.

Reference cells follow basix/dolfinx: the unit simplex with vertex 0 at the origin and
vertex k+1 on axis k, and the unit square/cube with vertex a at the corner whose
coordinate along axis k is bit k of a. So the Q1 basis is the tensor product
N_a(xi) = prod_k (xi_k if bit_k(a) else 1 - xi_k), and the P1 basis is
N_0 = 1 - sum(xi), N_{k+1} = xi_k.

Kernels are written for any dimension d in {2, 3}; `kind` is 0 for simplices and 1 for
tensor-product cells. The per-point passes (location, pull-back, shape functions) run on
numba's threads in chunks (kernels.threads): a serial loop `_name(..., lo, hi)` per chunk.
"""
import numpy as np
from numba import njit, prange

from ..kernels.threads import PRANGE, chunk, particle_chunks

SIMPLEX = 0
TENSOR = 1
INSIDE_TOL = 1e-10


@njit(cache=True)
def _q1_basis(xi, d, N, dNdxi):
    """Q1 values N[a] and reference gradients dNdxi[a, m] at xi (tensor product)."""
    nv = 1 << d
    for a in range(nv):
        val = 1.0
        for k in range(d):
            val *= xi[k] if (a >> k) & 1 else 1.0 - xi[k]
        N[a] = val
        for m in range(d):
            g = 1.0 if (a >> m) & 1 else -1.0
            for k in range(d):
                if k != m:
                    g *= xi[k] if (a >> k) & 1 else 1.0 - xi[k]
            dNdxi[a, m] = g


@njit(cache=True)
def _inv_small(J, d, Jinv):
    """Inverse of a 2x2 or 3x3 matrix; returns the determinant."""
    if d == 2:
        det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
        Jinv[0, 0] = J[1, 1] / det
        Jinv[0, 1] = -J[0, 1] / det
        Jinv[1, 0] = -J[1, 0] / det
        Jinv[1, 1] = J[0, 0] / det
        return det
    det = (J[0, 0] * (J[1, 1] * J[2, 2] - J[1, 2] * J[2, 1])
           - J[0, 1] * (J[1, 0] * J[2, 2] - J[1, 2] * J[2, 0])
           + J[0, 2] * (J[1, 0] * J[2, 1] - J[1, 1] * J[2, 0]))
    Jinv[0, 0] = (J[1, 1] * J[2, 2] - J[1, 2] * J[2, 1]) / det
    Jinv[0, 1] = (J[0, 2] * J[2, 1] - J[0, 1] * J[2, 2]) / det
    Jinv[0, 2] = (J[0, 1] * J[1, 2] - J[0, 2] * J[1, 1]) / det
    Jinv[1, 0] = (J[1, 2] * J[2, 0] - J[1, 0] * J[2, 2]) / det
    Jinv[1, 1] = (J[0, 0] * J[2, 2] - J[0, 2] * J[2, 0]) / det
    Jinv[1, 2] = (J[0, 2] * J[1, 0] - J[0, 0] * J[1, 2]) / det
    Jinv[2, 0] = (J[1, 0] * J[2, 1] - J[1, 1] * J[2, 0]) / det
    Jinv[2, 1] = (J[0, 1] * J[2, 0] - J[0, 0] * J[2, 1]) / det
    Jinv[2, 2] = (J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]) / det
    return det


@njit(cache=True)
def _pull_back_one(kind, c, x, cell_nodes, node_x, affine_Jinv, xi, N, dN, J, Jinv, r):
    """Reference coordinates xi of point x in cell c; returns True if they are trustworthy.

    Affine cells (all simplices; parallelogram quads/hexes when affine_Jinv has one entry
    per cell): xi = J^-1 (x - x_0), always exact. Other Q1 cells: Newton on the multilinear
    map (steps clipped to the reference-cell size, at most 40 iterations), converged when
    |x(xi) - x| <= 1e-13 times the cell's size (1e-10 if round-off stalls it); the scratch arrays N, dN, J, Jinv, r come
    from the caller (no allocation per point)."""
    d = x.shape[0]
    n0 = cell_nodes[c, 0]
    if kind == SIMPLEX or affine_Jinv.shape[0] > 0:
        for i in range(d):
            s = 0.0
            for j in range(d):
                s += affine_Jinv[c, i, j] * (x[j] - node_x[n0, j])
            xi[i] = s
        return True
    nv = 1 << d
    size = 0.0
    for a in range(1, nv):
        for i in range(d):
            size = max(size, abs(node_x[cell_nodes[c, a], i] - node_x[n0, i]))
    for k in range(d):
        xi[k] = 0.5
    for it in range(40):
        _q1_basis(xi, d, N, dN)
        res = 0.0
        for i in range(d):
            r[i] = -x[i]
            for j in range(d):
                J[i, j] = 0.0
        for a in range(nv):
            na = cell_nodes[c, a]
            for i in range(d):
                r[i] += N[a] * node_x[na, i]
                for j in range(d):
                    J[i, j] += node_x[na, i] * dN[a, j]
        for i in range(d):
            res = max(res, abs(r[i]))
        if res <= 1e-13 * size:
            return True
        det = _inv_small(J, d, Jinv)
        if det == 0.0 or not np.isfinite(det):
            return False
        for i in range(d):
            s = 0.0
            for j in range(d):
                s += Jinv[i, j] * r[j]
            xi[i] -= min(max(s, -1.0), 1.0)
    return res <= 1e-10 * size          # round-off floor reached: accept if close enough


@njit(cache=True, inline="always")
def _affine_inside(kind, c, x, p, cell_nodes, node_x, affine_Jinv, xi_out, tol):
    """_pull_back_one's affine case written out for point p of x (xi_out[p] = J^-1 (x_p -
    x_0) in cell c) and whether it lies inside within tol (_inside): inlined in the location
    loops, where a call of the general function with its many array arguments cost more than
    the arithmetic (the corners of 146,882 triangular CPDI2 domains on a structured
    triangle mesh: located in 30 -> 21 ms on one thread)."""
    d = x.shape[1]
    n0 = cell_nodes[c, 0]
    ok = True
    s_sum = 0.0
    for i in range(d):
        s = 0.0
        for j in range(d):
            s += affine_Jinv[c, i, j] * (x[p, j] - node_x[n0, j])
        xi_out[p, i] = s
        s_sum += s
        if s < -tol or (kind != SIMPLEX and s > 1.0 + tol):
            ok = False
    return ok and (kind != SIMPLEX or s_sum <= 1.0 + tol)


@njit(cache=True)
def _inside(kind, xi, tol):
    d = xi.shape[0]
    if kind == SIMPLEX:
        s = 0.0
        for k in range(d):
            if xi[k] < -tol:
                return False
            s += xi[k]
        return s <= 1.0 + tol
    for k in range(d):
        if xi[k] < -tol or xi[k] > 1.0 + tol:
            return False
    return True


@njit(cache=True)
def _pull_back(kind, x, cells, cell_nodes, node_x, affine_Jinv, xi_out, inside_out, lo, hi):
    d = x.shape[1]
    nv = cell_nodes.shape[1]
    N, dN, J, Jinv, r = np.empty(nv), np.empty((nv, d)), np.empty((d, d)), np.empty((d, d)), np.empty(d)
    affine = kind == SIMPLEX or affine_Jinv.shape[0] > 0
    for p in range(lo, hi):
        c = cells[p]
        if c < 0:
            inside_out[p] = False
            continue
        if affine:
            inside_out[p] = _affine_inside(kind, c, x, p, cell_nodes, node_x, affine_Jinv,
                                           xi_out, INSIDE_TOL)
            continue
        ok = _pull_back_one(kind, c, x[p], cell_nodes, node_x, affine_Jinv, xi_out[p], N, dN, J, Jinv, r)
        inside_out[p] = ok and _inside(kind, xi_out[p], INSIDE_TOL)


@njit(parallel=PRANGE, cache=True)
def pull_back(kind, x, cells, cell_nodes, node_x, affine_Jinv, xi_out, inside_out):
    """Reference coordinates of each point in its given cell, and whether it lies inside.

    affine_Jinv: per-cell inverse Jacobians of affine cells, or an array of shape (0, d, d)
    for general Q1 cells (Newton). Points with cells[p] < 0 are reported as outside."""
    n = x.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _pull_back(kind, x, cells, cell_nodes, node_x, affine_Jinv, xi_out, inside_out,
                          np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _pull_back(kind, x, cells, cell_nodes, node_x, affine_Jinv, xi_out, inside_out, lo, hi)


@njit(cache=True)
def _locate_structured(D, kind, x, origin, first, spacing, nbox, box_cells, cell_nodes, node_x,
                       affine_Jinv, cells_out, xi_out, lo, hi):
    d = len(D)
    nv = cell_nodes.shape[1]
    N, dN, J, Jinv, r = np.empty(nv), np.empty((nv, d)), np.empty((d, d)), np.empty((d, d)), np.empty(d)
    for p in range(lo, hi):
        flat = 0
        stride = 1
        ok = True
        for k in range(d):
            tg = (x[p, k] - origin[k]) / spacing[k]      # the same bits on every rank
            i = int(np.floor(tg)) - first[k]
            t = tg - first[k]
            if i == nbox[k] and t - nbox[k] < 1e-9:
                i = nbox[k] - 1  # on the upper face
            if i == -1 and t > -1e-9:
                i = 0
            if i < 0 or i >= nbox[k]:
                ok = False
                break
            flat += i * stride
            stride *= nbox[k]
        cells_out[p] = -1
        if not ok:
            continue
        if kind == TENSOR and affine_Jinv.shape[0] > 0:
            # one parallelogram cell per box: xi = J^-1 (x - x_0), no search, no Newton
            c = box_cells[flat, 0]
            n0 = cell_nodes[c, 0]
            for i in range(d):
                s = 0.0
                for j in range(d):
                    s += affine_Jinv[c, i, j] * (x[p, j] - node_x[n0, j])
                xi_out[p, i] = min(max(s, 0.0), 1.0)
            cells_out[p] = c
            continue
        for j in range(box_cells.shape[1]):
            c = box_cells[flat, j]
            if c < 0:
                break
            if kind == SIMPLEX:
                if _affine_inside(kind, c, x, p, cell_nodes, node_x, affine_Jinv, xi_out, 1e-9):
                    cells_out[p] = c
                    break
                continue
            ok = _pull_back_one(kind, c, x[p], cell_nodes, node_x, affine_Jinv, xi_out[p], N, dN, J, Jinv, r)
            if ok and _inside(kind, xi_out[p], 1e-9):
                cells_out[p] = c
                break


@njit(parallel=PRANGE, cache=True)
def locate_structured(D, kind, x, origin, first, spacing, nbox, box_cells, cell_nodes, node_x,
                      affine_Jinv, cells_out, xi_out):
    """O(1) location on a structured grid of boxes (rectangles or boxes split into cells).

    The box index is found by arithmetic, then the (at most 6) cells of that box are tested.
    `origin` is the global lattice's lower corner (the same on every rank) and `first` the
    global index of this rank's first box per axis, so a point on a grid line between ranks
    gets the same box on every rank and exactly one rank owns it. Points outside every local
    box get cell -1. D: tuple of length gdim (compile-time)."""
    n = x.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _locate_structured(D, kind, x, origin, first, spacing, nbox, box_cells,
                                  cell_nodes, node_x, affine_Jinv, cells_out, xi_out,
                                  np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _locate_structured(D, kind, x, origin, first, spacing, nbox, box_cells, cell_nodes,
                           node_x, affine_Jinv, cells_out, xi_out, lo, hi)


@njit(cache=True, inline="always")
def _values(kind, d, c, xi, p, cell_nodes, Nq, dNq, nodes_out, N_out):
    """Point p's cell nodes and basis values N_a(xi_p) in row p (P1: 1 - sum xi, xi_k; Q1:
    _q1_basis, whose reference gradients stay in dNq for the caller)."""
    nv = cell_nodes.shape[1]
    for a in range(nv):
        nodes_out[p, a] = cell_nodes[c, a]
    if kind == SIMPLEX:
        s = 0.0
        for k in range(d):
            N_out[p, k + 1] = xi[p, k]
            s += xi[p, k]
        N_out[p, 0] = 1.0 - s
        return
    _q1_basis(xi[p], d, Nq, dNq)
    for a in range(nv):
        N_out[p, a] = Nq[a]


@njit(cache=True)
def _mpm_shape(D, kind, cells, xi, cell_nodes, node_x, simplex_grad, affine_Jinv,
               nodes_out, N_out, dN_out, lo, hi):
    d = len(D)
    nv = cell_nodes.shape[1]
    Nq = np.empty(nv)
    dNq = np.empty((nv, d))
    J = np.empty((d, d))
    Jinv = np.empty((d, d))
    for p in range(lo, hi):
        c = cells[p]
        _values(kind, d, c, xi, p, cell_nodes, Nq, dNq, nodes_out, N_out)
        if kind == SIMPLEX:
            for a in range(nv):
                for k in range(d):
                    dN_out[p, a, k] = simplex_grad[c, a, k]
            continue
        if affine_Jinv.shape[0] > 0:
            for i in range(d):
                for j in range(d):
                    Jinv[i, j] = affine_Jinv[c, i, j]
        else:
            for i in range(d):
                for j in range(d):
                    J[i, j] = 0.0
            for a in range(nv):
                na = cell_nodes[c, a]
                for i in range(d):
                    for j in range(d):
                        J[i, j] += node_x[na, i] * dNq[a, j]
            _inv_small(J, d, Jinv)
        for a in range(nv):
            for k in range(d):
                s = 0.0
                for j in range(d):
                    s += dNq[a, j] * Jinv[j, k]
                dN_out[p, a, k] = s


@njit(parallel=PRANGE, cache=True)
def mpm_shape(D, kind, cells, xi, cell_nodes, node_x, simplex_grad, affine_Jinv,
              nodes_out, N_out, dN_out):
    """Standard MPM shape functions: the Lagrange basis of the particle's cell at the particle.

    nodes_out[p, a] = node index, N_out[p, a] = N_a(x_p), dN_out[p, a, :] = grad N_a(x_p).
    D: tuple of length gdim (compile-time dimension). Simplices use their constant gradients;
    Q1 cells use the per-cell inverse Jacobian when they are parallelograms (affine_Jinv with
    one entry per cell), else the Jacobian at the point."""
    n = cells.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _mpm_shape(D, kind, cells, xi, cell_nodes, node_x, simplex_grad, affine_Jinv,
                          nodes_out, N_out, dN_out, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _mpm_shape(D, kind, cells, xi, cell_nodes, node_x, simplex_grad, affine_Jinv,
                   nodes_out, N_out, dN_out, lo, hi)


@njit(cache=True)
def _mpm_values(D, kind, cells, xi, cell_nodes, nodes_out, N_out, lo, hi):
    d = len(D)
    nv = cell_nodes.shape[1]
    Nq = np.empty(nv)
    dNq = np.empty((nv, d))
    for p in range(lo, hi):
        _values(kind, d, cells[p], xi, p, cell_nodes, Nq, dNq, nodes_out, N_out)


@njit(parallel=PRANGE, cache=True)
def mpm_values(D, kind, cells, xi, cell_nodes, nodes_out, N_out):
    """mpm_shape without the gradients: nodes_out[p, a] and N_out[p, a] = N_a(x_p) only (the
    corner values CPDI combines, shapes.cpdi.shape_at_points(gradients=False))."""
    n = cells.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _mpm_values(D, kind, cells, xi, cell_nodes, nodes_out, N_out, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _mpm_values(D, kind, cells, xi, cell_nodes, nodes_out, N_out, lo, hi)


@njit(cache=True)
def reference_points_to_physical(kind, cells, xi, cell_nodes, node_x, x_out, detJ_out):
    """Map reference points to physical space; also return |det J| there (for volumes)."""
    d = xi.shape[1]
    nv = cell_nodes.shape[1]
    Nq = np.empty(nv)
    dNq = np.empty((nv, d))
    J = np.empty((d, d))
    Jinv = np.empty((d, d))
    for p in range(cells.shape[0]):
        c = cells[p]
        if kind == SIMPLEX:
            s = 0.0
            for k in range(d):
                Nq[k + 1] = xi[p, k]
                s += xi[p, k]
            Nq[0] = 1.0 - s
            for a in range(nv):
                for k in range(d):
                    dNq[a, k] = 0.0
            for k in range(d):
                dNq[0, k] = -1.0
                dNq[k + 1, k] = 1.0
        else:
            _q1_basis(xi[p], d, Nq, dNq)
        for i in range(d):
            x_out[p, i] = 0.0
            for j in range(d):
                J[i, j] = 0.0
        for a in range(nv):
            na = cell_nodes[c, a]
            for i in range(d):
                x_out[p, i] += Nq[a] * node_x[na, i]
                for j in range(d):
                    J[i, j] += node_x[na, i] * dNq[a, j]
        detJ_out[p] = abs(_inv_small(J, d, Jinv))


@njit(cache=True)
def first_inside(kind, x, offsets, candidates, cell_nodes, node_x, affine_Jinv, cells_out, xi_out):
    """For each point p, the first candidate cell (candidates[offsets[p]:offsets[p+1]]) that
    contains it according to the exact pull-back; -1 if none does."""
    d = x.shape[1]
    nv = cell_nodes.shape[1]
    N, dN, J, Jinv, r = np.empty(nv), np.empty((nv, d)), np.empty((d, d)), np.empty((d, d)), np.empty(d)
    for p in range(x.shape[0]):
        cells_out[p] = -1
        for q in range(offsets[p], offsets[p + 1]):
            c = candidates[q]
            ok = _pull_back_one(kind, c, x[p], cell_nodes, node_x, affine_Jinv, xi_out[p], N, dN, J, Jinv, r)
            if ok and _inside(kind, xi_out[p], INSIDE_TOL):
                cells_out[p] = c
                break
