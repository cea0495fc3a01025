"""CPDI1 and CPDI2 shape functions (fenicsmpm.shapes.cpdi, Simulation(shape=...)).

- On triangles and quadrilaterals, structured and with interior vertices moved by up to
  0.1 h, at random particle positions (domains sheared and stretched by a random F near I for
  CPDI1, corners moved at random by up to 0.1 of the domain for CPDI2): sum_i phi_ip = 1 and
  sum_i grad phi_ip = 0 (1e-12); an affine nodal field u = A x + b is reproduced: the
  gradient sum_i u_i (x) grad phi_ip = A (1e-12) and the value sum_i phi_ip u_i = u at the
  domain's centroid (1e-12; for CPDI1 the centroid is x_p).
- CPDI1's gradient equals the corrected formula of BENCHMARKS.md ("CPDI1", seed 004 eq 2.25
  with S_i(x3) in the first bracket) evaluated from the standard shape functions at the
  corners (1e-12).
- A rigid rotation F = R(37 deg) keeps the domain area: sum_c w_c = V0_p (1e-12).
- BENCHMARKS L1 soft column (as in test_gimp): every particle deeper than 2 h within 3 % of
  rho g d, every particle within 3 % of rho g H; and the parallel run equals the serial one.
"""
import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenicsmpm as fm
from conftest import distort_interior
from fenicsmpm.grid import vertex_ghost_partitioner
from fenicsmpm.shapes import cpdi as kc
from fenicsmpm.shapes import standard as ks
from test_gimp import RHO, G, H, column_errors, soft_column

CT = dmesh.CellType


def make(cell_type, shape, distorted):
    msh = dmesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [1.5, 1.0]], [6, 4], cell_type,
                                 partitioner=vertex_ghost_partitioner())
    if distorted:
        assert distort_interior(msh, 0.025) > 0
    grid = fm.Grid(msh)
    pts = fm.Particles.fill(grid, fm.LinearElastic(E=1e3, nu=0.3, density=1.0), per_cell=2)
    return grid, pts, fm.Simulation(grid, pts, fm.Explicit(), dt=1e-5, shape=shape)


def corner_shape(grid, corners):
    """Standard shape functions S_i at every corner (n, 4) -> nodes, S (n, 4, nv)."""
    flat = np.ascontiguousarray(corners.reshape(-1, 2))
    cells, xi = grid.locate(flat)
    assert np.all(cells >= 0)
    nv = grid.cell_nodes.shape[1]
    nodes = np.empty((len(flat), nv), dtype=np.int32)
    S = np.empty((len(flat), nv))
    ks.mpm_shape(grid.D, grid.kind, cells, xi, grid.cell_nodes, grid.node_x, grid.simplex_grad,
                 grid.affine_Jinv, nodes, S, np.empty((len(flat), nv, 2)))
    return nodes.reshape(len(corners), 4, nv), S.reshape(len(corners), 4, nv)


@pytest.mark.parametrize("distorted", [False, True], ids=["structured", "distorted"])
@pytest.mark.parametrize("shape", ["cpdi1", "cpdi2"])
@pytest.mark.parametrize("cell_type", [CT.triangle, CT.quadrilateral], ids=lambda c: c.name)
def test_partition_of_unity_and_affine(cell_type, shape, distorted, rng):
    grid, pts, sim = make(cell_type, shape, distorted)
    n = len(pts)
    side = np.sqrt(pts.V0)[:, None]
    nc = 3 if cell_type == CT.triangle else 4        # triangular domains on triangle meshes
    # move each particle by up to 0.2 of its domain; keep every corner inside the mesh
    pts.x[:] = pts.x + rng.uniform(-0.2, 0.2, (n, 2)) * side
    if shape == "cpdi1":
        pts.F[:, :2, :2] = np.eye(2) + rng.uniform(-0.15, 0.15, (n, 2, 2))
        corners = np.empty((n, nc, 2))
        if nc == 3:
            kc.simplex_corners(pts.x, pts.F, pts.cpdi_t0, corners)
        else:
            kc.cpdi1_corners(pts.x, pts.F, pts.cpdi_r0, corners)
        centroid = pts.x
    else:
        pts.cpdi_corners[:] += rng.uniform(-0.1, 0.1, (n, nc, 2)) * side[:, :, None]
        corners = pts.cpdi_corners
    inside = np.all((corners > 1e-9) & (corners < np.array([1.5, 1.0]) - 1e-9), axis=(1, 2))
    sim.locate_and_shape()
    w = np.empty((n, nc))
    gc = np.empty((n, nc, 2))
    (kc.tri_weights if nc == 3 else kc.corner_weights)(np.ascontiguousarray(corners), w, gc)
    if shape == "cpdi2":      # centroid of the domain: int x dx / V
        centroid = np.einsum("pc,pck->pk", w, corners) / w.sum(axis=1)[:, None]
    A = rng.normal(size=(2, 2))
    b = rng.normal(size=2)
    u = grid.node_x @ A.T + b
    pu = np.abs(sim.N.sum(axis=1) - 1).max()
    gsum = np.abs(sim.dN.sum(axis=1)).max()
    grad = np.abs(np.einsum("pai,paj->pij", u[sim.nodes], sim.dN) - A)[inside].max(initial=0.0)
    val = np.einsum("pa,pak->pk", sim.N, u[sim.nodes])
    rep = np.abs(val - (centroid @ A.T + b))[inside].max(initial=0.0)
    worst = MPI.COMM_WORLD.allreduce(max(pu, gsum, grad, rep), op=MPI.MAX)
    assert worst < 1e-12, f"{shape}: PU {pu:.2e}, sum grad {gsum:.2e}, gradient {grad:.2e}, " \
                          f"value {rep:.2e} (tol 1e-12)"


def test_cpdi1_gradient_is_the_corrected_formula(rng):
    grid, pts, sim = make(CT.quadrilateral, "cpdi1", True)
    n = len(pts)
    pts.x[:] += rng.uniform(-0.05, 0.05, (n, 2))
    pts.F[:, :2, :2] = np.eye(2) + rng.uniform(-0.15, 0.15, (n, 2, 2))
    corners = np.empty((n, 4, 2))
    kc.cpdi1_corners(pts.x, pts.F, pts.cpdi_r0, corners)
    sim.locate_and_shape()
    inside = np.flatnonzero(np.all((corners > 1e-9) & (corners < np.array([1.5, 1.0]) - 1e-9),
                                   axis=(1, 2)))
    assert len(inside) > n // 2
    cn, S = np.zeros((n, 4, grid.cell_nodes.shape[1]), dtype=np.int32), np.zeros((n, 4, grid.cell_nodes.shape[1]))
    cn[inside], S[inside] = corner_shape(grid, corners[inside])
    r1 = np.einsum("pij,pj->pi", pts.F[:, :2, :2], pts.cpdi_r0[:, 0])
    r2 = np.einsum("pij,pj->pi", pts.F[:, :2, :2], pts.cpdi_r0[:, 1])
    V = r1[:, 0] * r2[:, 1] - r1[:, 1] * r2[:, 0]
    a = np.stack([r1[:, 1] - r2[:, 1], r2[:, 0] - r1[:, 0]], axis=1)
    b = np.stack([r1[:, 1] + r2[:, 1], -r1[:, 0] - r2[:, 0]], axis=1)
    worst = 0.0
    for p in inside:
        for j, i in enumerate(sim.nodes[p]):
            if sim.N[p, j] == 0.0:
                continue
            Si = [(S[p, c] * (cn[p, c] == i)).sum() for c in range(4)]
            ref = ((Si[0] - Si[2]) * a[p] + (Si[1] - Si[3]) * b[p]) / (2 * V[p])
            worst = max(worst, np.abs(sim.dN[p, j] - ref).max())
            assert abs(sim.N[p, j] - 0.25 * sum(Si)) < 1e-12
    worst = MPI.COMM_WORLD.allreduce(worst, op=MPI.MAX)
    assert worst < 1e-12, f"CPDI1 gradient differs from BENCHMARKS eq 2.25 by {worst:.2e}"


@pytest.mark.parametrize("shape", ["cpdi1", "cpdi2"])
def test_rigid_rotation_keeps_volume(shape):
    grid, pts, sim = make(CT.triangle, shape, False)
    c, s = np.cos(np.radians(37.0)), np.sin(np.radians(37.0))
    R = np.array([[c, -s], [s, c]])
    n = len(pts)
    if shape == "cpdi1":                       # triangular domains (the sub-triangles)
        pts.F[:, :2, :2] = R
        corners = np.empty((n, 3, 2))
        kc.simplex_corners(pts.x, pts.F, pts.cpdi_t0, corners)
    else:
        rel = pts.cpdi_corners - pts.x[:, None, :]
        pts.cpdi_corners[:] = pts.x[:, None, :] + rel @ R.T
        corners = pts.cpdi_corners
    w = np.empty((n, 3))
    kc.tri_weights(np.ascontiguousarray(corners), w, np.empty((n, 3, 2)))
    err = MPI.COMM_WORLD.allreduce(float(np.abs(w.sum(axis=1) / pts.V0 - 1).max()), op=MPI.MAX)
    assert err < 1e-12, f"{shape}: rotated domain area / V0 - 1 = {err:.2e} (tol 1e-12)"


@pytest.mark.parametrize("shape", ["cpdi1", "cpdi2"])
def test_soft_column(shape):
    err_H, err_d, settle = column_errors(shape)
    assert settle > 1.0, f"top settlement {settle:.2f} cells: particles must cross cells"
    assert err_H < 0.03, f"{shape}: max |sigma_yy + rho g d| = {100 * err_H:.2f} % of rho g H (tol 3 %)"
    assert err_d < 0.03, f"{shape}: max |sigma_yy / (-rho g d) - 1| below 2 h = {100 * err_d:.2f} % (tol 3 %)"
    print(f"\nL1 soft column: {shape} {100 * err_H:.2f} % of rho g H, {100 * err_d:.2f} % of rho g d")


@pytest.mark.skipif(MPI.COMM_WORLD.size == 1, reason="compares a parallel run with a serial one")
def test_parallel_matches_serial():
    comm = MPI.COMM_WORLD
    X0, syy, _, _ = soft_column("cpdi2", comm=comm, n_cells=10)
    Xs, ss, _, _ = soft_column("cpdi2", comm=MPI.COMM_SELF, n_cells=10)
    X0 = np.concatenate(comm.allgather(X0))
    syy = np.concatenate(comm.allgather(syy))
    assert len(X0) == len(Xs) == 40
    a = np.lexsort(np.round(X0, 6).T)          # by initial height, then x (ties: round-off)
    b = np.lexsort(np.round(Xs, 6).T)
    assert np.allclose(X0[a], Xs[b], rtol=0, atol=1e-9)
    diff = np.abs(syy[a] - ss[b]).max() / (RHO * G * H)
    assert diff < 1e-9, f"parallel and serial sigma_yy differ by {diff:.2e} rho g H (tol 1e-9)"


def test_combine_into_fewer_columns_than_the_corners_reach():
    """cpdi_combine into the last step's column count (shapes.gimp.PaddedStencil): with enough
    columns the same rows as at full width, to the bit; with too few, a count above the
    columns, so the caller evaluates again at full width."""
    from fenicsmpm.shapes.cpdi import cpdi_combine
    rng = np.random.default_rng(5)
    n, ncor, nvc = 200, 4, 4
    cnodes = rng.integers(0, 12, (n, ncor, nvc)).astype(np.int32)
    cN = rng.random((n, ncor, nvc))
    cN[rng.random((n, ncor, nvc)) < 0.2] = 0.0
    w, g = rng.random((n, ncor)) + 0.1, rng.standard_normal((n, ncor, 2))

    def combine(cols):
        out = (np.empty((n, cols), np.int32), np.empty((n, cols)), np.empty((n, cols, 2)),
               np.empty(n, np.int64))
        cpdi_combine((0, 1), cnodes, cN, w, g, *out)
        return out

    full = combine(ncor * nvc)
    nv = int(full[3].max())
    cut = combine(nv)
    assert np.array_equal(cut[3], full[3])
    for a, b in zip(cut[:3], full[:3]):
        assert np.array_equal(a, b[:, :nv])
    few = combine(nv - 2)
    over = full[3] > nv - 2
    assert over.any() and np.all(few[3][over] > nv - 2)
    assert np.array_equal(few[3][~over], full[3][~over])
    for a, b in zip(few[:3], full[:3]):
        assert np.array_equal(a[~over], b[~over, :nv - 2])


@pytest.mark.parametrize("distorted", [False, True], ids=["structured", "distorted"])
def test_corners_searched_from_last_steps_cells(distorted):
    """CpdiShape starts each corner's search at the cell it was in last step (shapes.cpdi.
    shape_at_points' point_cells): after steps of a rotating body on triangles (corners
    crossing cells), the weights equal those from a search started at the particles' own
    cells (1e-13), and the remembered cells are where the corners are."""
    grid, pts, sim = make(CT.triangle, "cpdi2", distorted)
    pts.v[:] = 2.0 * np.c_[-(pts.x[:, 1] - 0.5), pts.x[:, 0] - 0.75]
    sim.dt = 2e-3
    for _ in range(10):
        sim.step()
    shape = sim._wide
    assert shape._corner_key == (pts.version, len(pts))
    ncor = pts.cpdi_corners.shape[1]
    remembered = shape._corner_cells.reshape(-1, ncor)
    moved = MPI.COMM_WORLD.allreduce(int(np.sum(remembered != pts.cell[:, None])))
    assert moved > 0, "no corner outside its particle's cell: the test checks nothing"
    nodes, N, dN = (a.copy() for a in shape.evaluate(sim))
    shape._corner_key = None                    # forget: search from the particles' cells
    fresh = shape.evaluate(sim)
    for a, b in zip((nodes, N, dN), fresh):
        assert a.shape == b.shape
    assert np.array_equal(nodes, fresh[0])
    assert np.abs(N - fresh[1]).max(initial=0.0) < 1e-13
    assert np.abs(dN - fresh[2]).max(initial=0.0) < 1e-13 * np.abs(dN).max(initial=1.0)


@pytest.mark.parametrize("integrator", ["Newmark", "ImplicitGeneralizedAlpha",
                                        "ExplicitGeneralizedAlpha", "Explicit"])
def test_corners_move_with_the_particles_in_free_fall(integrator):
    """A body in free fall translates rigidly: CPDI2's corners (moved at the end of each step
    by the grid displacement the particles moved by, CpdiShape.after_step) keep their offsets
    from the particle to round-off with every integrator. Moving them by dt v_(n+1) instead
    (as before, for Newmark and generalized-alpha, whose particles move by du = dt v_n +
    dt^2 / 2 ((1 - 2 beta) a_n + 2 beta a_(n+1))) put them g dt^2 / 2 lower each step."""
    grid, pts, _ = make(CT.triangle, "cpdi2", False)
    integ = getattr(fm, integrator)()
    sim = fm.Simulation(grid, pts, integ, dt=2e-3, shape="cpdi2", gravity=(0.0, -10.0))
    rel0 = pts.cpdi_corners - pts.x[:, None, :]
    for _ in range(8):
        sim.step()
    drift = np.abs(pts.cpdi_corners - pts.x[:, None, :] - rel0).max(initial=0.0)
    assert drift < 1e-12, drift
    fall = MPI.COMM_WORLD.allreduce(float(np.abs(pts.u[:, 1]).max(initial=0.0)), op=MPI.MAX)
    assert fall > 5e-4, fall                       # 0.5 g t^2 = 1.28e-3 m at t = 0.016 s


def _offsets(pts):
    """{particle id: x_p - the mean of its triangular domain's corners}."""
    return dict(zip(pts.id.tolist(), pts.x - pts.cpdi_corners.mean(axis=1)))


@pytest.mark.parametrize("integrator", ["MUSL", "AVG", "contact"])
def test_corners_follow_the_particles_through_deformation(integrator):
    """A soft block on a triangle mesh sags under gravity (base fixed) while a rigid block
    (body 1, contact only) sinks into it. A particle of a triangular CPDI2 domain moves by
    sum_c (1/3) sum_i S_i(x_c) du_i, the mean of its corners' moves, so its offset from the
    corners' mean stays to round-off when the corners move by the displacement its particle
    moved by (measured 1e-15 m in 40 steps, serial and 2 ranks). Explicit MUSL and AVG map the
    updated velocities back to the grid before the stress update; moving the corners by dt
    times that remapped velocity (as before) let them drift 2.4e-3 m (2.4 % of h) from their
    particles, and under fm.ExplicitContact, where they followed the bodies' centre-of-mass
    velocity, 8.5e-3 m."""
    msh = dmesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [1.0, 1.0]], [10, 10],
                                 CT.triangle, partitioner=vertex_ghost_partitioner())
    grid = fm.Grid(msh)
    soft = fm.LinearElastic(E=2e4, nu=0.3, density=1000.0)
    pts = fm.Particles.fill(grid, soft, per_cell=2,
                            region=lambda x: (x[:, 1] < 0.5) & (x[:, 0] > 0.1) & (x[:, 0] < 0.9))
    if integrator == "contact":
        lid = fm.Particles.fill(grid, fm.LinearElastic(E=2e4, nu=0.3, density=1000.0),
                                per_cell=2, region=lambda x: (x[:, 1] > 0.5) & (x[:, 1] < 0.7)
                                & (x[:, 0] > 0.3) & (x[:, 0] < 0.7))
        pts = pts + lid
        integ = fm.ExplicitContact("MUSL", rigid={1: (0.0, -0.2)})
    else:
        integ = fm.Explicit(integrator)
    sim = fm.Simulation(grid, pts, integ, dt="auto", gravity=(0.0, -10.0), shape="cpdi2")
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0))
    sim.step()
    before = _offsets(sim.particles)
    sim.run(t_end=sim.t + 40 * sim.dt)
    after = _offsets(sim.particles)
    drift = max((float(np.abs(after[i] - before[i]).max()) for i in after if i in before),
                default=0.0)
    drift = MPI.COMM_WORLD.allreduce(drift, op=MPI.MAX)
    sag = MPI.COMM_WORLD.allreduce(float(np.abs(sim.particles.u).max(initial=0.0)), op=MPI.MAX)
    print(f"\n{integrator}: corner drift {drift:.2e} m, largest displacement {sag:.2e} m")
    assert drift < 1e-12, drift
    assert sag > 1e-3, sag                      # the block deformed (and the lid moved 8 mm)
