"""Prescribed particle displacement by penalty (Simulation.move_particles,
fenicsmpm.boundaries.particle_motion), serially and under `mpirun -n 2`.

Scene: a weightless linear elastic column (E = 1 MPa, nu = 0.3, M = E (1 - nu) / ((1 + nu)
(1 - 2 nu)) = 1.346 MPa), 0.5 m x 2 m, quadrilaterals h = 0.125 m, 2 x 2 particles per cell,
bottom fixed, rollers on both sides (oedometric), its top particle row pushed down by
delta = 1e-5 m in one quasi-static step. Measured (serial and 2 ranks, both families): the
pushed particles move 0.99872 delta with the default penalty 100 (the springs' lag), the
stress below the top cell is the reaction over the width to round-off, the particle reaction
balances the base reaction to round-off, and sigma_yy is 1.012 x M u_top / (H - h/4) (the top
cell carries the load into the grid: a first-order error in h)."""
import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenicsmpm as fm

W, H, DELTA = 0.5, 2.0, 1e-5
M = 1e6 * 0.7 / (1.3 * 0.4)


def _column(h=0.125, integrator=None, shape="auto"):
    msh = dmesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [W, H]],
                                 [round(W / h), round(H / h)], dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    pts = fm.Particles.fill(grid, fm.LinearElastic(E=1e6, nu=0.3, density=1000.0), per_cell=2)
    sim = fm.Simulation(grid, pts, integrator or fm.QuasiStatic(), dt=1.0 if integrator is None else "auto",
                        shape=shape)
    sim.fix(lambda x: np.abs(x[:, 1]) < 1e-9)
    sim.fix(lambda x: (np.abs(x[:, 0]) < 1e-9) | (np.abs(x[:, 0] - W) < 1e-9), [0])
    return sim


def _push(X, t):
    return np.column_stack([np.zeros(len(X)), np.full(len(X), -DELTA * t)])


def _gather(comm, a):
    return np.concatenate(comm.allgather(a))


@pytest.mark.parametrize("shape", ["mpm", "auto"])
@pytest.mark.parametrize("penalty", [100.0, 1000.0])
def test_pushed_column(shape, penalty):
    h = 0.125
    sim = _column(h, shape=shape)
    top = lambda x: x[:, 1] > H - 0.5 * h
    sel = top(sim.particles.x)
    k = sim.move_particles(top, _push, components=[1], penalty=penalty)
    sim.run(steps=1)
    p, comm = sim.particles, sim.comm
    R = sim.particle_reaction(k)
    base = sim.reaction(lambda x: np.abs(x[:, 1]) < 1e-9)
    assert R[1] < 0
    assert np.allclose(R + base, 0.0, atol=1e-9 * abs(R[1]))            # equilibrium
    u_top = _gather(comm, p.u[sel, 1])
    lag = 1.0 + np.mean(u_top) / DELTA
    assert np.ptp(u_top) < 1e-9 * DELTA
    assert 0 < lag < 0.2 / penalty                      # the springs' lag: 0.128 % at 100
    low = p.x[:, 1] < H / 2
    s_low = _gather(comm, p.stress[low, 1, 1])
    assert np.allclose(s_low, R[1] / W, rtol=1e-6)      # uniform, equal to the reaction
    ratio = np.mean(s_low) / (M * np.mean(u_top) / (H - h / 4))
    assert abs(ratio - 1.0) < 0.015, ratio              # 1.012 at h = 0.125


def test_first_order_in_h():
    """sigma_yy / (M u_top / (H - h/4)) - 1 halves with h: 1.2 % at h = 0.125, 0.6 % at 0.0625."""
    errs = []
    for h in (0.125, 0.0625):
        sim = _column(h, shape="mpm")
        top = lambda x: x[:, 1] > H - 0.5 * h
        sel = top(sim.particles.x)
        sim.move_particles(top, _push, components=[1])
        sim.run(steps=1)
        p = sim.particles
        u = np.mean(_gather(sim.comm, p.u[sel, 1]))
        s = np.mean(_gather(sim.comm, p.stress[p.x[:, 1] < H / 2, 1, 1]))
        errs.append(s / (M * u / (H - h / 4)) - 1.0)
    assert 0 < errs[1] < 0.6 * errs[0], errs


def test_bad_input():
    sim = _column()
    with pytest.raises(ValueError, match="'region' selects no particle"):
        sim.move_particles(lambda x: x[:, 1] > 2 * H, _push)
    with pytest.raises(ValueError, match="'components'"):
        sim.move_particles(lambda x: x[:, 1] > H - 0.05, _push, components=[2])
    with pytest.raises(ValueError, match="'penalty'"):
        sim.move_particles(lambda x: x[:, 1] > H - 0.05, _push, penalty=0.0)
    with pytest.raises(TypeError, match="'displacement'"):
        sim.move_particles(lambda x: x[:, 1] > H - 0.05, 1.0)
    with pytest.raises(ValueError, match="no prescribed particle motion"):
        sim.particle_reaction(0)
    explicit = _column(integrator=fm.Explicit())
    with pytest.raises(NotImplementedError, match="implicit"):
        explicit.move_particles(lambda x: x[:, 1] > H - 0.05, _push)


@pytest.mark.parametrize("rough", [False, True])
@pytest.mark.heavy
def test_particle_footing_converges_on_prandtl(rough):
    """Prandtl's footing on weightless Tresca soil, implicit, pushed through its top
    particle row (problems.localisation.strip_footing(footing="particles"), 30 mm in 30
    steps), smooth (the row moves freely sideways) and rough (held sideways; the same limit
    on weightless Tresca soil): the mean pressure over the last third is 1.264 / 1.098
    (smooth) and 1.277 / 1.108 (rough) (2 + pi) c_u at 2 / 5 cells under B/2 (pushed in 60
    steps: 1.052 and 1.054 at 10 cells; with the footing's edge at a cell centre 0.996 and
    1.007 at 10.5 cells, bench bearing-capacity's implicit rows): it falls towards
    Prandtl's value, the error 2.6-2.7 x smaller."""
    from fenicsmpm.problems import localisation
    q = []
    for h in (0.25, 0.1):
        r = localisation.strip_footing(
            h, material=fm.VonMises(E=10e6, nu=0.49, density=1800.0, c_u=1e4), width=5.0,
            depth=3.0, half_width=0.5, settlement=0.03, steps=30, footing="particles",
            rough=rough)
        assert r["completed"], r["stopped"]
        p = r["pressure"] / ((2.0 + np.pi) * 1e4)
        q.append(np.mean(p[len(p) * 2 // 3:]))
    assert 1.0 < q[1] < q[0] < 1.3, q
    assert q[1] - 1.0 < 0.45 * (q[0] - 1.0), q


def test_rough_footing_needs_a_particle_footing():
    from fenicsmpm.problems import localisation
    with pytest.raises(ValueError, match="rough"):
        localisation.strip_footing(0.5, footing="nodes", rough=True)

