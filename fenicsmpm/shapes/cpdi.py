"""CPDI shape functions (convected particle domain interpolation, 2D) on any P1/Q1 mesh.

A particle's domain Omega_p is a quadrilateral with corners x_1..x_4 (counter-clockwise).
With M_c the bilinear corner functions of the domain and S_i the grid's standard shape
functions evaluated at the corners (Sadeghirad et al. 2011, 2013; seed 004 §2.5):
    phi_ip      = (1/V_p) sum_c w_c S_i(x_c),      w_c = int_{Omega_p} M_c dx,
    grad phi_ip = (1/V_p) sum_c S_i(x_c) g_c,      g_c = int_{Omega_p} grad M_c dx
                = 1/2 R (x_{c+1} - x_{c-1}),       R (a, b) = (b, -a)  (the boundary integral
                  of M_c n over the two edges at corner c),  V_p = sum_c w_c.
CPDI1 (seed 004 eqs 2.24-2.25, corrected in BENCHMARKS.md "CPDI1"): the domain is the
parallelogram of edge vectors r1, r2 (r_k = F_p r_k^0),
    x1 = x_p - (r1 + r2)/2, x2 = x_p + (r1 - r2)/2, x3 = x_p + (r1 + r2)/2, x4 = x_p - (r1 - r2)/2,
so w_c = V_p / 4 and the gradient above is
    grad phi_ip = 1/(2 V_p) {[S_i(x1) - S_i(x3)] [r1y - r2y; r2x - r1x]
                             + [S_i(x2) - S_i(x4)] [r1y + r2y; -r1x - r2x]},  V_p = r1 x r2.
CPDI2 (Sadeghirad et al. 2013, quadrilateral domains): the corners are material points
themselves, moved with the grid velocity, x_c += dt sum_i S_i(x_c) v_i, so the domain can
take any quadrilateral shape; w_c is integrated exactly by 2 x 2 Gauss points.
Both satisfy sum_i phi_ip = 1 and sum_i grad phi_ip = 0 and reproduce affine fields exactly
(S_i does at each corner).
"""
import numpy as np
from numba import njit, prange

from ..kernels.threads import PRANGE, chunk, particle_chunks

N_CORNERS = 4
_GP = (0.5 - 0.5 / np.sqrt(3.0), 0.5 + 0.5 / np.sqrt(3.0))


@njit(cache=True)
def _cpdi1_corners(x, F, r0, corners_out, lo, hi):
    for p in range(lo, hi):
        r1x = F[p, 0, 0] * r0[p, 0, 0] + F[p, 0, 1] * r0[p, 0, 1]
        r1y = F[p, 1, 0] * r0[p, 0, 0] + F[p, 1, 1] * r0[p, 0, 1]
        r2x = F[p, 0, 0] * r0[p, 1, 0] + F[p, 0, 1] * r0[p, 1, 1]
        r2y = F[p, 1, 0] * r0[p, 1, 0] + F[p, 1, 1] * r0[p, 1, 1]
        corners_out[p, 0, 0] = x[p, 0] - 0.5 * (r1x + r2x)
        corners_out[p, 0, 1] = x[p, 1] - 0.5 * (r1y + r2y)
        corners_out[p, 1, 0] = x[p, 0] + 0.5 * (r1x - r2x)
        corners_out[p, 1, 1] = x[p, 1] + 0.5 * (r1y - r2y)
        corners_out[p, 2, 0] = x[p, 0] + 0.5 * (r1x + r2x)
        corners_out[p, 2, 1] = x[p, 1] + 0.5 * (r1y + r2y)
        corners_out[p, 3, 0] = x[p, 0] - 0.5 * (r1x - r2x)
        corners_out[p, 3, 1] = x[p, 1] - 0.5 * (r1y - r2y)


@njit(parallel=PRANGE, cache=True)
def cpdi1_corners(x, F, r0, corners_out):
    """Corners of the CPDI1 parallelograms: r_k = F_p r_k^0 (in-plane block of F), corners
    x_p -(r1+r2)/2, x_p +(r1-r2)/2, x_p +(r1+r2)/2, x_p -(r1-r2)/2. r0: (n, 2, 2), r0[p, k]
    is the initial edge vector k."""
    n = x.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _cpdi1_corners(x, F, r0, corners_out, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _cpdi1_corners(x, F, r0, corners_out, lo, hi)


@njit(cache=True)
def _corner_weights(corners, w_out, g_out, lo, hi):
    vmin = np.inf
    # reference corners (0,0), (1,0), (1,1), (0,1) in the counter-clockwise order
    rx = (0.0, 1.0, 1.0, 0.0)
    ry = (0.0, 0.0, 1.0, 1.0)
    M = np.empty(4)
    for p in range(lo, hi):
        for c in range(4):
            w_out[p, c] = 0.0
            nxt = corners[p, (c + 1) % 4]
            prv = corners[p, (c + 3) % 4]
            g_out[p, c, 0] = 0.5 * (nxt[1] - prv[1])
            g_out[p, c, 1] = -0.5 * (nxt[0] - prv[0])
        for gi in range(2):
            for gj in range(2):
                s, t = _GP[gi], _GP[gj]
                J00 = J01 = J10 = J11 = 0.0
                for c in range(4):
                    fs = s if rx[c] == 1.0 else 1.0 - s
                    ft = t if ry[c] == 1.0 else 1.0 - t
                    M[c] = fs * ft
                    ds = (1.0 if rx[c] == 1.0 else -1.0) * ft
                    dt = (1.0 if ry[c] == 1.0 else -1.0) * fs
                    J00 += corners[p, c, 0] * ds
                    J01 += corners[p, c, 0] * dt
                    J10 += corners[p, c, 1] * ds
                    J11 += corners[p, c, 1] * dt
                det = J00 * J11 - J01 * J10
                for c in range(4):
                    w_out[p, c] += 0.25 * M[c] * det
        V = w_out[p, 0] + w_out[p, 1] + w_out[p, 2] + w_out[p, 3]
        vmin = min(vmin, V)
    return vmin


@njit(parallel=PRANGE, cache=True)
def corner_weights(corners, w_out, g_out):
    """w_c = int M_c dx (2 x 2 Gauss on the bilinear map of the quadrilateral, exact) and
    g_c = 1/2 R (x_{c+1} - x_{c-1}) for each particle's domain (corners counter-clockwise).
    Returns the smallest domain area (<= 0: a domain turned inside out)."""
    n = corners.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _corner_weights(corners, w_out, g_out, np.int64(0), n)
    vmin = np.empty(nc)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        vmin[c] = _corner_weights(corners, w_out, g_out, lo, hi)
    return vmin.min()


@njit(cache=True)
def _cpdi_combine(D, cnodes, cN, w, g, nodes_out, N_out, dN_out, count_out, lo, hi):
    d = len(D)
    nv = nodes_out.shape[1]
    for p in range(lo, hi):
        V = w[p, 0] + w[p, 1] + w[p, 2] + w[p, 3]
        cnt = 0
        for c in range(4):
            for a in range(cnodes.shape[2]):
                s = cN[p, c, a]
                if s == 0.0:
                    continue
                i = cnodes[p, c, a]
                slot = cnt
                for b in range(cnt):
                    if nodes_out[p, b] == i:
                        slot = b
                        break
                if slot == cnt:
                    nodes_out[p, cnt] = i
                    N_out[p, cnt] = 0.0
                    for k in range(d):
                        dN_out[p, cnt, k] = 0.0
                    cnt += 1
                N_out[p, slot] += w[p, c] * s / V
                for k in range(d):
                    dN_out[p, slot, k] += g[p, c, k] * s / V
        count_out[p] = cnt
        for a in range(cnt, nv):
            nodes_out[p, a] = nodes_out[p, 0]
            N_out[p, a] = 0.0
            for k in range(d):
                dN_out[p, a, k] = 0.0


@njit(parallel=PRANGE, cache=True)
def cpdi_combine(D, cnodes, cN, w, g, nodes_out, N_out, dN_out, count_out):
    """phi_ip and grad phi_ip from the corner shape functions (see the module docstring).

    cnodes, cN: (n, 4, nvc) grid nodes and standard shape values at each corner; w (n, 4),
    g (n, 4, 2) from corner_weights. Nodes shared by several corners are merged: each node
    appears once (count_out[p] of them), then padding (a valid node with N = dN = 0)."""
    n = cnodes.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _cpdi_combine(D, cnodes, cN, w, g, nodes_out, N_out, dN_out, count_out, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _cpdi_combine(D, cnodes, cN, w, g, nodes_out, N_out, dN_out, count_out, lo, hi)


@njit(cache=True)
def _move_corners(D, cnodes, cN, du, corners, lo, hi):
    d = len(D)
    for p in range(lo, hi):
        for c in range(4):
            for a in range(cnodes.shape[2]):
                i = cnodes[p, c, a]
                for k in range(d):
                    corners[p, c, k] += cN[p, c, a] * du[i, k]


@njit(parallel=PRANGE, cache=True)
def move_corners(D, cnodes, cN, du, corners):
    """CPDI2 corner update x_c += sum_i S_i(x_c) du_i (du: the step's nodal displacement)."""
    n = corners.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _move_corners(D, cnodes, cN, du, corners, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _move_corners(D, cnodes, cN, du, corners, lo, hi)


def initial_edges(grid, particles):
    """CPDI1 edge vectors r_k^0 (n, 2, 2) of area V0_p: on quadrilaterals the particle's cell
    edges e_k = x_(vertex 2^k) - x_(vertex 0) scaled by sqrt(V0_p / |e1 x e2|) (for
    Particles.fill with n per direction: e_k / n on parallelogram cells); on triangles an
    axis-aligned square of side sqrt(V0_p)."""
    from . import standard as ks
    n = len(particles)
    r0 = np.zeros((n, 2, 2))
    if grid.kind == ks.SIMPLEX:
        s = np.sqrt(particles.V0)
        r0[:, 0, 0] = s
        r0[:, 1, 1] = s
        return r0
    cn = grid.cell_nodes[particles.cell]
    e1 = grid.node_x[cn[:, 1]] - grid.node_x[cn[:, 0]]
    e2 = grid.node_x[cn[:, 2]] - grid.node_x[cn[:, 0]]
    cross = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    s = np.sqrt(particles.V0 / np.abs(cross))
    flip = cross < 0                          # keep r1 x r2 > 0 (corners counter-clockwise)
    r0[:, 0] = np.where(flip[:, None], e2, e1) * s[:, None]
    r0[:, 1] = np.where(flip[:, None], e1, e2) * s[:, None]
    return r0


class CpdiShape:
    """CPDI1 (version 1) or CPDI2 (version 2, quadrilateral domains) for a 2D Simulation.

    Adds the particle field `cpdi_r0` (n, 2, 2), the initial edge vectors (initial_edges),
    and for CPDI2 `cpdi_corners` (n, 4, 2), started as the CPDI1 parallelograms. A corner
    outside the mesh (a particle at the boundary) uses the basis of the particle's own cell,
    extended linearly: the weights still sum to 1 and reproduce affine fields."""

    def __init__(self, sim, version):
        from .gimp import _RING_MESSAGE
        grid, p = sim.grid, sim.particles
        if grid.gdim != 2:
            raise NotImplementedError(f"CPDI shape functions are implemented in 2D only, "
                                      f"got gdim = {grid.gdim}")
        if not grid.has_vertex_ring():
            raise ValueError(_RING_MESSAGE.format(name="CPDI"))
        self.version = int(version)
        if not hasattr(p, "cpdi_r0"):
            p.add_field("cpdi_r0", (2, 2))[:] = initial_edges(grid, p)
        if self.version == 2 and not hasattr(p, "cpdi_corners"):
            cpdi1_corners(p.x, p.F, p.cpdi_r0, p.add_field("cpdi_corners", (N_CORNERS, 2)))
        self._corner_shape = None

    def before_locate(self, sim):
        """CPDI2: move the corners with the last step's grid displacement dt v_i (the nodal
        velocity the integrator left in sim.nodal), x_c += sum_i S_i(x_c) dt v_i, with the
        corner shape functions of that step (particles not yet migrated)."""
        cs, self._corner_shape = self._corner_shape, None
        if self.version == 2 and cs is not None and "velocity" in sim.nodal:
            move_corners(sim.grid.D, cs[0], cs[1], sim.dt * sim.nodal["velocity"],
                         sim.particles.cpdi_corners)

    def evaluate(self, sim):
        """(nodes, N, dN) of the local particles; nv = the largest number of distinct nodes a
        particle's corners reach (padded)."""
        p, g = sim.particles, sim.grid
        n, nvc = len(p), g.cell_nodes.shape[1]
        if self.version == 2:
            corners = p.cpdi_corners
        else:
            corners = np.empty((n, N_CORNERS, 2))
            cpdi1_corners(p.x, p.F, p.cpdi_r0, corners)
        cnodes, cN, _ = shape_at_points(g, corners, p.cell)
        cnodes = cnodes.reshape(n, N_CORNERS, nvc)
        cN = cN.reshape(n, N_CORNERS, nvc)
        w = np.empty((n, N_CORNERS))
        gc = np.empty((n, N_CORNERS, 2))
        if n and corner_weights(corners, w, gc) <= 0.0:
            bad = int(np.argmin(w.sum(axis=1)))
            raise RuntimeError(f"CPDI: the domain of particle {int(p.id[bad])} at "
                               f"{np.round(p.x[bad], 6).tolist()} has turned inside out "
                               f"(area {w[bad].sum():.3g})")
        width = N_CORNERS * nvc
        nodes = np.empty((n, width), dtype=np.int32)
        N = np.empty((n, width))
        dN = np.empty((n, width, 2))
        count = np.empty(n, dtype=np.int64)
        cpdi_combine(g.D, cnodes, cN, w, gc, nodes, N, dN, count)
        self._corner_shape = (cnodes, cN)
        return trim_stencil(nodes, N, dN, count)


def shape_at_points(g, points, cells_hint):
    """Standard-MPM (nodes, N, dN) at points (n, k, 2) of n particles, flattened to n k rows.
    A point outside the local mesh uses its particle's cell (`cells_hint`), extended linearly."""
    from . import standard as ks
    n, k = points.shape[:2]
    nvc = g.cell_nodes.shape[1]
    flat = np.ascontiguousarray(points.reshape(-1, 2))
    hint = np.repeat(cells_hint, k)
    cells, xi = g.locate(flat, hint)
    lost = np.flatnonzero(cells < 0)
    if len(lost):
        cells[lost] = hint[lost]
        xl = np.empty((len(lost), 2))
        ks.pull_back(g.kind, np.ascontiguousarray(flat[lost]), cells[lost], g.cell_nodes,
                     g.node_x, g.affine_Jinv, xl, np.empty(len(lost), dtype=np.bool_))
        xi[lost] = xl
    nodes = np.empty((n * k, nvc), dtype=np.int32)
    N = np.empty((n * k, nvc))
    dN = np.empty((n * k, nvc, 2))
    ks.mpm_shape(g.D, g.kind, cells, xi, g.cell_nodes, g.node_x, g.simplex_grad, g.affine_Jinv,
                 nodes, N, dN)
    return nodes, N, dN


def trim_stencil(nodes, N, dN, count):
    """The combined stencil cut to the largest distinct-node count over particles (>= 1)."""
    nv = max(int(count.max()) if len(count) else 1, 1)
    return (np.ascontiguousarray(nodes[:, :nv]), np.ascontiguousarray(N[:, :nv]),
            np.ascontiguousarray(dN[:, :nv]))
