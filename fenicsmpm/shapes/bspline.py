"""Quadratic B-spline shape functions on structured quadrilateral/hexahedral grids:
Simulation(shape="bspline2") (B-spline MPM, Steffen, Kirby & Berzins 2008).

Basis. Node i of a lattice of spacing L (per axis) carries the C1 quadratic B-spline centred
on it, with s = (x - x_i) / L,
    N(s) = 3/4 - s^2               |s| <= 1/2
           (3/2 - |s|)^2 / 2       1/2 < |s| < 3/2
           0                       |s| >= 3/2,
(knots at the cell midpoints x_i +- L/2, x_i +- 3L/2), and the weight of node i at a
particle is the tensor product of the 1D factors, grad the product rule. A particle's 1D
support spans the 3 nodes nearest to it (j_c - 1, j_c, j_c + 1, j_c the nearest node), all in
its own cell or a cell sharing a vertex with it: the vertex ghost ring of cpGIMP suffices in
parallel, and two of its nodes are joined by a chain of 2 cells (implicit pattern: rings = 2).

Boundary. Inside, the centred splines sum to 1 and reproduce x (sum_i N_i x_i = x). At the
grid's ends [0, n L] (per axis) the spline of the ghost node x_{-1} = -L (support reaching
L/2 into the grid) is folded into the first two nodes by linear extrapolation of the nodal
values, u_{-1} = 2 u_0 - u_1:
    N'_0 = N_0 + 2 N_{-1},    N'_1 = N_1 - N_{-1}         (likewise at x_n with x_{n+1}).
Every field sum_i N_i u_i with u linear in x_i is unchanged by the fold (the ghost value is
the linear one), so the modified basis keeps the partition of unity and reproduces linear
fields exactly on the whole grid, particles in the boundary cells included; the gradients sum
to 0 and sum_i x_i (x) grad N_i = I. On the boundary half-cell 0 <= x <= L/2 the folded
functions are N'_0 = 1 - x/L and N'_1 = x/L (N_2 vanishes there): non-negative, C1 at x = L/2,
and interpolating at the wall (N'_0 = 1, every other function 0 at x = 0), so a fixed boundary
node fixes the velocity on the wall. The span is the quadratic splines on the midpoint knots
that are linear on the two boundary half-cells, one function per grid node (the lumped mass
matrix and the boundary conditions of the Simulation apply unchanged); an axis of one cell
(n = 1) gets the linear hats. This boundary treatment was chosen over the open-knot-vector
basis (end knots repeated three times), which on the same midpoint knots has n + 3 functions
per axis, not one per grid node: its coefficients are not grid-node values, so neither the
nodal mass/momentum arrays nor the Simulation's fixed-node boundary conditions would apply
unchanged. (Steffen, Kirby & Berzins 2008 also modify the splines next to the boundary; their
exact end functions were not compared with these.)

Measured (tests/test_bspline.py, docs/guide/choosing.md): as accurate as cpGIMP on the
elastic columns under self-weight, but on the V3 manufactured solution its stress error
stops converging with 2 x 2 particles per cell (0.084 at 32 cells against cpGIMP's 0.012;
with 4 x 4 it converges, 0.017 against 0.015, which points to the particle quadrature);
shape="auto" does not pick it.

Particles are points (no domain): the weights depend on x_p only (no F, no particle field).
Particles must lie in the grid (lo <= x_p <= hi per axis): the formulas are evaluated on the
window of the nearest node, clamped to the grid.
"""
import numpy as np
from numba import njit, prange

from ..kernels.threads import PRANGE, chunk, particle_chunks
from .gimp import _RING_MESSAGE, LatticeShape, lattice, tensor_product

NS = 3          # nodes per axis of a particle's window


@njit(cache=True)
def bspline_1d(x, origin, L, n, S, dS):
    """Boundary-modified quadratic B-spline weights (S) and d/dx (dS) at x of the 3 lattice
    nodes j0, j0 + 1, j0 + 2 (global lattice indices from `origin`, n cells on the axis);
    returns j0. For n = 1 the third entry (node 2, not a grid node) gets 0. On the boundary
    half-cells (nearest node 0 or n) the folded end functions 1 - u, u (u: distance to the
    wall in cells), elsewhere the centred splines of the 3 nearest nodes."""
    t = (x - origin) / L
    jc = min(max(int(np.floor(t + 0.5)), 0), n)            # the nearest grid node
    j0 = min(max(jc - 1, 0), max(n - 2, 0))
    for q in range(NS):
        S[q] = 0.0
        dS[q] = 0.0
    if jc == 0 or jc == n:
        # boundary half-cell: the fold of the ghost spline, in closed form (exact: no
        # cancellation of N_1 - N_-1 near the wall, so no weight of -1e-16)
        u = t - jc if jc == 0 else jc - t                   # distance to the wall, in cells
        u = min(max(u, 0.0), 1.0)      # a particle out of the grid by round-off: the wall's
        sgn = 1.0 if jc == 0 else -1.0
        inner = jc + 1 if jc == 0 else jc - 1
        S[jc - j0] = 1.0 - u
        dS[jc - j0] = -sgn / L
        S[inner - j0] = u
        dS[inner - j0] = sgn / L
        return j0
    for j in range(jc - 1, jc + 2):
        s = t - j
        a = abs(s)
        if a <= 0.5:
            S[j - j0] = 0.75 - s * s
            dS[j - j0] = -2.0 * s / L
        elif a < 1.5:
            r = 1.5 - a
            S[j - j0] = 0.5 * r * r
            dS[j - j0] = -r / L if s > 0.0 else r / L
    return j0


@njit(cache=True)
def _bspline(D, x, origin, spacing, ncells, ilo, nlat, table, p0, p1,
             nodes_out, N_out, dN_out, count_out):
    d = len(D)
    Sk = np.empty((d, NS))
    dSk = np.empty((d, NS))
    off = np.empty((d, NS), dtype=np.int64)     # flat lattice offset of node q on axis k, -1 outside
    S = np.empty(NS)
    dS = np.empty(NS)
    nsk = np.full(d, NS, dtype=np.int64)
    bad = -1
    for p in range(p0, p1):
        stride = 1
        for k in range(d):
            j0 = bspline_1d(x[p, k], origin[k], spacing[k], ncells[k], S, dS)
            for q in range(NS):
                j = j0 + q
                jl = j - ilo[k]
                off[k, q] = jl * stride if (0 <= jl < nlat[k] and j <= ncells[k]) else -1
                Sk[k, q] = S[q]
                dSk[k, q] = dS[q]
            stride *= nlat[k]
        if tensor_product(d, nsk, Sk, dSk, off, table, p, True,
                          nodes_out, N_out, dN_out, count_out):
            bad = p
    return bad


@njit(parallel=PRANGE, cache=True)
def bspline_shape(D, x, origin, spacing, ncells, ilo, nlat, table,
                  nodes_out, N_out, dN_out, count_out):
    """Boundary-modified quadratic B-spline weights of every particle on its 3^d lattice
    nodes (see the module docstring). origin/spacing: global lattice origin (the grid's lower
    corner) and cell size per axis; ncells: cells per axis of the whole grid; ilo/nlat/table:
    the local part of the lattice (gimp.lattice). Output per particle as gimp_shape: the
    nodes of nonzero weight (or nonzero gradient) first, count_out of them, then padding.
    Returns -1, or the index of a particle that needs a node that is not local."""
    n = x.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _bspline(D, x, origin, spacing, ncells, ilo, nlat, table, np.int64(0), n,
                        nodes_out, N_out, dN_out, count_out)
    bad = np.empty(nc, dtype=np.int64)
    for c in prange(nc):
        p0, p1 = chunk(n, nc, c)
        bad[c] = _bspline(D, x, origin, spacing, ncells, ilo, nlat, table, p0, p1,
                          nodes_out, N_out, dN_out, count_out)
    return bad.max()


class BsplineShape(LatticeShape):
    """Boundary-modified quadratic B-spline shape functions (shape="bspline2") for a
    Simulation on a structured axis-aligned quadrilateral/hexahedral grid. Collective at
    construction."""
    name = "B-spline"

    def __init__(self, sim):
        grid = sim.grid
        self.lat = lattice(grid, name="Quadratic B-spline")
        if not grid.has_vertex_ring():
            raise ValueError(_RING_MESSAGE.format(name="B-spline"))
        lat = self.lat
        self.ncells = np.ascontiguousarray(
            np.round((lat["hi"] - lat["lo"]) / lat["spacing"]).astype(np.int64))
        self._init_buffers()

    def _window(self, sim):
        return NS

    def _kernel(self, sim, ns, nodes, N, dN, count):
        lat = self.lat
        return bspline_shape(sim.grid.D, sim.particles.x, lat["origin"], lat["spacing"],
                             self.ncells, lat["ilo"], lat["nlat"], lat["table"],
                             nodes, N, dN, count)
