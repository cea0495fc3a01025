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


def test_integrator_must_be_an_integrator(setup):
    grid, mat, pts = setup
    with pytest.raises(TypeError, match=r"'integrator' must be an integrator.*'MUSL'"):
        fm.Simulation(grid, pts, "MUSL", dt=1e-4)


def test_gravity_and_traction_dimension_mismatch(setup):
    grid, mat, pts = setup
    with pytest.raises(ValueError, match=r"'gravity' must be a finite vector of length 2"):
        fm.Simulation(grid, pts, fm.Explicit(), dt=1e-4, gravity=(0.0, 0.0, -9.81))
    sim = fm.Simulation(grid, pts, fm.Explicit(), dt=1e-4)
    with pytest.raises(ValueError, match=r"vector of length 2"):
        sim.add_traction(lambda x: np.isclose(x[:, 1], 1.0), (0.0, 0.0, -1.0))
        sim.run(steps=1)


@pytest.mark.parametrize("per_cell", [0, -1, 1.5])
def test_per_cell_not_a_positive_integer(setup, per_cell):
    grid, mat, _ = setup
    with pytest.raises(ValueError, match=f"'per_cell' must be a positive integer, got {per_cell}"):
        fm.Particles.fill(grid, mat, per_cell=per_cell)


def test_region_selecting_nothing(setup):
    grid, mat, _ = setup
    with pytest.raises(ValueError, match="region selects no particle"):
        fm.Particles.fill(grid, mat, region=lambda x: x[:, 0] > 2.0)


@pytest.mark.parametrize("t_end", [0.0, -1.0, float("nan")])
def test_t_end_not_after_current_time(setup, t_end):
    grid, mat, pts = setup
    sim = fm.Simulation(grid, pts, fm.Explicit(), dt=1e-4)
    with pytest.raises(ValueError, match="'t_end' is the end time, not a duration: it must be "
                                         "> the current time t = 0 s"):
        sim.run(t_end=t_end)


def test_t_end_is_an_end_time_after_a_stage(setup):
    """A later run (a stage) given a duration as t_end: the message gives the time reached and
    how to ask for a duration."""
    grid, mat, pts = setup
    sim = fm.Simulation(grid, pts, fm.Explicit(), dt=1e-4)
    sim.run(steps=3)
    with pytest.raises(ValueError, match=r"current time t = 0\.0003 s \(time runs on across "
                                         r"stages\), got 0\.0002; for a duration T pass "
                                         r"t_end=sim\.t \+ T"):
        sim.run(t_end=2e-4)


def test_misspelt_petsc_option_is_reported(setup):
    grid, mat, pts = setup
    with pytest.raises(ValueError, match=r"PETSc did not use \['ksp_tpye'\]"):
        fm.Simulation(grid, pts, fm.Newmark(petsc_options={"ksp_tpye": "cg"}), dt=1e-3)


def test_unwritable_output_path(setup):
    grid, mat, pts = setup
    sim = fm.Simulation(grid, pts, fm.Explicit(), dt=1e-4)
    with pytest.raises(ValueError, match=r"Output: 'path' '/proc/fenicsmpm/out' cannot be written"):
        sim.run(steps=1, output=fm.Output("/proc/fenicsmpm/out"))
    assert sim.step_count == 0


def test_courant_number_is_reported(setup):
    """Courant = dt c_p / h with c_p = sqrt(M / rho), M = 1.2e6 Pa, h = 0.25."""
    import io as _io
    from fenicsmpm.io import Progress
    grid, mat, pts = setup
    sim = fm.Simulation(grid, pts, fm.Newmark(), dt=5e-3)
    expected = 5e-3 * np.sqrt(1.2e6 / 1000.0) / 0.25
    assert np.isclose(sim.courant, expected, rtol=1e-12)
    sim.run(steps=1, progress=False)
    assert sim.stats["courant"] == sim.courant
    line = Progress(10, 1.0, None, stream=_io.StringIO(), note=f"Courant {sim.courant:.3g}").format(5, 0.5, 1.0)
    assert line.endswith(f"Courant {expected:.3g}")
