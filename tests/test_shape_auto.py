"""shape="auto" (shapes.choose_shape; issue 15): the family picked per mesh and option, with
its reason, the same on every rank; fallbacks to the standard family are named."""
import numpy as np
import pytest
from dolfinx import mesh
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.grid import vertex_ghost_partitioner

comm = MPI.COMM_WORLD


def _sim(cell_type, integrator, ring=True, material=None, per_cell=2, **kw):
    opts = dict(partitioner=vertex_ghost_partitioner()) if ring else {}
    msh = mesh.create_rectangle(comm, [[0, 0], [1, 1]], [8, 8], cell_type, **opts)
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, material or fm.LinearElastic(E=1e6, nu=0.3, density=1e3),
                          per_cell=per_cell)
    kw.setdefault("shape", "auto")
    return fm.Simulation(grid, p, integrator, dt=1e-4, **kw)


@pytest.mark.parametrize("cell_type,family", [(mesh.CellType.quadrilateral, "cpgimp"),
                                              (mesh.CellType.triangle, "cpdi2")])
def test_auto_picks_the_wide_family_of_the_mesh(cell_type, family):
    sim = _sim(cell_type, fm.Explicit())
    assert sim.shape == family, (sim.shape, sim.shape_reason)
    assert comm.allgather(sim.shape) == [family] * comm.size
    sim.run(t_end=5e-4)                                  # runs, serial and 2 ranks


def test_auto_falls_back_with_a_reason():
    assert _sim(mesh.CellType.quadrilateral, fm.Newmark()).shape == "cpgimp"     # elastic
    one = _sim(mesh.CellType.quadrilateral, fm.Newmark(), per_cell=1)
    assert one.shape == "mpm" and "particles per cell" in one.shape_reason, one.shape_reason
    assert _sim(mesh.CellType.quadrilateral, fm.Explicit(), per_cell=1).shape == "cpgimp"
    assert _sim(mesh.CellType.triangle, fm.Newmark()).shape_reason.startswith("implicit")
    sim = _sim(mesh.CellType.quadrilateral, fm.Explicit(), force_integration="mixed")
    assert sim.shape == "mpm" and "mixed" in sim.shape_reason
    sim = _sim(mesh.CellType.quadrilateral, fm.Explicit())
    sim.set_periodic(0)
    assert sim.shape == "mpm" and "periodic" in sim.shape_reason
    mc = fm.MohrCoulomb(E=1e6, nu=0.3, density=1e3, phi=30.0, c=1e3)
    vm = fm.VonMises(E=1e6, nu=0.3, density=1e3, c_u=1e3)
    for material, why in ((mc, "Bishop"), (vm, "Prandtl")):
        name = type(material).__name__
        for cell, integrator, shape, reason in (
                (mesh.CellType.quadrilateral, fm.Explicit(), "cpgimp", why),
                (mesh.CellType.triangle, fm.Explicit(), "mpm", name),
                (mesh.CellType.quadrilateral, fm.QuasiStatic(), "mpm", "implicit")):
            sim = _sim(cell, integrator, material=material)
            assert sim.shape == shape and reason in sim.shape_reason, (name, sim.shape_reason)
    sim = _sim(mesh.CellType.quadrilateral, fm.Explicit(),
               material=fm.NeoHookean(E=1e6, nu=0.3, density=1e3))
    assert sim.shape == "cpgimp"


def test_unknown_shape_lists_the_choices():
    sim = _sim(mesh.CellType.quadrilateral, fm.Explicit())
    with pytest.raises(ValueError, match="'shape' must be one of .*'auto'"):
        fm.Simulation(sim.grid, sim.particles, fm.Explicit(), dt=1e-4, shape="gimp")


@pytest.mark.parametrize("cell_type,shape", [(mesh.CellType.triangle, "auto"),
                                             (mesh.CellType.triangle, "cpdi2"),
                                             (mesh.CellType.quadrilateral, "cpgimp")])
def test_wide_family_on_a_default_partitioned_mesh(cell_type, shape):
    """A mesh made with dolfinx's default partitioner (on 2 ranks the triangle mesh lacks
    the diagonal ghost cells) runs a wide family: the Grid rebuilds it with the vertex ghost
    layer, same cells and owners; the particles and their total mass are kept and a short
    free fall moves the centre of mass by g dt^2 n (n + 1) / 2 after n symplectic-Euler steps
    (to round-off)."""
    msh = mesh.create_rectangle(comm, [[0, 0], [1, 1]], [20, 20], cell_type)
    grid = fm.Grid(msh)
    n_cells = grid.comm.allreduce(grid.n_owned_cells)
    p = fm.Particles.fill(grid, fm.LinearElastic(E=1e6, nu=0.3, density=1e3),
                          region=lambda x: (x[:, 1] > 0.3) & (x[:, 1] < 0.7))
    m0, n0, y0 = p.total(p.mass), p.total(np.ones(len(p))), p.total(p.mass * p.x[:, 1])
    sim = fm.Simulation(grid, p, fm.Explicit(), dt=1e-4, shape=shape, gravity=(0.0, -10.0))
    assert sim.shape in ("cpdi2", "cpgimp") and grid.has_vertex_ring()
    assert grid.comm.allreduce(grid.n_owned_cells) == n_cells
    sim.run(t_end=0.01)
    assert p.total(np.ones(len(p))) == n0 and abs(p.total(p.mass) - m0) < 1e-12 * m0
    drop = (y0 - p.total(p.mass * p.x[:, 1])) / m0
    n = sim.step_count
    assert abs(drop - 0.5 * 10.0 * sim.dt ** 2 * n * (n + 1)) < 1e-9 * drop, drop


def test_unsupported_family_says_what_auto_would_pick():
    """cpGIMP on triangles: ValueError naming the reason and auto's choice (CPDI2)."""
    msh = mesh.create_rectangle(comm, [[0, 0], [1, 1]], [4, 4], mesh.CellType.triangle)
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, fm.LinearElastic(E=1e6, nu=0.3, density=1e3))
    with pytest.raises(ValueError, match="structured grid.*shape='auto' would pick 'cpdi2'"):
        fm.Simulation(grid, p, fm.Explicit(), dt=1e-4, shape="cpgimp")


def test_fbar_auto_follows_the_materials_and_the_integrator():
    """fbar="auto" (setup.SetupMixin._resolve_fbar, issue 21): on with a von Mises material
    where the integrator supports it (explicit; implicit on plane and 3D grids), off for
    other materials, with fbar_reason naming why; an explicit value is kept."""
    vm = fm.VonMises(E=1e6, nu=0.3, density=1e3, c_u=1e3)
    mc = fm.MohrCoulomb(E=1e6, nu=0.3, density=1e3, phi=30.0, c=1e3)
    quad = mesh.CellType.quadrilateral
    sim = _sim(quad, fm.Explicit(), material=vm)
    assert sim.fbar is True and sim.shape == "cpgimp" and "von Mises" in sim.fbar_reason
    sim = _sim(quad, fm.QuasiStatic(), material=vm)
    assert sim.fbar is True and sim.shape == "mpm"
    sim = _sim(quad, fm.Newmark(), material=vm, shape="cpgimp")
    assert sim.fbar is True and sim.shape == "cpgimp"
    sim = _sim(quad, fm.Explicit(), material=vm, force_integration="mixed")
    assert sim.fbar is False and "mixed" in sim.fbar_reason
    for mat in (mc, None):
        sim = _sim(quad, fm.Explicit(), material=mat)
        assert sim.fbar is False and "no von Mises" in sim.fbar_reason
    assert _sim(quad, fm.Explicit(), material=mc, fbar=True).fbar is True
    assert _sim(quad, fm.Explicit(), material=vm, fbar=False).fbar is False
    with pytest.raises(ValueError, match="'fbar' must be True, False or 'auto'"):
        _sim(quad, fm.Explicit(), fbar="yes")


def test_fbar_auto_leaves_implicit_particle_layers_alone():
    """Implicit F-bar does not support particle layers: with fbar="auto" adding one turns
    F-bar off (fbar_reason says why), with fbar=True it raises naming the option."""
    vm = fm.VonMises(E=1e6, nu=0.3, density=1e3, c_u=1e3)
    layer = lambda: fm.ParticleLayer(fm.Viscous(lambda x: x[:, 1] < 0.2),
                                     region=lambda x: x[:, 1] < 0.2, normal=(0.0, -1.0))
    sim = _sim(mesh.CellType.quadrilateral, fm.Newmark(), material=vm)
    assert sim.fbar is True
    sim.add_boundary(layer())
    assert sim.fbar is False and "particle layers" in sim.fbar_reason
    sim = _sim(mesh.CellType.quadrilateral, fm.Newmark(), material=vm, fbar=True)
    with pytest.raises(NotImplementedError, match="fbar=False"):
        sim.add_boundary(layer())
    sim = _sim(mesh.CellType.quadrilateral, fm.Explicit(), material=vm)
    sim.add_boundary(layer())
    assert sim.fbar is True                              # explicit F-bar keeps the layer
