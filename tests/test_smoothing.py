"""Grid-smoothed stress (seed 002 eqs 4.18-4.19): constants reproduced, the mass-weighted
total kept exactly, particle noise filtered; as output field and as optional feedback."""
import os

import numpy as np
import pytest
from dolfinx import mesh
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.problems.elastic import vibrating_bar

WORLD = MPI.COMM_WORLD


def _block():
    msh = mesh.create_rectangle(WORLD, [[0, 0], [1, 1]], [8, 8], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, fm.LinearElastic(E=1e3, nu=0.3, density=1.0), per_cell=3)
    return fm.Simulation(grid, p, fm.Explicit(), dt=1e-4)


def test_constants_exact_totals_kept_noise_filtered():
    sim = _block()
    p = sim.particles
    p.stress[:] = np.array([[1.0, 2.0, 0], [2.0, -3.0, 0], [0, 0, 0.5]])
    s = sim.smoothed_stress()
    assert np.allclose(s, p.stress, rtol=0, atol=1e-13)
    # a linear field sigma_xx = x plus a +-0.5 particle checkerboard
    rng = np.random.default_rng(3 + WORLD.rank)
    exact = p.x[:, 0].copy()
    p.stress[:] = 0.0
    p.stress[:, 0, 0] = exact + 0.5 * rng.choice([-1.0, 1.0], len(p))
    s = sim.smoothed_stress()
    tot = lambda a: p.total(p.mass[:, None, None] * a)
    assert np.allclose(tot(s), tot(p.stress), rtol=1e-13, atol=1e-15)
    raw = np.sqrt(p.total((p.stress[:, 0, 0] - exact) ** 2))
    smooth = np.sqrt(p.total((s[:, 0, 0] - exact) ** 2))
    assert smooth < 0.35 * raw, (smooth, raw)


def test_output_field_and_feedback(shared_tmp_path):
    sim = _block()
    out = fm.Output(os.path.join(shared_tmp_path, "out"), every=1, grid_fields=False,
                    particle_fields=("stress", "stress_smoothed", "id"))
    sim.run(steps=2, output=out, progress=False)
    WORLD.barrier()
    name = "particles_000002.vtu" if WORLD.size == 1 else "particles_000002.pvtu"
    text = open(os.path.join(shared_tmp_path, "out", name)).read()
    assert "stress_smoothed" in text
    # the bar with smoothed-stress feedback still vibrates at the exact period (within 1 %)
    b, exact = vibrating_bar(fm.Explicit("MUSL"), n_cells=20)
    b = fm.Simulation(b.grid, b.particles, fm.Explicit("MUSL"), dt=b.dt, stress_feedback="smoothed")
    b.fix(lambda x: np.isclose(x[:, 0], 0.0), [0])
    b.fix(lambda x: np.full(len(x), True), [1])
    pr = b.probe((1.0 - 0.0125, 0.025), fields=("velocity",))
    b.run(t_end=1.5 * exact["period"], progress=False)
    d = pr.data()
    v = d["velocity_x"]
    crossings = d["t"][1:][np.diff(np.sign(v)) != 0]
    period = 2 * (crossings[1] - crossings[0])
    assert abs(period / exact["period"] - 1) < 0.01, period / exact["period"]
    with pytest.raises(NotImplementedError, match="explicit"):
        fm.Simulation(b.grid, b.particles, fm.Newmark(), dt=1e-3, stress_feedback="smoothed")
    with pytest.raises(ValueError, match="stress_feedback"):
        fm.Simulation(b.grid, b.particles, fm.Explicit(), dt=1e-4, stress_feedback="gauss")
