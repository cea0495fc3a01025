"""Deformed-voxel GIMP by Gauss quadrature (2D, any P1/Q1 mesh): shape="gauss".

Seed 002 §3.3.1 (eqs 3.16-3.22), with the erratum of BENCHMARKS.md ("Errata in seed 002":
in (3.17) the derivative inside the sum is that of the grid function N_i, not of N-bar).
The particle's voxel, initially the parallelogram of edge vectors r1^0, r2^0 (area V0_p,
shapes.cpdi.initial_edges: along the cell edges on quadrilaterals, axis-aligned squares on
triangles), is integrated by 2 x 2 Gauss points pushed forward by the particle's F (eqs
3.20-3.22, dx = F dx^0):
    x_g = x_p + F_p (s r1^0 + t r2^0) / (2 sqrt 3),   s, t = +-1   (r_g = +-l/(2 sqrt 3)
          along the initial axes for a voxel of side l),
    S_ip      = sum_g w_g N_i(x_g),           w_g = 1/4 (eq 3.18: phi-bar_g / 4, sum = 1),
    grad S_ip = sum_g w_g grad N_i(x_g)       (eq 3.19 with the erratum),
with N_i the grid's standard (P1/Q1) shape functions and chi_p = 1 at the Gauss points.
Since sum_i N_i = 1, sum_i grad N_i = 0, sum_i N_i(x) x_i = x and sum_i x_i (x) grad N_i = I
hold at every x_g, the weights sum to 1, the gradients to 0, an affine field is reproduced
(value at the mean of the x_g, which is x_p; gradient exactly), for any F. When the whole
voxel lies in one cell, 2 x 2 Gauss is exact (N_i is bilinear or linear there), so S_ip is
then the exact average of N_i over the deformed voxel (uGIMP's weights for F = I on a
lattice). A Gauss point outside the local mesh (a particle at the boundary) uses the basis of
the particle's own cell, extended linearly (PU and affine reproduction still hold).
"""
import numpy as np
from numba import njit

from ..kernels.transfer import pad_row

N_GAUSS = 4


@njit(cache=True)
def gauss_points(x, F, r0, out):
    """x_g = x_p + F_p (s r1^0 + t r2^0) / (2 sqrt 3) for (s, t) = (-,-), (+,-), (+,+), (-,+)
    (in-plane block of F). x (n, 2), F (n, 3, 3), r0 (n, 2, 2) initial edge vectors;
    out (n, 4, 2)."""
    a = 0.5 / np.sqrt(3.0)
    for p in range(x.shape[0]):
        for g in range(4):
            s = -1.0 if g == 0 or g == 3 else 1.0
            t = -1.0 if g < 2 else 1.0
            d0 = a * (s * r0[p, 0, 0] + t * r0[p, 1, 0])
            d1 = a * (s * r0[p, 0, 1] + t * r0[p, 1, 1])
            out[p, g, 0] = x[p, 0] + F[p, 0, 0] * d0 + F[p, 0, 1] * d1
            out[p, g, 1] = x[p, 1] + F[p, 1, 0] * d0 + F[p, 1, 1] * d1


@njit(cache=True)
def gauss_combine(D, gnodes, gN, gdN, nodes_out, N_out, dN_out, count_out):
    """S_ip = 1/4 sum_g N_i(x_g), grad S_ip = 1/4 sum_g grad N_i(x_g), per particle.

    gnodes, gN: (n, 4, nvc), gdN (n, 4, nvc, d): the standard shape functions at each Gauss
    point. Nodes shared by several Gauss points are merged: each node appears once
    (count_out[p] of them), then padding (kernels.transfer.pad_row)."""
    d = len(D)
    nv = nodes_out.shape[1]
    for p in range(gnodes.shape[0]):
        cnt = 0
        for g in range(gnodes.shape[1]):
            for a in range(gnodes.shape[2]):
                i = gnodes[p, g, a]
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
                N_out[p, slot] += 0.25 * gN[p, g, a]
                for k in range(d):
                    dN_out[p, slot, k] += 0.25 * gdN[p, g, a, k]
        count_out[p] = cnt
        pad_row(d, p, cnt, nodes_out[p, 0], nodes_out, N_out, dN_out)


class GaussGimpShape:
    """Deformed-voxel GIMP by 2 x 2 Gauss quadrature for a 2D Simulation (module docstring).

    Adds the particle field `cpdi_r0` (n, 2, 2), the initial voxel edge vectors
    (shapes.cpdi.initial_edges; shared with CPDI). Like CPDI, the Gauss points may lie in
    the cells around the particle's cell: in parallel the mesh needs the shared-vertex ghost
    layer (partitioner=fenicsmpm.grid.vertex_ghost_partitioner())."""

    def __init__(self, sim):
        from .cpdi import initial_edges
        from .gimp import _RING_MESSAGE
        grid, p = sim.grid, sim.particles
        if grid.gdim != 2:
            raise NotImplementedError(f"shape='gauss' (deformed-voxel GIMP by Gauss quadrature) "
                                      f"is implemented in 2D only, got gdim = {grid.gdim}")
        if not grid.has_vertex_ring():
            raise ValueError(_RING_MESSAGE.format(name="Gauss-GIMP"))
        if not hasattr(p, "cpdi_r0"):
            p.add_field("cpdi_r0", (2, 2))[:] = initial_edges(grid, p)

    def after_step(self, sim, dt):
        """Nothing to move: the Gauss points follow x_p and F."""

    def evaluate(self, sim):
        """(nodes, N, dN) of the local particles; nv = the largest number of distinct nodes a
        particle's Gauss points reach (padded)."""
        from .cpdi import shape_at_points, trim_stencil
        p, g = sim.particles, sim.grid
        n, nvc = len(p), g.cell_nodes.shape[1]
        pts = np.empty((n, N_GAUSS, 2))
        gauss_points(p.x, p.F, p.cpdi_r0, pts)
        gnodes, gN, gdN, _ = shape_at_points(g, pts, p.cell)
        width = N_GAUSS * nvc
        nodes = np.empty((n, width), dtype=np.int32)
        N = np.empty((n, width))
        dN = np.empty((n, width, 2))
        count = np.empty(n, dtype=np.int64)
        gauss_combine(g.D, gnodes.reshape(n, N_GAUSS, nvc), gN.reshape(n, N_GAUSS, nvc),
                      gdN.reshape(n, N_GAUSS, nvc, 2), nodes, N, dN, count)
        return trim_stencil(nodes, N, dN, count)
