"""Periodic lateral boundaries (BENCHMARKS.md section P, "Periodic sides";
fenicsmpm.boundaries.periodic). Serial and `mpirun -n 2` (the column is cut into vertical
strips with fm.partition.strips, so the left and right faces lie on different ranks).

Shear column: H = 10 m, 2 m wide (4 cells of 0.5 m), E = 1e4 kPa, nu = 0.33,
rho = 1886 kg/m^3 (V_s = 44.65 m/s), fixed base, free top, periodic sides, initial velocity
v_x = v0 sin(pi y / 2H): the first shear mode of the 1D column, v_x(y, t) = v0 cos(omega t)
sin(pi y / 2H), omega = pi V_s / (2H), period T = 0.896 s."""
import numpy as np
import pytest
from mpi4py import MPI
from dolfinx import mesh as dmesh

import fenicsmpm as fm

comm = MPI.COMM_WORLD
H, W, DX, V0 = 10.0, 2.0, 0.5, 0.01


def shear_column(integrator, periodic=True, dt="auto"):
    nx, ny = int(W / DX), int(H / DX)
    msh = dmesh.create_rectangle(comm, [[0, 0], [W, H]], [nx, ny], dmesh.CellType.quadrilateral,
                                 partitioner=fm.partition.strips(nx, ny, axis=0))
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=1e7, nu=0.33, density=1886.0)
    p = fm.Particles.fill(grid, mat, per_cell=2)
    p.v[:, 0] = V0 * np.sin(np.pi * p.x[:, 1] / (2 * H))
    sim = fm.Simulation(grid, p, integrator, dt=dt, on_leave="periodic")
    if periodic:
        sim.set_periodic(0)
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0))
    omega = np.pi * mat.s_wave_speed / (2 * H)
    return sim, omega


def lateral_spread(p):
    """Largest difference of v_x between particles at the same height (global)."""
    y = np.round(p.x[:, 1] - p.u[:, 1], 6)
    rows = {}
    for yy, v in zip(y, p.v[:, 0]):
        lo, hi = rows.get(yy, (np.inf, -np.inf))
        rows[yy] = (min(lo, v), max(hi, v))
    allrows = comm.allgather(rows) if comm.size > 1 else [rows]
    merged = {}
    for r in allrows:
        for k, (lo, hi) in r.items():
            a, b = merged.get(k, (np.inf, -np.inf))
            merged[k] = (min(a, lo), max(b, hi))
    return max(b - a for a, b in merged.values())


@pytest.mark.parametrize("integrator,dt", [(fm.Explicit("USL"), "auto"),
                                           (fm.ExplicitGeneralizedAlpha(0.8), "auto"),
                                           (fm.Newmark(), 0.01)],
                         ids=["usl", "explicit-ga", "newmark"])
def test_uniform_shear_wave_matches_1d(integrator, dt):
    """Two periods of the first shear mode: the top velocity follows v0 cos(omega t) within
    3 % of v0 and particles at equal height move identically (spread < 1e-10 v0); with free
    sides instead of periodic ones the column is no shear beam (error > 50 % of v0)."""
    sim, omega = shear_column(integrator, dt=dt)
    pr = sim.probe([0.25, H - 0.125], ["velocity"])
    sim.run(t_end=2 * 2 * np.pi / omega, progress=False)
    d = pr.data()
    err = np.max(np.abs(d["velocity_x"] - d["velocity_x"][0] * np.cos(omega * d["t"]))) / V0
    assert err < 0.03, err
    assert lateral_spread(sim.particles) < 1e-10 * V0
    if integrator.explicit and isinstance(integrator, fm.Explicit):
        free, _ = shear_column(fm.Explicit("USL"), periodic=False)
        pf = free.probe([0.25, H - 0.125], ["velocity"])
        free.run(t_end=2 * 2 * np.pi / omega, progress=False)
        df = pf.data()
        err_free = np.max(np.abs(df["velocity_x"] - df["velocity_x"][0] * np.cos(omega * df["t"]))) / V0
        assert err_free > 0.5, err_free


def test_tie_sums_pairs_across_ranks():
    """Each pair of side nodes holds the sum of both after accumulate (the faces are on
    different ranks under mpirun -n 2)."""
    sim, _ = shear_column(fm.Explicit("USL"))
    grid = sim.grid
    a = np.where(grid.node_x[:, 0] < 1e-9, 1.0, 0.0) + np.where(grid.node_x[:, 0] > W - 1e-9, 2.0, 0.0)
    a[grid.n_owned_nodes:] = 0.0                      # ghosts: reverse scatter adds owners
    a2 = np.stack([a, 10 * a], axis=1)
    grid.accumulate(a, a2)
    side = (grid.node_x[:, 0] < 1e-9) | (grid.node_x[:, 0] > W - 1e-9)
    assert np.all(a[side] == 3.0) and np.all(a[~side] == 0.0)
    assert np.all(a2[side, 1] == 30.0)
    assert grid.periodic.n_pairs == int(H / DX) + 1


def test_particle_wraps_with_state_intact():
    """A rigid translation v = 3 m/s to the right, no base: after 0.4 s every particle has
    moved 1.2 m, those that crossed x = W re-entered at x - W; velocity, stress (a uniform
    sigma_xx, in equilibrium only because the faces are tied), F, mass and id are unchanged
    and no particle is lost."""
    nx, ny = 4, 4
    msh = dmesh.create_rectangle(comm, [[0, 0], [W, 2.0]], [nx, ny], dmesh.CellType.quadrilateral,
                                 partitioner=fm.partition.strips(nx, ny, axis=0))
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, fm.LinearElastic(E=1e7, nu=0.33, density=1886.0), per_cell=2)
    p.v[:, 0] = 3.0
    p.stress[:, 0, 0] = 1.0e3      # a state to carry along; balanced only through the tie
    x0 = {}
    for part in comm.allgather({int(i): x.copy() for i, x in zip(p.id, p.x)}):
        x0.update(part)                                       # particles migrate between ranks
    n0 = comm.allreduce(len(p))
    sim = fm.Simulation(grid, p, fm.Explicit("USL"), dt=0.004, on_leave="periodic")
    sim.set_periodic(0)
    sim.run(steps=100, progress=False)
    p = sim.particles
    assert comm.allreduce(len(p)) == n0
    wrapped = 0
    for i, x in zip(p.id, p.x):
        expect = (x0[int(i)][0] + 1.2) % W
        assert abs(x[0] - expect) < 1e-9 and abs(x[1] - x0[int(i)][1]) < 1e-12
        wrapped += x0[int(i)][0] + 1.2 > W
    assert comm.allreduce(wrapped) == n0 * 5 // 8          # particle columns x0 >= 0.875 crossed
    assert np.allclose(p.v[:, 0], 3.0, rtol=0, atol=1e-12) and np.allclose(p.v[:, 1], 0.0, atol=1e-12)
    assert np.allclose(p.stress[:, 0, 0], 1.0e3, rtol=1e-12)
    assert np.allclose(p.F, np.eye(3), atol=1e-12)
    assert np.allclose(p.mass, p.mass[0])


def test_periodic_leave_needs_tie_and_reports_other_exits():
    """on_leave='periodic' without set_periodic is refused when a particle leaves; a
    particle leaving through the top still stops the run."""
    msh = dmesh.create_rectangle(comm, [[0, 0], [1.0, 1.0]], [2, 2], dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, fm.LinearElastic(E=1e7, nu=0.33, density=1886.0), per_cell=1)
    p.v[:, 1] = 30.0
    sim = fm.Simulation(grid, p, fm.Explicit("USL"), dt=0.004, on_leave="periodic")
    with pytest.raises(ValueError, match="set_periodic"):
        sim.run(steps=10, progress=False)
    grid.periodic = None
    sim = fm.Simulation(grid, p, fm.Explicit("USL"), dt=0.004, on_leave="periodic")
    sim.set_periodic(0)
    with pytest.raises(fm.simulation.ParticlesLeftMesh):
        sim.run(steps=10, progress=False)
