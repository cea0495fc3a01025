"""Issue 20, the rough edges a new user hit: n_global() is an explicit collective, the form
compiler is quiet, explicit integrators fill the acceleration, fenicsmpm's exceptions are
exported, a probe outside the mesh raises and a probe says which particle it follows, a
missing checkpoint names its path, dt="auto" warns about millions of steps, a too fast initial
velocity is named. (The energy monitor's warmup is in test_energy_monitor.py.)"""
import os
import subprocess
import sys
import time
import warnings

import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenicsmpm as fm

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def block(n=4, cell=dmesh.CellType.quadrilateral, size=1.0, **mat):
    msh = dmesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [size, size]], [n, n], cell)
    grid = fm.Grid(msh)
    kw = dict(E=1e6, nu=0.25, density=1000.0)
    kw.update(mat)
    return grid, fm.LinearElastic(**kw)


def test_n_global_is_a_collective_method():
    grid, mat = block()
    p = fm.Particles.fill(grid, mat, per_cell=2)
    assert callable(p.n_global)
    assert p.n_global() == MPI.COMM_WORLD.allreduce(len(p)) == 64
    assert "collective" in fm.Particles.n_global.__doc__.lower()
    assert "if rank == 0" in fm.Particles.n_global.__doc__


COMPILE = """
import sys, time, logging
import fenicsmpm
if sys.argv[1] == "on":
    logging.getLogger("fenicsmpm.compiler").setLevel(logging.INFO)
import ufl
from mpi4py import MPI
from dolfinx import fem, mesh
msh = mesh.create_unit_square(MPI.COMM_SELF, 2, 2)
V = fem.FunctionSpace(msh, ("Lagrange", 1))
# a form no earlier run compiled (the literal is new), so FFCx calls the C compiler
k = float(sys.argv[2])
fem.form(ufl.sin(k * ufl.SpatialCoordinate(msh)[0]) * ufl.TestFunction(V) * ufl.ds)
print("compiled")
"""


@pytest.mark.parametrize("logging_on", [False, True], ids=["default", "opt-in"])
def test_form_compiler_output_is_silenced(logging_on):
    """Compiling a fresh form after `import fenicsmpm` prints nothing on stderr; the build's
    lines ("running build_ext", gcc) appear only when the user asks for them."""
    comm = MPI.COMM_WORLD
    out = None
    if comm.rank == 0:
        env = dict(os.environ)
        for k in list(env):                  # a plain serial child, not an MPI rank
            if k.startswith(("OMPI_", "PMIX_", "PMI_")):
                del env[k]
        literal = f"{time.time_ns() % 10**12 + 0.5}"
        r = subprocess.run([sys.executable, "-c", COMPILE, "on" if logging_on else "off",
                            literal], capture_output=True, text=True, timeout=300, env=env,
                           cwd=ROOT)
        out = (r.returncode, r.stdout, r.stderr)
    rc, stdout, stderr = comm.bcast(out, root=0)
    assert rc == 0 and "compiled" in stdout, stderr
    if logging_on:
        assert "running build_ext" in stderr and "gcc" in stderr
    else:
        assert stderr == "", stderr


@pytest.mark.parametrize("integrator", [fm.Explicit("MUSL"), fm.Explicit("USF", flip=0.5),
                                        fm.ExplicitContact("USL")],
                         ids=["MUSL", "USF-flip0.5", "contact-USL"])
def test_explicit_acceleration_probe(integrator):
    """A block in free fall (no supports): every particle accelerates at g, and the probe's
    acceleration column says so (it was always zero with explicit integrators)."""
    grid, mat = block()
    p = fm.Particles.fill(grid, mat, per_cell=2)
    sim = fm.Simulation(grid, p, integrator, dt="auto", gravity=(0.0, -9.81))
    probe = sim.probe((0.3, 0.6), ["acceleration", "velocity"])
    sim.run(steps=5)
    d = probe.data()
    assert np.allclose(d["acceleration_y"][1:], -9.81, rtol=1e-9), d["acceleration_y"]
    assert np.allclose(d["acceleration_x"][1:], 0.0, atol=1e-9)
    assert np.allclose(np.diff(d["velocity_y"]) / sim.dt, -9.81, rtol=1e-9)
    assert np.allclose(p.a[:, 1], -9.81, rtol=1e-9)


def test_generalized_alpha_acceleration_probe():
    """Explicit generalized-alpha (rho_b = 0.8, alpha_m = 1/3) carries its own particle
    acceleration: in free fall from a = 0 it approaches g as a^{n+1} - g = -(alpha_m /
    (1 - alpha_m)) (a^n - g), i.e. the error is g / 2 (-1/2)^(n-1) after step n."""
    grid, mat = block()
    p = fm.Particles.fill(grid, mat, per_cell=2)
    sim = fm.Simulation(grid, p, fm.ExplicitGeneralizedAlpha(0.8), dt="auto",
                        gravity=(0.0, -9.81))
    probe = sim.probe((0.3, 0.6), ["acceleration"])
    sim.run(steps=5)
    err = probe.data()["acceleration_y"][1:] + 9.81
    assert np.allclose(err, -9.81 / 2 * (-0.5) ** np.arange(5), rtol=1e-9), err


def test_exceptions_are_exported():
    from fenicsmpm import errors, guards
    assert fm.ParticlesLeftMesh is guards.ParticlesLeftMesh is errors.ParticlesLeftMesh
    assert issubclass(fm.ParticlesLeftMesh, RuntimeError)
    assert issubclass(fm.CheckpointNotFoundError, FileNotFoundError)
    for name in ("ParticlesLeftMesh", "CheckpointNotFoundError"):
        assert name in fm.__all__ and getattr(fm, name).__doc__


def test_particles_leaving_raise_the_exported_exception():
    grid, mat = block()
    p = fm.Particles.fill(grid, mat, per_cell=2, region=lambda x: x[:, 0] > 0.75,
                          velocity=(20.0, 0.0))
    sim = fm.Simulation(grid, p, fm.Explicit(), dt=0.005)
    with pytest.raises(fm.ParticlesLeftMesh, match=r"step 1, t = 0.005: 8 particle\(s\) left the mesh, ids \[.*\] at \[\[1.0375, ") as e:
        sim.run(steps=3)
    c = mat.p_wave_speed                        # 34.6 m/s: the block flowed out
    assert f"their largest speed 20 m/s, |stress| " in str(e.value)
    assert (f"(P-wave speed of the material's state c_p = {c:.4g} m/s). The material flowed "
            f"out of the mesh: extend the mesh, or pass on_leave='remove'") in str(e.value)


def test_particles_leaving_faster_than_the_wave_speed_are_named_a_blow_up():
    """Particles leaving faster than the material's P-wave speed were thrown out (issue 21:
    the guards name the blow-up, not only the particles that left)."""
    grid, mat = block()
    c = mat.p_wave_speed
    p = fm.Particles.fill(grid, mat, per_cell=2, region=lambda x: x[:, 0] > 0.75,
                          velocity=(2.0 * c, 0.0))
    sim = fm.Simulation(grid, p, fm.Explicit(), dt=0.001)
    with pytest.raises(fm.ParticlesLeftMesh, match=rf"their largest speed {2 * c:.4g} m/s.*"
                                                   r"Faster than c_p: unless the material was "
                                                   r"launched that fast, a blow-up threw them"):
        sim.run(steps=10)


def test_probe_outside_the_mesh_raises():
    grid, mat = block()
    p = fm.Particles.fill(grid, mat, per_cell=2)
    sim = fm.Simulation(grid, p, fm.Explicit(), dt="auto")
    with pytest.raises(ValueError, match=r"probe: 'point' \(1.5, 0.5\) lies outside the mesh"):
        sim.probe((1.5, 0.5), ["velocity"])


def test_probe_reports_its_particle_and_ties():
    """Particles of a 4 x 4 grid with 2 per cell sit at 1/16 + k/8. A point at a particle
    follows it (no tie); a point on the cell face x = 0.5 is equally far from two particle
    columns: the smallest id is chosen and the tie is reported."""
    grid, mat = block()
    p = fm.Particles.fill(grid, mat, per_cell=2)
    sim = fm.Simulation(grid, p, fm.Explicit(), dt="auto")
    pr = sim.probe((0.3125, 0.6875), ["velocity"])
    assert pr.particle_x0 == pytest.approx((0.3125, 0.6875)) and pr.ties == 0
    assert pr.distance == pytest.approx(0.0, abs=1e-12)
    assert str(pr) == (f"probe at (0.3125, 0.6875): particle {pr.particle_id}, initial "
                       f"position (0.3125, 0.6875), distance 0")
    face = sim.probe((0.5, 0.6875), ["velocity"])
    assert face.ties == 1 and face.distance == pytest.approx(0.0625)
    ids = MPI.COMM_WORLD.allgather([(int(i), tuple(x)) for i, x in zip(p.id, p.x)])
    at = {i: x for part in ids for i, x in part}
    pair = sorted(i for i, x in at.items() if np.allclose(x, (0.4375, 0.6875))
                  or np.allclose(x, (0.5625, 0.6875)))
    assert face.particle_id == pair[0]
    assert "1 other particle(s) at the same distance, the smallest id chosen" in str(face)


def test_missing_checkpoint_names_the_path(shared_tmp_path):
    grid, mat = block()
    p = fm.Particles.fill(grid, mat, per_cell=2)
    sim = fm.Simulation(grid, p, fm.Explicit(), dt="auto")
    missing = os.path.join(shared_tmp_path, "nowhere")
    with pytest.raises(fm.CheckpointNotFoundError,
                       match=f"no checkpoint in '{missing}' \\(missing {missing}/LATEST\\)"):
        sim.restore(missing)
    with pytest.raises(FileNotFoundError):             # still a FileNotFoundError
        fm.Simulation.restart(missing, lambda: sim)


def test_dt_auto_warns_about_millions_of_steps():
    """Steel (c_p = 6001 m/s) on a grid of h = 0.25 m: dt = cfl h / c_p = 2.08e-5 s, so 30 s
    of simulated time is 1.44 million steps: run() warns first, naming the count and the
    material that limits dt (the check run() does before its first step)."""
    grid, mat = block(E=210e9, nu=0.3, density=7850.0)
    p = fm.Particles.fill(grid, mat, per_cell=1)
    sim = fm.Simulation(grid, p, fm.Explicit(), dt="auto")
    steps = int(np.ceil(30.0 / sim.dt - 1e-9))
    assert steps == 1_440_236, steps
    pattern = (r"run: dt='auto' gives 1,440,236 steps of dt = 2.08e-05 s; the limit cfl \* h "
               r"/ c_p comes from LinearElastic \(material 0, c_p = 6001 m/s, h = 0.25\)")
    if MPI.COMM_WORLD.rank == 0:
        with pytest.warns(RuntimeWarning, match=pattern):
            sim._check_run(steps)
    else:
        sim._check_run(steps)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        sim.run(steps=2)                                     # few steps: no warning


def test_initial_velocity_beyond_the_stability_limit():
    """h = 0.25, dt = 1e-3: a particle at 300 m/s would cross 1.2 cells per step."""
    grid, mat = block()
    p = fm.Particles.fill(grid, mat, per_cell=2, velocity=(300.0, 0.0))
    sim = fm.Simulation(grid, p, fm.Explicit(), dt=1e-3)
    with pytest.raises(ValueError, match=r"the initial particle velocity \|v\| = 300 m/s "
                                         r"exceeds the explicit stability limit h / dt = 250 m/s"):
        sim.run(steps=1)
    assert sim.step_count == 0
