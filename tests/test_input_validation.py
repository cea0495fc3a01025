"""Invalid input raises a clear ValueError that names the parameter (and the value given).

Every case raises on all ranks (the checks are either local and identical on every rank,
or collective), so the tests are safe under mpirun."""
import re

import numpy as np
import pytest
from dolfinx import mesh as dmesh

import fenicsmpm as fm

CT = dmesh.CellType


@pytest.fixture(scope="module")
def setup():
    from mpi4py import MPI
    msh = dmesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [1.0, 1.0]], [4, 4],
                                 CT.quadrilateral)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=1e6, nu=0.25, density=1000.0)
    pts = fm.Particles.fill(grid, mat, per_cell=2)
    return grid, mat, pts


@pytest.mark.parametrize("cls", [fm.LinearElastic, fm.NeoHookean], ids=lambda c: c.__name__)
@pytest.mark.parametrize("kwargs,pattern", [
    (dict(E=0.0, nu=0.3, density=1.0), r"'E'.*> 0.*0\.0"),
    (dict(E=-5.0, nu=0.3, density=1.0), r"'E'.*> 0.*-5\.0"),
    (dict(E=1.0, nu=0.5, density=1.0), r"'nu'.*-1\.0 < nu < 0\.5.*0\.5"),
    (dict(E=1.0, nu=0.7, density=1.0), r"'nu'.*0\.7"),
    (dict(E=1.0, nu=-1.0, density=1.0), r"'nu'.*-1\.0"),
    (dict(E=1.0, nu=-1.5, density=1.0), r"'nu'.*-1\.5"),
    (dict(E=1.0, nu=0.3, density=0.0), r"'density'.*> 0.*0\.0"),
    (dict(E=1.0, nu=0.3, density=-2.0), r"'density'.*> 0.*-2\.0"),
])
def test_material_parameters(cls, kwargs, pattern):
    with pytest.raises(ValueError, match=pattern) as exc:
        cls(**kwargs)
    assert cls.__name__ in str(exc.value), f"message does not name the class: {exc.value}"


@pytest.mark.parametrize("dt", [0.0, -1e-3])
def test_dt_not_positive(setup, dt):
    grid, _, pts = setup
    with pytest.raises(ValueError, match=rf"'dt' must be > 0, got {re.escape(repr(dt))}"):
        fm.Simulation(grid, pts, fm.Explicit("MUSL"), dt=dt)


def test_dt_not_positive_implicit(setup):
    grid, _, pts = setup
    with pytest.raises(ValueError, match=r"'dt' must be > 0, got -1\.0"):
        fm.Simulation(grid, pts, fm.Newmark(), dt=-1.0)


def test_explicit_dt_above_critical(setup):
    """The critical step is h / c_p = 0.25 / sqrt(M / rho) with M = 1.2e6 Pa (nu = 0.25)."""
    grid, mat, pts = setup
    dt_crit = 0.25 / np.sqrt(mat.constrained_modulus / mat.density)
    assert abs(dt_crit - 0.25 / np.sqrt(1.2e6 / 1000.0)) < 1e-15
    limit = re.escape(f"{dt_crit:.4g}")
    with pytest.raises(ValueError, match=rf"'?dt'?.*critical.*{limit}"):
        fm.Simulation(grid, pts, fm.Explicit("USF"), dt=1.01 * dt_crit)
    # just below the limit is accepted
    sim = fm.Simulation(grid, pts, fm.Explicit("USF"), dt=0.99 * dt_crit)
    assert abs(sim.dt_critical - dt_crit) < 1e-12 * dt_crit, (
        f"dt_critical = {sim.dt_critical!r}, expected h / c_p = {dt_crit!r}")


def test_particles_outside_mesh(setup):
    grid, mat, _ = setup
    x = np.array([[1.25, 0.5], [0.5, 0.5]])
    with pytest.raises(ValueError, match=r"outside the mesh.*1\.25, 0\.5"):
        fm.Particles.from_points(grid, mat, x, volume=0.01)


def test_dirichlet_locator_matches_nothing(setup):
    grid, _, pts = setup
    sim = fm.Simulation(grid, pts, fm.Explicit("MUSL"), dt="auto")
    with pytest.raises(ValueError, match=r"'where' matches no grid node"):
        sim.fix(lambda x: np.isclose(x[:, 0], 7.0), [0])


def test_unsupported_cell_type(comm):
    msh = dmesh.create_interval(comm, 4, [0.0, 1.0])
    with pytest.raises(ValueError, match=r"unsupported cell type 'interval'"):
        fm.Grid(msh)
