"""Frictional rigid base (issue 7; seed 002 §5.1 with the static check): a block sliding on a
rough floor stops after v0^2 / (2 mu g); on a rough incline (gravity tilted by theta) it
sticks for tan(theta) < mu and otherwise accelerates at g (sin(theta) - mu cos(theta))."""
import numpy as np
import pytest
from dolfinx import mesh
from mpi4py import MPI

import fenicsmpm as fm

G = 9.81


def _block(theta_deg, mu, v0, t_end, n=32):
    """A 0.25 m x 0.25 m elastic block (E = 2 MPa) on the floor of a 2 m x 0.5 m grid, with
    its geostatic stress; returns the mass-weighted x displacement and the simulation."""
    msh = mesh.create_rectangle(MPI.COMM_WORLD, [[0, 0], [2.0, 0.5]], [n, n // 4],
                                mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    rho, bh, th = 1000.0, 0.25, np.radians(theta_deg)
    mat = fm.LinearElastic(E=2e6, nu=0.3, density=rho)
    p = fm.Particles.fill(grid, mat, per_cell=2, velocity=(v0, 0.0),
                          region=lambda x: (x[:, 0] > 0.25) & (x[:, 0] < 0.5) & (x[:, 1] < bh))
    p.stress[:, 1, 1] = -rho * G * np.cos(th) * (bh - p.x[:, 1])
    p.stress[:, 0, 0] = p.stress[:, 2, 2] = 0.3 / 0.7 * p.stress[:, 1, 1]
    sim = fm.Simulation(grid, p, fm.Explicit("MUSL"), dt="auto",
                        gravity=(G * np.sin(th), -G * np.cos(th)))
    sim.add_friction(lambda x: np.isclose(x[:, 1], 0.0), mu, (0.0, -1.0))
    m0 = p.total(p.mass)
    x0 = p.total(p.mass * p.x[:, 0]) / m0
    sim.run(t_end=t_end)
    return p.total(p.mass * p.x[:, 0]) / m0 - x0, sim


def test_sliding_block_stops_after_v0_squared_over_2_mu_g():
    """v0 = 2 m/s, mu = 0.3: stops after 0.6796 m at t = 0.68 s (measured 0.6797 m, 0.02 %)."""
    d, sim = _block(0.0, 0.3, 2.0, 1.0)
    exact = 2.0 ** 2 / (2 * 0.3 * G)
    assert abs(d - exact) < 0.05 * exact, (d, exact)
    p = sim.particles
    v_mean = p.momentum()[0] / p.total(p.mass)
    assert abs(v_mean) < 0.01 * 2.0, v_mean          # at rest at t = 1 s (elastic ringing only)


def test_block_sticks_on_incline_below_friction_angle():
    """theta = 20 deg, mu = 0.5 > tan(theta) = 0.364: only elastic creep (measured 0.5 mm)
    against 0.42 m of frictionless sliding in 0.5 s."""
    d, sim = _block(20.0, 0.5, 0.0, 0.5)
    free = 0.5 * G * np.sin(np.radians(20.0)) * sim.t ** 2
    assert abs(d) < 0.01 * free, (d, free)


def test_block_slides_on_incline_above_friction_angle():
    """theta = 30 deg, mu = 0.3: a = g (sin - mu cos) = 2.36 m/s^2; displacement at 0.5 s
    within 5 % of a t^2 / 2 (measured +1.1 %)."""
    d, sim = _block(30.0, 0.3, 0.0, 0.5)
    th = np.radians(30.0)
    exact = 0.5 * G * (np.sin(th) - 0.3 * np.cos(th)) * sim.t ** 2
    assert abs(d - exact) < 0.05 * exact, (d, exact)


def test_friction_input_validation():
    msh = mesh.create_rectangle(MPI.COMM_WORLD, [[0, 0], [1, 1]], [4, 4], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, fm.LinearElastic(E=1e6, nu=0.3, density=1e3))
    sim = fm.Simulation(grid, p, fm.Explicit(), dt=1e-4)
    with pytest.raises(ValueError, match="'mu' must be a finite number >= 0, got -0.1"):
        sim.add_friction(lambda x: np.isclose(x[:, 1], 0.0), -0.1, (0.0, -1.0))
    with pytest.raises(ValueError, match="'normal' must have length 2"):
        sim.add_friction(lambda x: np.isclose(x[:, 1], 0.0), 0.3, (0.0, 0.0, -1.0))
    with pytest.raises(ValueError, match="matches no grid node"):
        sim.add_friction(lambda x: x[:, 1] < -1.0, 0.3, (0.0, -1.0))
    with pytest.raises(NotImplementedError, match="need fm.Explicit or fm.ExplicitContact, not Newmark"):
        fm.Simulation(grid, p, fm.Newmark(), dt=1e-3).add_friction(lambda x: x[:, 1] < 1e-9, 0.3, (0, -1))
