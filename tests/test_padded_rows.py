"""Padded shape rows (kernels.transfer.row_length / pad_row; issue 16).

A wide family's particle touches fewer nodes than its row has columns (a cpGIMP box of
half-width L/4 touches 4, 6 or 9 nodes in 2D); each row lists its nodes once, then repeats
its last node with N = dN = 0, and the particle passes stop at that padding.
- For every wide family on its meshes (cpGIMP, uGIMP, B-splines on quadrilaterals, CPDI1 and
  CPDI2 on quadrilaterals and triangles, Gauss-GIMP), after particles have moved off their
  fill positions: the columns before row_length hold distinct nodes and every column from
  it on has N = dN = 0 (so stopping there drops exact zeros only); the GIMP, CPDI1,
  Gauss-GIMP and triangle CPDI2 rows are ragged here (some row shorter than the columns:
  the passes save work).
- The P2G, internal-force and G2P passes that stop at row_length give the same nodal mass,
  momentum, force and particle updates as a dense numpy evaluation over every column
  (1e-12 relative).
- Rows that grow (particles moved off the fill positions after an evaluation there) are
  evaluated again with as many columns as the longest row and equal a fresh evaluation.
Serial and on 2 ranks."""
import numpy as np
import pytest
from dolfinx import mesh
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.kernels import transfer as kt

comm = MPI.COMM_WORLD
QUAD, TRI = mesh.CellType.quadrilateral, mesh.CellType.triangle
# family, mesh, whether its rows here must be ragged (a quadratic B-spline touches 3 x 3
# nodes wherever it is; these CPDI2 corners mostly stay in their cells: 4 nodes each)
CASES = [("cpgimp", QUAD, True), ("ugimp", QUAD, True), ("bspline2", QUAD, False),
         ("cpdi1", QUAD, True), ("cpdi2", QUAD, False), ("gauss", QUAD, True),
         ("cpdi1", TRI, True), ("cpdi2", TRI, True)]


def _mesh(cell_type):
    return mesh.create_rectangle(comm, [[-0.5, -0.5], [1.5, 1.5]], [16, 16], cell_type)


def _block(shape, msh):
    """A 1 x 1 elastic block on 8 x 8 cells of msh (h = 1/8), 2 x 2 particles per cell."""
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, fm.LinearElastic(E=1e3, nu=0.3, density=1.0), per_cell=2,
                          region=lambda x: (np.abs(x[:, 0] - 0.5) < 0.5)
                          & (np.abs(x[:, 1] - 0.5) < 0.5))
    return fm.Simulation(grid, p, fm.Explicit(), dt=1e-4, shape=shape)


def _moved(shape, cell_type, rng):
    """_block after the particles moved by up to 0.3 cells (and F stretched up to 10 %):
    rows of every length."""
    sim = _block(shape, _mesh(cell_type))
    p = sim.particles
    h = 2.0 / 16
    p.x[:] += rng.uniform(-0.3, 0.3, p.x.shape) * h
    p.F[:, 0, 0] *= rng.uniform(0.95, 1.1, len(p))
    p.v[:] = rng.normal(size=p.v.shape)
    sim.locate_and_shape()
    return sim


@pytest.mark.parametrize("shape,cell_type,ragged", CASES, ids=lambda c: getattr(c, "name", c))
def test_rows_are_distinct_nodes_then_zero_padding(shape, cell_type, ragged, rng):
    sim = _moved(shape, cell_type, rng)
    nodes, N, dN = sim.nodes, sim.N, sim.dN
    n, nv = nodes.shape
    length = np.array([kt.row_length(nodes, p) for p in range(n)], dtype=int)
    col = np.arange(nv)[None, :]
    pad = col >= length[:, None]
    assert np.all(N[pad] == 0.0) and np.all(dN[pad] == 0.0), f"{shape}: nonzero padding"
    for p in range(n):
        real = nodes[p, :length[p]]
        assert len(np.unique(real)) == len(real), (shape, p, real)
    short = comm.allreduce(int(n > 0 and length.min() < nv), op=MPI.MAX)
    assert short or not ragged, f"{shape}: every row fills its {nv} columns (no padding to skip)"


@pytest.mark.parametrize("shape,cell_type", [c[:2] for c in CASES[:2] + CASES[6:7]],
                         ids=lambda c: getattr(c, "name", c))
def test_passes_that_stop_at_the_padding_equal_dense_sums(shape, cell_type, rng):
    sim = _moved(shape, cell_type, rng)
    p, g = sim.particles, sim.grid
    nodes, N, dN = sim.nodes, sim.N, sim.dN
    # dense references over every column (np.add.at: the padding adds its zeros)
    m_ref = np.zeros(g.n_nodes)
    mv_ref = np.zeros((g.n_nodes, 2))
    f_ref = np.zeros((g.n_nodes, 2))
    sigma = rng.normal(size=(len(p), 3, 3))
    np.add.at(m_ref, nodes, N * p.mass[:, None])
    np.add.at(mv_ref, nodes, (N * p.mass[:, None])[:, :, None] * p.v[:, None, :])
    np.add.at(f_ref, nodes, -p.V[:, None, None] * np.einsum("pkl,pal->pak", sigma[:, :2, :2], dN))
    m, mv = sim.nodal_mass_momentum()
    f = np.zeros((g.n_nodes, 2))
    kt.p2g_force(g.D, nodes, N, dN, p.mass, p.V, sigma, np.zeros(2), f)
    w = rng.normal(size=(g.n_nodes, 2))
    dF_ref = np.einsum("pai,paj->pij", w[nodes], dN)
    dF = np.empty((len(p), 3, 3))
    kt.incremental_F(g.D, nodes, dN, w, 1.0, dF)
    x_ref = p.x + np.einsum("pa,pak->pk", N, w[nodes])
    x, v, u = p.x.copy(), p.v.copy(), p.u.copy()
    kt.g2p(g.D, nodes, N, w, np.zeros_like(w), w, 1.0, x, v, u)

    def rel(a, b):
        scale = comm.allreduce(float(np.abs(b).max()) if b.size else 0.0, op=MPI.MAX)
        err = comm.allreduce(float(np.abs(a - b).max()) if b.size else 0.0, op=MPI.MAX)
        return err / max(scale, 1e-300)
    errs = dict(mass=rel(m, m_ref), momentum=rel(mv, mv_ref), force=rel(f, f_ref),
                dF=rel(dF[:, :2, :2] - np.eye(2), dF_ref), x=rel(x, x_ref))
    assert max(errs.values()) < 1e-12, errs


@pytest.mark.parametrize("shape,cell_type", [("cpgimp", QUAD), ("ugimp", QUAD),
                                             ("bspline2", QUAD), ("cpdi1", TRI)],
                         ids=lambda c: getattr(c, "name", c))
def test_rows_that_grow_are_evaluated_again_at_their_width(shape, cell_type):
    """A family keeps last step's columns (4 at the fill positions for cpGIMP); when particles
    then touch more nodes, the rows are evaluated again with exactly as many columns as the
    longest row (gimp.PaddedStencil._fill), and equal those of a fresh evaluation."""
    msh = _mesh(cell_type)

    def scene(first_at_fill):                  # one mesh: one partition for both scenes
        sim = _block(shape, msh)
        p = sim.particles
        if first_at_fill:
            sim.locate_and_shape()
        shift = np.random.default_rng(7).uniform(-0.3, 0.3, (p.n_global(), 2)) * (2.0 / 16)
        p.x[:] += shift[p.id]                  # by particle id: the same on any partition
        sim.locate_and_shape()
        return sim
    grown, fresh = scene(True), scene(False)
    n, nv = grown.nodes.shape
    longest = max((kt.row_length(grown.nodes, q) for q in range(n)), default=1)
    assert nv == max(longest, 1)
    assert grown.nodes.shape == fresh.nodes.shape
    assert np.array_equal(grown.nodes, fresh.nodes)
    assert np.array_equal(grown.N, fresh.N) and np.array_equal(grown.dN, fresh.dN)
