"""Tractions as UFL ds forms: a column compressed by a top traction (quasi-static and dynamic)."""
import numpy as np
import pytest
from mpi4py import MPI
from dolfinx import mesh

import fenicsmpm as fm

H, W, NY = 4.0, 0.25, 16
E, NU, RHO = 1e7, 0.0, 1000.0
P = 1e4       # traction magnitude (Pa); strain P/M = 1e-3


def _column(integrator, dt, cell_type=mesh.CellType.quadrilateral, value=(0.0, -P), shape="auto"):
    comm = MPI.COMM_WORLD
    h = H / NY
    msh = mesh.create_rectangle(comm, [[0, 0], [W, H]], [1, NY], cell_type)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=E, nu=NU, density=RHO)
    pts = fm.Particles.fill(grid, mat, per_cell=2)
    sim = fm.Simulation(grid, pts, integrator, dt=dt, shape=shape)
    sim.fix(lambda x: np.isclose(x[:, 0], 0) | np.isclose(x[:, 0], W), [0])
    sim.fix(lambda x: np.isclose(x[:, 1], 0), [1])
    sim.add_traction(lambda x: np.isclose(x[:, 1], H), value)
    return sim, mat, h


@pytest.mark.parametrize("cell_type", [mesh.CellType.quadrilateral, mesh.CellType.triangle])
def test_quasistatic_top_traction(cell_type):
    """Uniform compression: sigma_yy = -P everywhere, top settlement P H / M (to 0.5 %).
    Standard family (exact here, -0.1 %): with the implicit default cpGIMP the interior
    particles read within 2e-4 but the top two rows 1.6 % low, because their boxes have
    settled u_top = 4 mm (1.6 % of h) below the loaded facet, which stays on the mesh."""
    sim, mat, h = _column(fm.QuasiStatic(load_steps=1), 1.0, cell_type, shape="mpm")
    sim.run(steps=2)
    p = sim.particles
    M = mat.constrained_modulus
    err_s = sim.comm.allreduce(float(np.max(np.abs(p.stress[:, 1, 1] + P), initial=0.0)), op=MPI.MAX) / P
    assert err_s < 5e-3, f"sigma_yy error {err_s:.2e} relative (tolerance 0.5 %)"
    y0 = (p.x - p.u)[:, 1]
    # displacement is linear in y: u_y = -P y / M
    err_u = sim.comm.allreduce(float(np.max(np.abs(p.u[:, 1] + P * y0 / M), initial=0.0)), op=MPI.MAX)
    assert err_u < 5e-3 * P * H / M, f"u_y error {err_u:.3e} m (tolerance 0.5 % of P H / M)"


def test_time_dependent_amplitude_dynamic():
    """A top load ramped smoothly (sin^2) to P over t_r = 0.25 H/c (4 cells):
    - before the wave reaches the base, the column's momentum equals the applied impulse
      -W int P dt (the ds form's nodal forces sum to the traction resultant);
    - at t = t_r + 0.4 H/c the top 30 % carries -P, and the bottom 25 % (beyond the front at
      depth 0.65 H) is still unloaded."""
    c = np.sqrt(E / RHO)
    dt = 0.2 * (H / NY) / c
    t_r = 0.25 * H / c
    ramp = lambda t: np.sin(0.5 * np.pi * min(t / t_r, 1.0)) ** 2
    sim, mat, h = _column(fm.Explicit("MUSL"), dt, value=lambda t: (0.0, -P * ramp(t)))
    t_front = t_r + 0.4 * H / c
    sim.run(t_end=t_front)
    p = sim.particles
    # impulse: the load is applied at t_k (k = 0..n-1), int P dt = dt sum P(t_k)
    impulse = -W * dt * sum(P * ramp(k * dt) for k in range(sim.step_count))
    py = p.momentum()[1]
    # not round-off: the fixed base already reacts to the dispersive precursor of the front
    assert abs(py / impulse - 1) < 1e-4, f"momentum {py:.6g} vs impulse {impulse:.6g}"
    y0 = (p.x - p.u)[:, 1]
    top = p.total(np.where(y0 > H - 0.3 * H, p.stress[:, 1, 1] * p.V0, 0.0)) / p.total(np.where(y0 > H - 0.3 * H, p.V0, 0.0))
    bottom = p.total(np.where(y0 < 0.25 * H, np.abs(p.stress[:, 1, 1]) * p.V0, 0.0)) / p.total(np.where(y0 < 0.25 * H, p.V0, 0.0))
    assert abs(top / -P - 1) < 0.1, f"top stress {top:.4g} vs {-P} (tolerance 10 %)"
    assert bottom < 0.05 * P, f"bottom stress {bottom:.4g} should be ~0 before the front arrives"


def test_traction_on_nodes_without_material_warns():
    """A traction on facets the material has left is lost: the run says so (once)."""
    comm = MPI.COMM_WORLD
    msh = mesh.create_rectangle(comm, [[0, 0], [1, 2]], [2, 4], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=1e6, nu=0.0, density=1000.0)
    pts = fm.Particles.fill(grid, mat, per_cell=2, region=lambda x: x[:, 1] < 1.0)
    sim = fm.Simulation(grid, pts, fm.QuasiStatic(), dt=1.0)
    sim.fix(lambda x: np.isclose(x[:, 1], 0))
    sim.add_traction(lambda x: np.isclose(x[:, 1], 2.0), (0.0, -1e3))   # top facet: no material
    if comm.rank == 0:
        with pytest.warns(RuntimeWarning, match="without material"):
            sim.run(steps=1)
    else:
        sim.run(steps=1)


def test_particle_load_follows_material_and_gives_its_impulse():
    """A free block pushed by a particle load: total momentum equals the impulse to round-off
    (the load's nodal forces sum to value(t)), on any number of ranks."""
    comm = MPI.COMM_WORLD
    msh = mesh.create_rectangle(comm, [[0, 0], [4, 4]], [8, 8], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)
    pts = fm.Particles.fill(grid, mat, per_cell=2,
                            region=lambda x: np.all((x > 1.0) & (x < 3.0), axis=1))
    sim = fm.Simulation(grid, pts, fm.Explicit("MUSL"), dt="auto")
    n = sim.add_particle_load(lambda x: x[:, 1] > 2.8, lambda t: (50.0 * t, -200.0))
    assert n == 8                                   # the top particle row of the block
    sim.run(steps=40)
    ts = np.arange(40) * sim.dt
    impulse = np.array([np.sum(50.0 * ts), -200.0 * 40]) * sim.dt
    assert np.allclose(pts.momentum(), impulse, rtol=1e-12, atol=0), (pts.momentum(), impulse)
    with pytest.raises(ValueError, match="selects no particle"):
        sim.add_particle_load(lambda x: x[:, 1] > 10.0, (0.0, 1.0))
