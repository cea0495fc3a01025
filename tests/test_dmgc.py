"""DM-GC: double mapping + composite MPM (fenicsmpm.shapes.cmpm, fenicsmpm.integrators.dmgc;
seed 000 §2.7-2.9, BENCHMARKS.md "DM-GC and CMPM").

- The 1D CMPM functions (eq 2.54) equal the corrected closed forms of eqs 2.55 (interior) and
  2.56 (boundary, and its mirror) to 1e-15 and sum to one; the forms as printed in the seed
  (first interior function with a + sign, last boundary one (xi^2 + 4xi - 3)/8) do not
  (their sums are off by more than 0.1 somewhere in [-1, 1]).
- 2D CMPM on a 6 x 4 quad lattice at random points (all cells, boundary ones included):
  sum_i N_i = 1 and sum_i grad N_i = 0, affine and quadratic fields reproduced in value and
  gradient (1e-12); cubic fields too where the stencil is not trimmed (4 x 4 nodes). With an
  empty neighbour cell the stencil is trimmed there and still reproduces quadratics.
- Double mapping of a uniform material (2 x 2 and 3 x 3 particles per cell filling the grid):
  the nodal tangents A_i^e and the Gauss-point tangents A_g equal A (1e-12), and the assembled
  DM stiffness equals dolfinx's Q1 elasticity matrix (relative Frobenius norm 1e-12).
- V2 small strain (H = 10, 10 cells, E = 1e8, rho = 2000, 5 load steps; self_weight_errors):
  DM-GC stress error (AMPLE's norm, fraction of rho g H) below 1e-3 (measured 9.1e-5) and at
  least 20x below plain uGIMP implicit (measured 2.47e-2); displacement error of both below
  4e-3 (measured 3.11e-3 DM-GC, 3.05e-3 uGIMP: the GIMP interpolation of nodal values,
  h^2 / (4 H^2) = 2.5e-3, dominates); Newton at most 6 iterations per load step.
- V1 bar, DoubleMappingNewmark at dt = 5 h/c, mass_tolerance 1e-2, 3 periods: period within
  3 % (measured 1.33 %; uGIMP Newmark 1.34 %).
- Other shapes and 3D grids are refused.
Serial and under mpirun -n 2 (vertex-ghost partitioned meshes).
"""
import numpy as np
import pytest
import ufl
from dolfinx import fem, mesh as dmesh
import dolfinx.fem.petsc
from mpi4py import MPI
from petsc4py import PETSc

import fenicsmpm as fm
from fenicsmpm.grid import vertex_ghost_partitioner
from fenicsmpm.problems.elastic import self_weight_errors
from fenicsmpm.shapes.cmpm import CompositeBasis, lagrange_1d
from fenicsmpm.problems.elastic import vibrating_bar

WORLD = MPI.COMM_WORLD
XI = np.linspace(-1.0, 1.0, 41)


def interior(xi):
    return [-(xi ** 3 - 3 * xi ** 2 - xi + 3) / 48, (xi ** 3 - xi ** 2 - 9 * xi + 9) / 16,
            (-xi ** 3 - xi ** 2 + 9 * xi + 9) / 16, (xi ** 3 + 3 * xi ** 2 - xi - 3) / 48]


def boundary(xi):
    return [(xi ** 2 - 4 * xi + 3) / 8, (-xi ** 2 + 2 * xi + 3) / 4, (xi ** 2 - 1) / 8]


def test_closed_forms():
    N, dN = np.empty(4), np.empty(4)
    for xi in XI:
        lagrange_1d(xi, -1, 2, N, dN)
        assert np.allclose(N, interior(xi), rtol=0, atol=1e-15)
        h = 1e-6
        fd = (np.array(interior(xi + h)) - np.array(interior(xi - h))) / (2 * h)
        assert np.allclose(dN, fd, rtol=0, atol=1e-8)
        lagrange_1d(xi, 0, 2, N, dN)                       # nodes -1, 1, 3
        assert np.allclose(N[:3], boundary(xi), rtol=0, atol=1e-15)
        lagrange_1d(xi, -1, 1, N, dN)                      # mirror: nodes -3, -1, 1
        assert np.allclose(N[:3], boundary(-xi)[::-1], rtol=0, atol=1e-15)
        assert abs(sum(interior(xi)) - 1) < 1e-15 and abs(sum(boundary(xi)) - 1) < 1e-15
    printed_interior = [(xi ** 3 - 3 * xi ** 2 - xi + 3) / 48 + sum(interior(xi)[1:]) for xi in XI]
    printed_boundary = [sum(boundary(xi)[:2]) + (xi ** 2 + 4 * xi - 3) / 8 for xi in XI]
    assert np.max(np.abs(np.array(printed_interior) - 1)) > 0.1
    assert np.max(np.abs(np.array(printed_boundary) - 1)) > 0.1


def _lattice_points():
    msh = dmesh.create_rectangle(WORLD, [[0.0, 0.0], [1.5, 1.0]], [6, 4],
                                 dmesh.CellType.quadrilateral, partitioner=vertex_ghost_partitioner())
    grid = fm.Grid(msh)
    x = np.random.default_rng(3).uniform([0.0, 0.0], [1.5, 1.0], (400, 2))
    cell, _ = grid.locate(x, np.full(len(x), -1, dtype=np.int32))
    own = (cell >= 0) & (cell < grid.n_owned_cells)
    return grid, CompositeBasis(grid), x[own], cell[own]


def _fields():
    """(u, grad u) pairs: affine, quadratic, cubic."""
    return [(lambda X: 2 + 3 * X[:, 0] - X[:, 1], lambda X: np.c_[3 + 0 * X[:, 0], -1 + 0 * X[:, 0]]),
            (lambda X: 1 + X[:, 0] ** 2 + 2 * X[:, 0] * X[:, 1] - 3 * X[:, 1] ** 2,
             lambda X: np.c_[2 * X[:, 0] + 2 * X[:, 1], 2 * X[:, 0] - 6 * X[:, 1]]),
            (lambda X: X[:, 0] ** 3 - X[:, 0] * X[:, 1] ** 2 + X[:, 0] ** 2 * X[:, 1] ** 3,
             lambda X: np.c_[3 * X[:, 0] ** 2 - X[:, 1] ** 2 + 2 * X[:, 0] * X[:, 1] ** 3,
                             -2 * X[:, 0] * X[:, 1] + 3 * X[:, 0] ** 2 * X[:, 1] ** 2])]


def _reproduction_errors(grid, nodes, N, dN, x, sel):
    out = []
    for f, df in _fields():
        u = f(grid.node_x)
        ev = np.abs((N * u[nodes]).sum(1) - f(x))[sel]
        eg = np.abs(np.einsum("pa,pak->pk", u[nodes], dN) - df(x))[sel]
        out.append(max(ev.max(initial=0.0), eg.max(initial=0.0)))
    return [WORLD.allreduce(float(e), op=MPI.MAX) for e in out]


def test_cmpm_reproduction():
    grid, basis, x, cell = _lattice_points()
    nodes, N, dN = basis.evaluate(x, cell, np.ones(grid.n_cells, dtype=bool))
    assert WORLD.allreduce(len(x)) > 300
    pu = WORLD.allreduce(max(np.abs(N.sum(1) - 1).max(initial=0), np.abs(dN.sum(1)).max(initial=0)), op=MPI.MAX)
    assert pu < 1e-12
    full = np.count_nonzero(N, axis=1) == 16
    lat = basis.cell_lat[cell]
    interior = np.all((lat >= 1) & (lat + 2 <= basis.ncell), axis=1)
    assert WORLD.allreduce(bool(np.array_equal(full, interior)), op=MPI.LAND)
    affine, quadratic, _ = _reproduction_errors(grid, nodes, N, dN, x, np.ones(len(x), dtype=bool))
    cubic = _reproduction_errors(grid, nodes, N, dN, x, interior)[2]
    assert affine < 1e-12 and quadratic < 1e-12 and cubic < 1e-12, (affine, quadratic, cubic)


def test_cmpm_trimmed_at_empty_cells():
    """Cells in lattice column 3 hold no material: particles in columns 2 and 4 lose that
    side of the stencil (3 nodes along x) and still reproduce quadratics."""
    grid, basis, x, cell = _lattice_points()
    material = basis.cell_lat[:, 0] != 3
    nodes, N, dN = basis.evaluate(x, cell, material)
    col = basis.cell_lat[cell, 0]
    xn = grid.node_x[nodes][..., 0]
    reach = np.where(N != 0, xn, np.nan)
    left = np.nanmin(reach, axis=1) - 0.25 * col
    right = np.nanmax(reach, axis=1) - 0.25 * (col + 1)
    ok = (np.all(np.abs(right[col == 2]) < 1e-12) and np.all(np.abs(left[col == 4]) < 1e-12)
          and np.all(np.abs(left[col == 2] + 0.25) < 1e-12))
    assert WORLD.allreduce(bool(ok), op=MPI.LAND)
    affine, quadratic, _ = _reproduction_errors(grid, nodes, N, dN, x, col != 3)
    assert affine < 1e-12 and quadratic < 1e-12, (affine, quadratic)


@pytest.mark.parametrize("per_cell", [2, 3])
def test_double_mapping_uniform(per_cell):
    """A_i^e = A_g = A and K = the Q1 finite-element matrix for a uniform material."""
    lam, mu = 3.0, 2.0
    msh = dmesh.create_rectangle(WORLD, [[0.0, 0.0], [1.5, 1.0]], [6, 4],
                                 dmesh.CellType.quadrilateral, partitioner=vertex_ghost_partitioner())
    grid = fm.Grid(msh)
    pts = fm.Particles.fill(grid, fm.LinearElastic(E=1.0, nu=0.25, density=1.0), per_cell=per_cell)
    integ = fm.DoubleMappingQuasiStatic()
    sim = fm.Simulation(grid, pts, integ, dt=1.0, shape="ugimp")
    sim.locate_and_shape()
    integ.prepare(sim)
    d = np.eye(2)
    A = np.zeros((3, 3, 3, 3))
    A[:2, :2, :2, :2] = (lam * np.einsum("rj,cl->rjcl", d, d)
                         + mu * (np.einsum("rc,jl->rjcl", d, d) + np.einsum("rl,jc->rjcl", d, d)))
    A4 = np.ascontiguousarray(np.broadcast_to(A, (len(pts), 3, 3, 3, 3)))
    ndof = 2 * grid.n_nodes
    integ.assemble_tangent(sim, A4, integ.system.plan(sim.nodes), np.zeros(ndof),
                           np.zeros(ndof, dtype=bool))
    Dn = integ._Dn[: grid.n_owned_cells][integ._touched[: grid.n_owned_cells]]   # complete here
    Ag = np.einsum("ga,eaijkl->egijkl", integ._Ng, Dn)
    err = max(np.abs(Dn - A[:2, :2, :2, :2]).max(initial=0), np.abs(Ag - A[:2, :2, :2, :2]).max(initial=0))
    assert WORLD.allreduce(err, op=MPI.MAX) < 1e-12
    assert WORLD.allreduce(int(integ._touched[: grid.n_owned_cells].sum())) == 24
    u, v = ufl.TrialFunction(grid.V), ufl.TestFunction(grid.V)

    def sigma(w):
        return lam * ufl.tr(ufl.sym(ufl.grad(w))) * ufl.Identity(2) + 2 * mu * ufl.sym(ufl.grad(w))

    ref = dolfinx.fem.petsc.assemble_matrix(fem.form(ufl.inner(sigma(u), ufl.grad(v)) * ufl.dx))
    ref.assemble()
    K = integ.system.A
    diff = K.copy()
    diff.axpy(-1.0, ref, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
    rel = diff.norm(PETSc.NormType.FROBENIUS) / ref.norm(PETSc.NormType.FROBENIUS)
    diff.destroy()
    ref.destroy()
    assert rel < 1e-12, f"DM stiffness vs Q1 matrix: relative difference {rel:.3e}"


@pytest.fixture(scope="module")
def column():
    return {m: self_weight_errors(m) for m in ("dmgc", "standard")}


def test_column_stress(column):
    dm, std = column["dmgc"]["stress"], column["standard"]["stress"]
    assert dm < 1e-3, f"DM-GC stress error {dm:.3e} of rho g H (tol 1e-3)"
    assert std > 20 * dm, f"uGIMP implicit {std:.3e} vs DM-GC {dm:.3e}: expected 20x"


def test_column_displacement(column):
    for m, r in column.items():
        assert r["displacement"] < 4e-3, f"{m}: displacement error {r['displacement']:.3e} (tol 4e-3)"
        assert r["settlement"] < 4e-3, f"{m}: top settlement error {r['settlement']:.3e} (tol 4e-3)"
    assert max(column["dmgc"]["newton"]) <= 6, column["dmgc"]["newton"]


def _period(t, v):
    s = np.sign(v)
    i = np.flatnonzero(s[:-1] * s[1:] < 0)
    tz = t[i] - v[i] * (t[i + 1] - t[i]) / (v[i + 1] - v[i])
    assert len(tz) >= 5, f"only {len(tz)} zero crossings"
    return 2.0 * np.polyfit(np.arange(len(tz)), tz, 1)[0]


def test_newmark_vibrating_bar():
    b, exact = vibrating_bar(fm.Explicit(), n_cells=20, partitioner=vertex_ghost_partitioner())
    dt = 5.0 * exact["h"] / exact["wave_speed"]
    sim = fm.Simulation(b.grid, b.particles, fm.DoubleMappingNewmark(), dt=dt, shape="ugimp",
                        mass_tolerance=1e-2)
    sim.fix(lambda x: np.isclose(x[:, 0], 0.0), [0])
    sim.fix(lambda x: np.full(len(x), True), [1])
    pr = sim.probe((0.9875, 0.0125), fields=("velocity",))
    sim.run(t_end=3 * exact["period"], progress=False)
    d = pr.data()
    err = abs(_period(d["t"], d["velocity_x"]) / exact["period"] - 1.0)
    assert err < 0.03, f"DM-GC Newmark period error {100 * err:.3f} % (tol 3 %)"
    assert max(sim.integrator.iterations) <= 15, sim.integrator.iterations


@pytest.mark.parametrize("shape", ["mpm", "cpdi2"])
def test_refuses_other_shapes(shape):
    msh = dmesh.create_rectangle(WORLD, [[0.0, 0.0], [1.0, 1.0]], [2, 2], dmesh.CellType.quadrilateral,
                                 partitioner=vertex_ghost_partitioner())
    grid = fm.Grid(msh)
    pts = fm.Particles.fill(grid, fm.LinearElastic(E=1.0, nu=0.25, density=1.0), per_cell=2)
    with pytest.raises(ValueError, match="shape='ugimp' or 'cpgimp'"):
        fm.Simulation(grid, pts, fm.DoubleMappingQuasiStatic(), dt=1.0, shape=shape)


def test_refuses_3d():
    msh = dmesh.create_box(WORLD, [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], [2, 2, 2],
                           dmesh.CellType.hexahedron, partitioner=vertex_ghost_partitioner())
    grid = fm.Grid(msh)
    pts = fm.Particles.fill(grid, fm.LinearElastic(E=1.0, nu=0.25, density=1.0), per_cell=1)
    with pytest.raises(ValueError, match="2D structured quadrilateral"):
        fm.Simulation(grid, pts, fm.DoubleMappingNewmark(), dt=1.0, shape="ugimp")


def test_bench_dmgc(shared_module_tmp_path):
    """`python -m fenicsmpm.bench dmgc --quick`: JSON + PNG; DM-GC's stress error at least 20x
    below plain implicit GIMP at every size (measured 9.1e-5 vs 2.5e-2 at 10 cells, uGIMP)."""
    import json
    import os
    from fenicsmpm.bench import dmgc
    out = os.path.join(shared_module_tmp_path, "dmgc")
    dmgc.run(quick=True, out=out, verbose=False)
    with open(os.path.join(out, "dmgc.json")) as f:
        runs = json.load(f)["runs"]
    assert os.path.getsize(os.path.join(out, "dmgc.png")) > 0
    err = {(r["config"]["method"], r["config"]["shape"], r["config"]["n_cells"]): r["metrics"]["stress_error"]
           for r in runs}
    for (method, shape, n), e in err.items():
        if method == "dmgc":
            assert e < err[("standard", shape, n)] / 20, (shape, n, e)
