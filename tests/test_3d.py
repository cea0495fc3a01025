"""3D: the V2 self-weight column on hexahedra and tetrahedra (quasi-static and Newmark)."""
import numpy as np
import pytest
from mpi4py import MPI
from dolfinx import mesh

import fenicsmpm as fm

H, h, N = 10.0, 1.0, 10
E, RHO, G = 1e8, 2000.0, 10.0


def column(ct, integrator, dt):
    msh = mesh.create_box(MPI.COMM_WORLD, [[0, 0, 0], [h, h, H + h]], [1, 1, N + 1], ct)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=E, nu=0.0, density=RHO)
    p = fm.Particles.fill(grid, mat, per_cell=2, region=lambda x: x[:, 2] < H)
    sim = fm.Simulation(grid, p, integrator, dt=dt, gravity=(0.0, 0.0, -G))
    sim.fix(lambda x: np.isclose(x[:, 0], 0) | np.isclose(x[:, 0], h), [0])
    sim.fix(lambda x: np.isclose(x[:, 1], 0) | np.isclose(x[:, 1], h), [1])
    sim.fix(lambda x: np.isclose(x[:, 2], 0), [2])
    return sim


def _band_mean(p, z0, lo, hi, values):
    sel = (z0 >= lo) & (z0 < hi)
    return p.total(np.where(sel, values * p.V0, 0.0)) / p.total(np.where(sel, p.V0, 0.0))


@pytest.mark.parametrize("ct", [mesh.CellType.hexahedron, mesh.CellType.tetrahedron])
def test_quasistatic_column_3d(ct):
    """sigma_zz in the cell layer around mid-depth within 2 % of -rho g (H - z) at the layer's
    mean height, top-layer settlement within 3 % of the exact u_z there."""
    sim = column(ct, fm.QuasiStatic(load_steps=2), 1.0)
    sim.run(steps=2)
    p = sim.particles
    z0 = (p.x - p.u)[:, 2]
    lo = np.floor(H / 2 / h) * h
    s_mid = _band_mean(p, z0, lo, lo + h, p.stress[:, 2, 2])
    z_mid = _band_mean(p, z0, lo, lo + h, z0)
    exact = -RHO * G * (H - z_mid)
    assert abs(s_mid / exact - 1) < 0.02, f"sigma_zz {s_mid:.1f} vs {exact:.1f}"
    u_top = _band_mean(p, z0, H - h, H, p.u[:, 2])
    z_top = _band_mean(p, z0, H - h, H, z0)
    u_exact = -RHO * G * (H * z_top - 0.5 * z_top ** 2) / E
    assert abs(u_top / u_exact - 1) < 0.03, f"u_z {u_top:.5e} vs {u_exact:.5e}"
    assert max(sim.integrator.iterations) <= 3


def test_newmark_column_3d_hex_oscillates_about_static():
    """Suddenly applied gravity (Newmark, no damping): the top oscillates between 0 and twice
    the static settlement; its time average over a period is the static value (5 %)."""
    c = np.sqrt(E / RHO)
    period = 4 * H / c
    dt = period / 80
    sim = column(mesh.CellType.hexahedron, fm.Newmark(), dt)
    probe = sim.probe((h / 4, h / 4, H - h / 4), ["displacement"])
    sim.run(steps=80)
    d = probe.data()
    u = d["displacement_z"][1:]
    z = H - h / 4
    static = -RHO * G * (H * z - 0.5 * z ** 2) / E
    assert abs(np.mean(u) / static - 1) < 0.05, f"mean {np.mean(u):.4e} vs static {static:.4e}"
    assert abs(np.min(u) / (2 * static) - 1) < 0.1, f"peak {np.min(u):.4e} vs 2 x static"
