"""Particle-layer absorbing boundary (seed 000 methods 2/4) on the W1 column."""
import numpy as np
import pytest
from mpi4py import MPI
from dolfinx import mesh

import fenicsmpm as fm

H, DX = 100.0, 0.5
E, NU, RHO = 20e6, 0.25, 1500.0
T0, A, IMPULSE = 0.05, 0.021, 0.375e3


def load(t):
    return IMPULSE / (A * np.sqrt(np.pi)) * np.exp(-((t - T0) / A) ** 2)


def column(integrator, dt, law, below=0.0):
    """W1 column on [0, H]; the mesh extends `below` metres under the material, so with
    below > 0 no mesh facet lies on the material's base: only the particle layer can absorb."""
    msh = mesh.create_rectangle(MPI.COMM_WORLD, [[0, -below], [DX, H]],
                                [1, int(round((H + below) / DX))], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=E, nu=NU, density=RHO)
    pts = fm.Particles.fill(grid, mat, per_cell=2, region=lambda x: x[:, 1] > 0.0)
    sim = fm.Simulation(grid, pts, integrator, dt=dt)
    sim.fix(lambda x: np.isclose(x[:, 0], 0) | np.isclose(x[:, 0], DX), [0])
    sim.add_boundary(fm.ParticleLayer(law, region=lambda x: x[:, 1] < DX / 2, normal=(0.0, -1.0)))
    sim.add_traction(lambda x: np.isclose(x[:, 1], H), lambda t: (0.0, -load(t)))
    mid = sim.probe((DX / 4, H / 2), ["stress"])
    base = sim.probe((DX / 4, 0.0), ["displacement"])
    return sim, mat, mid, base


def reflection(mid, cp):
    d = mid.data()
    t, s = d["t"], -d["stress_yy"]
    incident = t < T0 + 0.5 * H / cp + 0.2
    return np.max(np.abs(s[t > T0 + 0.5 * H / cp + 0.25])) / np.max(s[incident])


@pytest.mark.parametrize("integrator,dt", [("explicit", "auto"), ("newmark", 0.005)])
@pytest.mark.parametrize("below", [0.0, 2.0])
def test_viscous_layer_absorbs(integrator, dt, below):
    """Reflection < 5 % and final base offset within 5 % of I/(rho c_p), also when the mesh
    boundary is 2 m below the material (no facet to put a mesh dashpot on)."""
    integ = fm.Explicit("MUSL") if integrator == "explicit" else fm.Newmark()
    sim, mat, mid, base = column(integ, dt, fm.Viscous(), below)
    sim.run(t_end=1.5)
    cp = mat.p_wave_speed
    r = reflection(mid, cp)
    u = base.data()["displacement_y"][-1]
    offset = IMPULSE / (RHO * cp)
    assert r < 0.05, f"reflection ratio {r:.4f} (tolerance 5 %)"
    assert abs(-u / offset - 1) < 0.05, f"base offset {-u * 1e3:.4f} mm vs {offset * 1e3:.4f} mm"
    if integrator == "newmark":
        assert max(sim.integrator.iterations) <= 2, "the layer tangent should keep Newton at 1-2 iterations"


def test_viscoelastic_layer_returns_towards_zero():
    sim, mat, mid, base = column(fm.Explicit("MUSL"), "auto",
                                 fm.Viscoelastic(r_b=H))
    sim.run(t_end=2.5)
    d = base.data()
    u12 = np.interp(1.2, d["t"], d["displacement_y"])
    u25 = d["displacement_y"][-1]
    assert abs(u25) < abs(u12), f"|u(2.5)| = {abs(u25):.3e} should be below |u(1.2)| = {abs(u12):.3e}"


def test_layer_input_errors():
    msh = mesh.create_rectangle(MPI.COMM_WORLD, [[0, 0], [1, 1]], [2, 2], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=E, nu=NU, density=RHO)
    sim = fm.Simulation(grid, fm.Particles.fill(grid, mat), fm.Explicit(), dt="auto")
    bot = lambda x: np.isclose(x[:, 1], 0.0)
    with pytest.raises(ValueError, match="selects no particle"):
        sim.add_boundary(fm.ParticleLayer(fm.Viscous(bot), region=lambda x: x[:, 1] < -1, normal=(0, -1)))
    with pytest.raises(ValueError, match="normal"):
        fm.ParticleLayer(fm.Viscous(bot), region=bot, normal=(0, 0))
    with pytest.raises(TypeError, match="mesh facets only"):
        fm.ParticleLayer(fm.Robin(lambda u, v, n: -v, bot), region=bot, normal=(0, -1))
    with pytest.raises(ValueError, match="needs 'where'"):
        sim.add_boundary(fm.Viscous())
