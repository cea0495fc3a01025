"""Ghost stabilisation of poorly filled cells in the implicit solve (fenicsmpm.integrators.ghost,
fm.QuasiStatic / fm.Newmark ghost=), serially and under `mpirun -n 2`.

- The penalty vanishes on fields linear across the faces (consistency) and acts on a kink.
- Full cells get no ghost faces: a filled column gives the same answer with and without it.
- The softening W5 footing pushed through its particles (the bench localisation
  configuration) reaches 100 mm at h = 0.125. Where the penalty decides the outcome
  (h = 0.0625: a collapsed particle at the surface beside the footing at 68 mm without it)
  the run takes minutes: docs/guide/choosing.md has the figures."""
import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.integrators.ghost import GhostPenalty
from fenicsmpm.problems import localisation


def _half_filled(ghost=0.0, cell="quadrilateral"):
    """1 x 1 m, 8 x 8 quads (or triangles; 4 x 4 x 4 tetrahedra: 1 x 1 x 1 m, z up), particles
    below y = 0.5 (z = 0.5) and, in the row above, one particle per cell (a quarter full; on
    simplices those of Particles.fill's below the line). The region's bounds pass between the
    particles' coordinates on every cell type (sub-simplex centroids are multiples of h / 8
    or h / 6): with y < 0.5 and x mod 0.125 < 0.0625 they went through centroids, whose last
    bits depend on the cell's vertex order, so the particle set changed with the partition
    (1,556-1,600 tetrahedron particles on 2 ranks against 1,600 serially)."""
    if cell == "tetrahedron":
        msh = dmesh.create_box(MPI.COMM_WORLD, [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], [4, 4, 4],
                               dmesh.CellType.tetrahedron)
    else:
        msh = dmesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [1.0, 1.0]], [8, 8],
                                     getattr(dmesh.CellType, cell))
    grid = fm.Grid(msh)
    d = grid.gdim
    pts = fm.Particles.fill(grid, fm.LinearElastic(E=1e6, nu=0.3, density=1000.0), per_cell=2,
                            region=lambda x: (x[:, d - 1] < 0.49) | ((x[:, d - 1] < 0.55)
                                                                    & ((x[:, 0] + 0.01) % 0.125
                                                                       < 0.05)))
    return fm.Simulation(grid, pts, fm.QuasiStatic(ghost=ghost), dt=1.0, shape="mpm",
                         gravity=(0.0,) * (d - 1) + (-10.0,))


@pytest.mark.parametrize("cell", ["quadrilateral", "triangle", "tetrahedron"])
def test_ghost_force_is_consistent(cell):
    """G du vanishes for a displacement linear in x (to 1e-12 of its value on a kink across
    the filled surface), which it penalises, on every cell type."""
    sim = _half_filled(cell=cell)
    sim.locate_and_shape()
    m = sim.nodal_mass()
    sim.grid.accumulate(m)
    active = sim.active_mask(m)
    g = GhostPenalty(sim, 0.01, 0.5)
    g.update(sim, active, np.zeros(0, dtype=np.int32))
    x = sim.grid.node_x
    d = sim.gdim
    lin = np.column_stack([0.3 * x[:, 0] - 0.2 * x[:, 1] + 0.1]
                          + [0.5 * x[:, k] - 0.1 * x[:, 0] for k in range(1, d)])
    kink = np.column_stack([np.zeros(len(x))] * (d - 1) + [np.abs(x[:, d - 1] - 0.5)])
    f_lin, f_kink = g.force(lin), g.force(kink)
    scale = sim.comm.allreduce(float(np.abs(f_kink).max()), op=MPI.MAX)
    assert scale > 0.0                                 # the poor row's faces are penalised
    assert sim.comm.allreduce(float(np.abs(f_lin).max()), op=MPI.MAX) < 1e-12 * scale
    g.destroy()


def test_full_cells_are_untouched():
    """Gravity on the filled lower half (every cell there full, the row above it empty):
    no face qualifies and the displacements agree to round-off."""
    out = []
    for ghost in (0.0, 0.01):
        msh = dmesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [1.0, 1.0]], [8, 8],
                                     dmesh.CellType.quadrilateral)
        grid = fm.Grid(msh)
        pts = fm.Particles.fill(grid, fm.LinearElastic(E=1e6, nu=0.3, density=1000.0),
                                per_cell=2, region=lambda x: x[:, 1] < 0.5)
        sim = fm.Simulation(grid, pts, fm.QuasiStatic(ghost=ghost), dt=1.0, shape="mpm",
                            gravity=(0.0, -10.0))
        sim.fix(lambda x: np.abs(x[:, 1]) < 1e-9)
        sim.run(steps=1)
        ids = np.concatenate(sim.comm.allgather(sim.particles.id))
        u = np.concatenate(sim.comm.allgather(sim.particles.u))
        out.append(u[np.argsort(ids)])
    assert np.abs(out[0]).max() > 0
    assert np.allclose(out[0], out[1], rtol=0, atol=1e-12 * np.abs(out[0]).max())


@pytest.mark.heavy
def test_softening_footing_through_its_particles():
    """The softening W5 footing (L = 0.25 m) pushed through its top particle row with the
    ghost penalty, line search and rtol 1e-6 (the bench localisation configuration) reaches
    100 mm at h = 0.125; peak 1.043 (2 + pi) c_u, softened to half of it."""
    r = localisation.strip_footing(0.125, 0.25, footing="particles", ghost=0.01,
                                   line_search=6, rtol=1e-6)
    assert r["completed"], r["stopped"]
    peak = r["pressure"].max() / ((2.0 + np.pi) * 1e4)
    assert abs(peak - 1.0) < 0.05, peak
    assert r["pressure"][-1] < 0.6 * r["pressure"].max()
    assert max(r["newton"]) <= 10, r["newton"]


@pytest.mark.parametrize("name, bad", [("ghost", -1.0), ("ghost", True), ("ghost_fill", -0.5)])
def test_ghost_options_are_checked(name, bad):
    with pytest.raises(ValueError, match=f"'{name}'"):
        fm.QuasiStatic(**{name: bad})


def test_ghost_refuses_periodic_grids():
    sim = _half_filled(ghost=0.01)
    sim.set_periodic(axis=0)
    sim.fix(lambda x: np.abs(x[:, 1]) < 1e-9)
    with pytest.raises(NotImplementedError, match="periodic"):
        sim.step()


def test_penalised_faces_widen_the_pattern_only_there():
    """_half_filled's penalised faces: the 8 under its quarter-full row (y = 0.5) and the 7
    between that row's cells. The tangent's pattern is the cells' (one ring: 25 x 25 node pairs
    on the 9 x 9 nodes) plus the node pairs those faces' cell pairs add: 2 x 25 across y = 0.5
    (x-columns at most one apart, rows y = 0.375 and 0.625) and 2 x 28 along the row (x-columns
    two apart), not a second cell ring everywhere (39 x 39 node pairs)."""
    from petsc4py import PETSc
    sim = _half_filled(ghost=0.01)
    sim.fix(lambda x: np.abs(x[:, 1]) < 1e-9)
    sim.run(steps=1)
    system, ghost = sim.integrator.system, sim.integrator._ghost
    assert system.rings == 1
    owned = sim.grid.mesh.topology.index_map(1).size_local
    assert sim.comm.allreduce(int(np.count_nonzero(ghost._used < owned))) == 15
    nz = system.A.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["nz_used"]
    assert nz == 4 * (25 * 25 + 2 * 25 + 2 * 28), nz
    assert sim.comm.allreduce(bool(np.all(np.isfinite(sim.particles.u))), op=MPI.LAND)


@pytest.mark.parametrize("cell", ["quadrilateral", "triangle", "tetrahedron"])
def test_penalty_step_on_every_cell_type(cell):
    """A gravity step of _half_filled with the penalty (its faces' node pairs added to the
    one-ring pattern) against one without: the settlement moves by less than 1 % (measured
    -0.13 / +0.20 / +0.52 % on quadrilaterals / triangles / tetrahedra, serially and on 2 ranks
    with any partition)."""
    out = []
    for ghost in (0.0, 0.01):
        sim = _half_filled(ghost, cell)
        d = sim.gdim
        sim.fix(lambda x: np.abs(x[:, d - 1]) < 1e-9)
        sim.run(steps=1)
        out.append(sim.comm.allreduce(float(sim.particles.u[:, -1].min()), op=MPI.MIN))
    assert sim.integrator.system.rings == 1
    assert out[0] < -1e-3 and abs(out[1] / out[0] - 1.0) < 0.01, out
