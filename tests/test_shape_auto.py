"""shape="auto" (shapes.choose_shape; issue 15): the family picked per mesh and option, with
its reason, the same on every rank; fallbacks to the standard family are named."""
import numpy as np
import pytest
from dolfinx import mesh
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.grid import vertex_ghost_partitioner

comm = MPI.COMM_WORLD


def _sim(cell_type, integrator, ring=True, **kw):
    opts = dict(partitioner=vertex_ghost_partitioner()) if ring else {}
    msh = mesh.create_rectangle(comm, [[0, 0], [1, 1]], [8, 8], cell_type, **opts)
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, fm.LinearElastic(E=1e6, nu=0.3, density=1e3))
    return fm.Simulation(grid, p, integrator, dt=1e-4, shape="auto", **kw)


@pytest.mark.parametrize("cell_type,family", [(mesh.CellType.quadrilateral, "cpgimp"),
                                              (mesh.CellType.triangle, "cpdi2")])
def test_auto_picks_the_wide_family_of_the_mesh(cell_type, family):
    sim = _sim(cell_type, fm.Explicit())
    assert sim.shape == family, (sim.shape, sim.shape_reason)
    assert comm.allgather(sim.shape) == [family] * comm.size
    sim.run(t_end=5e-4)                                  # runs, serial and 2 ranks


def test_auto_falls_back_with_a_reason():
    assert _sim(mesh.CellType.quadrilateral, fm.Newmark()).shape_reason.startswith("implicit")
    sim = _sim(mesh.CellType.quadrilateral, fm.Explicit(), force_integration="mixed")
    assert sim.shape == "mpm" and "mixed" in sim.shape_reason
    sim = _sim(mesh.CellType.quadrilateral, fm.Explicit())
    sim.set_periodic(0)
    assert sim.shape == "mpm" and "periodic" in sim.shape_reason
    sim = _sim(mesh.CellType.quadrilateral, fm.Explicit(), ring=False)
    if not sim.grid.has_vertex_ring():      # dolfinx's default ghosts may lack diagonal cells
        assert sim.shape == "mpm" and "vertex ghost layer" in sim.shape_reason
    else:
        assert sim.shape == "cpgimp"


def test_unknown_shape_lists_the_choices():
    sim = _sim(mesh.CellType.quadrilateral, fm.Explicit())
    with pytest.raises(ValueError, match="'shape' must be one of .*'auto'"):
        fm.Simulation(sim.grid, sim.particles, fm.Explicit(), dt=1e-4, shape="gimp")
