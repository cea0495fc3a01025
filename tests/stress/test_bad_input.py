"""Bad-input sweep (issue 20): malformed calls across the whole public API.

Each case is one call with one thing wrong (under MPI every rank makes the same call, so
counts in messages are per rank times the number of ranks). It must raise the named exception type (a
fenicsmpm exception or a built-in one) with a message that names the parameter (the regular
expression), on every rank (serial and under `mpirun -n 2`: every rank passes the same input
and raises the same error), within CASE_TIMEOUT seconds (faulthandler ends the process with a
traceback otherwise: a hang is a failure, not a stuck CI job).

Areas: particles, materials, integrators, Simulation options, run, boundaries (Dirichlet,
absorbing, frictional, periodic), tractions and particle loads, probes, output, checkpoints,
stages, contact, base motion, energy monitor, observers, splitting, grids. A case that got
numpy's own message, a late error at run() or no error at all was fixed in the library."""
import faulthandler
import math
import os
import sys

import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenicsmpm as fm

CASE_TIMEOUT = 120.0          # s; the first traction form JIT-compiles it (a few s)
COMM = MPI.COMM_WORLD
_CTX = {}


def ctx():
    """A 4 x 4 quadrilateral grid on the unit square with an elastic material (built once)."""
    if not _CTX:
        msh = dmesh.create_rectangle(COMM, [[0.0, 0.0], [1.0, 1.0]], [4, 4],
                                     dmesh.CellType.quadrilateral)
        _CTX["grid"] = fm.Grid(msh)
        _CTX["mat"] = fm.LinearElastic(E=1e6, nu=0.25, density=1000.0)
    return _CTX


def grid():
    return ctx()["grid"]


def mat():
    return ctx()["mat"]


def particles(**kw):
    return fm.Particles.fill(grid(), mat(), per_cell=2, **kw)


def sim(integrator=None, **kw):
    """A fresh simulation on the shared grid (explicit MUSL, dt = 1e-3 unless given)."""
    kw.setdefault("dt", 1e-3)
    return fm.Simulation(grid(), particles(), integrator or fm.Explicit(), **kw)


def top(x):
    return np.isclose(x[:, 1], 1.0)


def bottom(x):
    return np.isclose(x[:, 1], 0.0)


def nowhere(x):
    return x[:, 0] > 5.0


def from_points(x, volume=0.01, **kw):
    return fm.Particles.from_points(grid(), mat(), x, volume, **kw)


def shared_dir(name):
    """A path in a directory shared by all ranks (made by rank 0)."""
    import tempfile
    path = tempfile.mkdtemp(prefix="fenicsmpm_bad_") if COMM.rank == 0 else None
    return os.path.join(COMM.bcast(path, root=0), name)


def traction_nan_at_run():
    s = sim()
    s.add_traction(top, lambda t: (0.0, -1e3 if t < 2.5e-3 else math.nan))
    s.run(steps=5)


def too_fast():
    p = fm.Particles.fill(grid(), mat(), per_cell=2, velocity=(400.0, 0.0))
    fm.Simulation(grid(), p, fm.Explicit(), dt=1e-3).run(steps=1)


def restart_with_bad_build():
    s = sim()
    path = shared_dir("ck")
    s.checkpoint(path)
    fm.Simulation.restart(path, lambda: "not a simulation")


def other_grid_particles():
    msh = dmesh.create_rectangle(COMM, [[0.0, 0.0], [1.0, 1.0]], [2, 2],
                                 dmesh.CellType.quadrilateral)
    p = fm.Particles.fill(fm.Grid(msh), mat(), per_cell=1)
    fm.Simulation(grid(), p, fm.Explicit(), dt=1e-3)


def add_other_grid_particles():
    msh = dmesh.create_rectangle(COMM, [[0.0, 0.0], [1.0, 1.0]], [2, 2],
                                 dmesh.CellType.quadrilateral)
    particles() + fm.Particles.fill(fm.Grid(msh), mat(), per_cell=1)


def penalty_without_polyline():
    p = particles()
    fm.set_body(p, 1, lambda x: x[:, 1] > 0.5)
    s = fm.Simulation(grid(), p, fm.ExplicitContact(algorithm="penalty",
                                                    penalty=dict(k_n=1e6)), dt=1e-3)
    s.run(steps=1)


SAND = dict(phi_c=30.0, h_s=5.8e9, n=0.28, e_d0=0.53, e_c0=0.84, e_i0=1.0, alpha=0.13,
            beta=1.0, m_R=10.0, m_T=2.0, R=5e-5, beta_r=0.3, chi=1.0, density=2600.0,
            e_0=0.65, p_t=1600.0)
MOTION = (np.linspace(0.0, 1.0, 11), np.sin(np.linspace(0.0, 1.0, 11)))

# (id, call, exception type, regular expression the message must match)
CASES = [
    # ---- particles
    ("from_points-ragged", lambda: from_points([[0.1, 0.2], [0.3]]), ValueError,
     r"Particles.from_points: 'x' must be an array of points of shape \(n, 2\), got a ragged"),
    ("from_points-3-columns", lambda: from_points(np.full((3, 3), 0.5)), ValueError,
     r"'x' must have shape \(n, 2\), got \(3, 3\)"),
    ("from_points-1d", lambda: from_points([0.1, 0.2, 0.3]), ValueError,
     r"'x' must have shape \(n, 2\), got \(3,\)"),
    ("from_points-strings", lambda: from_points([["a", "b"]]), ValueError, r"'x' must be"),
    ("from_points-nan", lambda: from_points([[0.5, 0.5], [math.nan, 0.5]]), ValueError,
     rf"'x' must be finite, got {COMM.size} point\(s\) with NaN or inf coordinates"),
    ("from_points-inf", lambda: from_points([[math.inf, 0.5]]), ValueError,
     r"'x' must be finite"),
    ("from_points-outside", lambda: from_points([[0.5, 0.5], [2.0, 0.5]]), ValueError,
     rf"{COMM.size} point\(s\) lie outside the mesh, first at x = \(2.0, 0.5\)"),
    ("from_points-volume-size", lambda: from_points(np.full((3, 2), 0.5), [0.1, 0.1]),
     ValueError, r"'volume' must be a number or an array of one volume per point, shape "
                 r"\(3,\), got \(2,\)"),
    ("from_points-volume-2d", lambda: from_points(np.full((2, 2), 0.5), np.ones((2, 2))),
     ValueError, r"'volume' must be a number or an array"),
    ("from_points-volume-negative", lambda: from_points([[0.5, 0.5]], -1.0), ValueError,
     r"'volume' must be finite and > 0, got -1.0"),
    ("from_points-volume-nan", lambda: from_points([[0.5, 0.5]], math.nan), ValueError,
     r"'volume' must be finite and > 0, got nan"),
    ("from_points-velocity-length", lambda: from_points([[0.5, 0.5]], velocity=(1, 2, 3)),
     ValueError, r"'velocity' must be a vector of length 2"),
    ("fill-per_cell-0", lambda: fm.Particles.fill(grid(), mat(), per_cell=0), ValueError,
     r"'per_cell' must be a positive integer, got 0"),
    ("fill-per_cell-float", lambda: fm.Particles.fill(grid(), mat(), per_cell=1.5),
     ValueError, r"'per_cell' must be a positive integer, got 1.5"),
    ("fill-region-none", lambda: particles(region=nowhere), ValueError,
     r"the region selects no particle"),
    ("fill-region-shape", lambda: particles(region=lambda x: True), ValueError,
     r"'region\(x\)' must return one bool per point, shape \(\d+,\), got shape \(\)"),
    ("fill-velocity-nan", lambda: particles(velocity=(math.nan, 0.0)), ValueError,
     r"'velocity' must be finite"),
    ("fill-velocity-callable-shape", lambda: particles(velocity=lambda x: x[:, :1]),
     ValueError, r"'velocity' must be a vector of length 2 or a function velocity\(x\)"),
    ("fill-material", lambda: fm.Particles.fill(grid(), {"E": 1e6}, per_cell=1), TypeError,
     r"'material' must be a fenicsmpm material, got dict"),
    ("add-other-grid", add_other_grid_particles, ValueError, r"different grids"),
    # ---- materials
    ("LinearElastic-E", lambda: fm.LinearElastic(E=0.0, nu=0.3, density=1.0), ValueError,
     r"LinearElastic: parameter 'E' must be > 0"),
    ("LinearElastic-E-string", lambda: fm.LinearElastic(E="soft", nu=0.3, density=1.0),
     (TypeError, ValueError), r"'E'"),
    ("NeoHookean-density", lambda: fm.NeoHookean(E=1e6, nu=0.3, density=-1.0), ValueError,
     r"NeoHookean: parameter 'density' must be > 0"),
    ("Hencky-nu", lambda: fm.Hencky(E=1e6, nu=0.6, density=1.0), ValueError,
     r"Hencky: parameter 'nu'"),
    ("MohrCoulomb-phi", lambda: fm.MohrCoulomb(E=1e6, nu=0.3, density=1.0, phi=-5.0, c=0.0),
     ValueError, r"MohrCoulomb: parameter 'phi'"),
    ("MohrCoulomb-c", lambda: fm.MohrCoulomb(E=1e6, nu=0.3, density=1.0, phi=30.0, c=-1.0),
     ValueError, r"MohrCoulomb: parameter 'c'"),
    ("MohrCoulomb-psi", lambda: fm.MohrCoulomb(E=1e6, nu=0.3, density=1.0, phi=30.0, c=0.0,
                                               psi=40.0), ValueError, r"MohrCoulomb: parameter 'psi'"),
    ("VonMises-c_u", lambda: fm.VonMises(E=1e6, nu=0.3, density=1.0, c_u=0.0), ValueError,
     r"VonMises: parameter 'c_u'"),
    ("Hypoplastic-phi_c", lambda: fm.Hypoplastic(**{**SAND, "phi_c": 0.0}), ValueError,
     r"Hypoplastic: .*'phi_c'"),
    ("Hypoplastic-e_d0", lambda: fm.Hypoplastic(**{**SAND, "e_d0": 0.9}), ValueError,
     r"Hypoplastic: parameter 'e_c0' must satisfy e_d0 < e_c0 < e_i0 \(e_d0 = 0.9\)"),
    ("Hypoplastic-missing", lambda: fm.Hypoplastic(phi_c=30.0), TypeError, r"'h_s'"),
    # ---- integrators
    ("Explicit-scheme", lambda: fm.Explicit("XYZ"), ValueError,
     r"Explicit: 'scheme' must be one of \('USF', 'USL', 'MUSL', 'AVG'\), got 'XYZ'"),
    ("Explicit-flip", lambda: fm.Explicit(flip=1.5), ValueError,
     r"Explicit: 'flip' must be in \[0, 1\], got 1.5"),
    ("Newmark-gamma", lambda: fm.Newmark(gamma=0.4), ValueError,
     r"Newmark: 'gamma' must be in \[1/2, 1\] .*got 0.4"),
    ("Newmark-beta", lambda: fm.Newmark(beta=0.0), ValueError,
     r"Newmark: 'beta' must be in \(0, 1/2\], got 0.0"),
    ("Newmark-rtol", lambda: fm.Newmark(rtol=-1.0), ValueError,
     r"Newmark: 'rtol' must be > 0, got -1.0"),
    ("Newmark-max_iter", lambda: fm.Newmark(max_iter=0), ValueError,
     r"Newmark: 'max_iter' must be a positive integer, got 0"),
    ("Newmark-flip", lambda: fm.Newmark(flip=2.0), ValueError,
     r"Newmark: 'flip' must be in \[0, 1\], got 2.0"),
    ("Newmark-petsc_options", lambda: fm.Newmark(petsc_options="-ksp_type cg"), TypeError,
     r"Newmark: 'petsc_options' must be a dict"),
    ("QuasiStatic-load_steps", lambda: fm.QuasiStatic(load_steps=0), ValueError,
     r"QuasiStatic: 'load_steps' must be a positive integer, got 0"),
    ("ExplicitGeneralizedAlpha-rho_b", lambda: fm.ExplicitGeneralizedAlpha(rho_b=1.5),
     ValueError, r"ExplicitGeneralizedAlpha: 'rho_b'"),
    ("ImplicitGeneralizedAlpha-rho_inf", lambda: fm.ImplicitGeneralizedAlpha(rho_inf=-0.1),
     ValueError, r"ImplicitGeneralizedAlpha: 'rho_inf'"),
    ("ExplicitContact-mu", lambda: fm.ExplicitContact(mu=-0.1), ValueError,
     r"ExplicitContact: 'mu' \(friction coefficients, and 'mu_default'\) must be finite "
     r"numbers >= 0, got -0.1"),
    ("ExplicitContact-algorithm", lambda: fm.ExplicitContact(algorithm="magic"), ValueError,
     r"ExplicitContact: 'algorithm' must be one of"),
    # ---- Simulation options
    ("Simulation-dt-string", lambda: sim(dt="fast"), ValueError,
     r"Simulation: 'dt' must be a positive number or 'auto', got 'fast'"),
    ("Simulation-dt-nan", lambda: sim(dt=math.nan), ValueError,
     r"Simulation: 'dt' must be > 0, got nan"),
    ("Simulation-dt-auto-implicit", lambda: sim(fm.Newmark(), dt="auto"), ValueError,
     r"dt='auto' is only defined for explicit integrators"),
    ("Simulation-dt-critical", lambda: sim(dt=1.0), ValueError,
     r"dt = 1 exceeds the explicit critical time step"),
    ("Simulation-gravity", lambda: sim(gravity=(0.0, 0.0, -9.81)), ValueError,
     r"Simulation: 'gravity' must be a finite vector of length 2"),
    ("Simulation-cfl", lambda: sim(dt="auto", cfl=0.0), ValueError,
     r"Simulation: 'cfl' must be in \(0, 1\], got 0.0"),
    ("Simulation-on_leave", lambda: sim(on_leave="ignore"), ValueError,
     r"Simulation: 'on_leave' must be one of"),
    ("Simulation-shape", lambda: sim(shape="bspline"), ValueError,
     r"Simulation: 'shape' must be one of"),
    ("Simulation-mass_tolerance", lambda: sim(mass_tolerance=2.0), ValueError,
     r"Simulation: 'mass_tolerance' must be a number in \(0, 1\), got 2.0"),
    ("Simulation-max_dt_cuts", lambda: sim(max_dt_cuts=-1), ValueError,
     r"Simulation: 'max_dt_cuts' must be an integer in \[0, 20\], got -1"),
    ("Simulation-stress_feedback", lambda: sim(stress_feedback="yes"), ValueError,
     r"Simulation: 'stress_feedback' must be None or 'smoothed'"),
    ("Simulation-gravity_ramp", lambda: sim(gravity_ramp=-1.0), ValueError,
     r"Simulation: 'gravity_ramp' must be a time > 0 or None"),
    ("Simulation-force_integration", lambda: sim(force_integration="gauss"), ValueError,
     r"Simulation: 'force_integration' must be one of"),
    ("Simulation-integrator", lambda: fm.Simulation(grid(), particles(), None, dt=1e-3),
     TypeError, r"Simulation: 'integrator' must be an integrator"),
    ("Simulation-particles-grid", other_grid_particles, ValueError,
     r"Simulation: 'particles' were created on a different grid"),
    # ---- run
    ("run-nothing", lambda: sim().run(), ValueError,
     r"run: give exactly one of 't_end' or 'steps'"),
    ("run-t_end-past", lambda: sim().run(t_end=-1.0), ValueError,
     r"run: 't_end' is the end time, not a duration: it must be > the current time t = 0 s "
     r"\(time runs on across stages\), got -1.0; for a duration T pass t_end=sim.t \+ T"),
    ("run-t_end-inf", lambda: sim().run(t_end=math.inf), ValueError, r"run: 't_end'"),
    ("run-steps-float", lambda: sim().run(steps=1.5), ValueError,
     r"run: 'steps' must be a non-negative integer, got 1.5"),
    ("run-checkpoint_every", lambda: sim().run(steps=1, checkpoint="ck"), ValueError,
     r"run: give both 'checkpoint' \(a directory\) and 'checkpoint_every'"),
    ("run-initial-velocity", too_fast, ValueError,
     r"the initial particle velocity \|v\| = 400 m/s exceeds the explicit stability limit "
     r"h / dt = 250 m/s"),
    # ---- boundaries
    ("fix-where", lambda: sim().fix("bottom"), TypeError, r"fix: 'where' must be callable"),
    ("fix-components", lambda: sim().fix(bottom, [2]), ValueError,
     r"fix: 'components' must be integers in \[0, 2\), got \[2\]"),
    ("fix-nowhere", lambda: sim().fix(nowhere), ValueError,
     r"fix: the Dirichlet locator 'where' matches no grid node"),
    ("release-components", lambda: sim().release(bottom, [5]), ValueError,
     r"'components' must be integers"),
    ("add_boundary-type", lambda: sim().add_boundary("viscous"), TypeError,
     r"add_boundary: expected fm.Robin, fm.Viscous or fm.Viscoelastic, got str"),
    ("Viscous-a", lambda: fm.Viscous(bottom, a=-1.0), ValueError, r"Viscous: 'a'"),
    ("Viscoelastic-spring", lambda: fm.Viscoelastic(bottom, r_b=1.0, spring="magic"),
     ValueError, r"Viscoelastic: 'spring'"),
    ("Viscous-nowhere", lambda: sim().add_boundary(fm.Viscous(nowhere)), ValueError,
     r"Viscous: the locator 'where' matches no boundary facet"),
    ("add_friction-mu", lambda: sim().add_friction(bottom, -0.2, (0.0, -1.0)), ValueError,
     r"'mu'"),
    ("add_friction-normal", lambda: sim().add_friction(bottom, 0.3, (0.0, -1.0, 0.0)),
     ValueError, r"'normal'"),
    ("add_friction-implicit", lambda: sim(fm.Newmark()).add_friction(bottom, 0.3),
     NotImplementedError, r"add_friction: frictional boundaries need fm.Explicit"),
    ("set_periodic-axis", lambda: sim().set_periodic(axis=5), ValueError, r"'axis'"),
    # ---- tractions and particle loads
    ("add_traction-length", lambda: sim().add_traction(top, (0.0, 1.0, 2.0)), ValueError,
     r"add_traction #0: 'value' must give a vector of length 2, got shape \(3,\)"),
    ("add_traction-nowhere", lambda: sim().add_traction(nowhere, (0.0, -1.0)), ValueError,
     r"add_traction #0: the locator 'where' matches no boundary facet"),
    ("add_traction-nan", lambda: sim().add_traction(top, (math.nan, 0.0)), ValueError,
     r"add_traction #0: 'value' gave the non-finite traction \[nan, 0.0\] at t = 0"),
    ("add_traction-string", lambda: sim().add_traction(top, "up"), TypeError,
     r"add_traction #0: 'value' must be a vector or a function t -> vector"),
    ("traction-nan-during-run", traction_nan_at_run, FloatingPointError,
     r"add_traction #0: 'value' gave the non-finite traction \[0.0, nan\] at t = 0.003"),
    ("add_particle_load-nowhere", lambda: sim().add_particle_load(nowhere, (0.0, -1.0)),
     ValueError, r"add_particle_load #0: 'region' selects no particle"),
    ("add_particle_load-value", lambda: sim().add_particle_load(top, (0.0,)), ValueError,
     r"add_particle_load #0: 'value' must give a vector of length 2"),
    # ---- probes
    ("probe-outside", lambda: sim().probe((2.0, 0.5)), ValueError,
     r"probe: 'point' \(2.0, 0.5\) lies outside the mesh"),
    ("probe-field", lambda: sim().probe((0.5, 0.5), ["temperature"]), ValueError,
     r"probe: unknown field\(s\) \['temperature'\]"),
    ("probe-point-length", lambda: sim().probe((0.5,)), ValueError,
     r"probe: 'point' must be 2 finite coordinates"),
    ("probe-point-nan", lambda: sim().probe((math.nan, 0.5)), ValueError,
     r"probe: 'point' must be 2 finite coordinates"),
    ("probe-every", lambda: sim().probe((0.5, 0.5), every=0), ValueError,
     r"probe: 'every' must be a positive integer, got 0"),
    # ---- output
    ("Output-every", lambda: fm.Output("out", every=0), ValueError,
     r"Output: 'every' must be a positive integer, got 0"),
    ("Output-path", lambda: sim().run(steps=1, output=fm.Output("/proc/forbidden")),
     ValueError, r"Output: 'path' '/proc/forbidden' cannot be written"),
    ("Output-fields", lambda: sim().run(steps=1, output=fm.Output(
        shared_dir("out"), particle_fields=("v", "colour"))), ValueError,
     r"Output: 'particle_fields' \['colour'\] are not particle fields"),
    ("Output-fields-string", lambda: fm.Output("out", particle_fields="v"), TypeError,
     r"Output: 'particle_fields' must be a sequence of field names"),
    # ---- checkpoints
    ("restore-missing", lambda: sim().restore("/nonexistent/ck"), fm.CheckpointNotFoundError,
     r"restore: no checkpoint in '/nonexistent/ck' \(missing /nonexistent/ck/LATEST\)"),
    ("checkpoint-keep", lambda: sim().checkpoint(shared_dir("ck"), keep=0), ValueError,
     r"checkpoint: 'keep' must be a positive integer, got 0"),
    ("restart-build", restart_with_bad_build, TypeError,
     r"restart: 'build' must return a Simulation, got str"),
    # ---- stages
    ("start_stage-gravity", lambda: sim().start_stage(gravity=(0.0,)), ValueError,
     r"start_stage: 'gravity' must be a finite vector of length 2"),
    ("start_stage-dt", lambda: sim().start_stage(dt=-1.0), ValueError,
     r"'dt' must be > 0, got -1.0"),
    ("start_stage-gravity_ramp", lambda: sim().start_stage(gravity_ramp=0.0), ValueError,
     r"start_stage: 'gravity_ramp' must be a time > 0 or None"),
    ("start_stage-integrator", lambda: sim().start_stage(integrator="Newmark"), TypeError,
     r"start_stage: 'integrator' must be an integrator"),
    # ---- contact
    ("set_body-id", lambda: fm.set_body(particles(), -1), ValueError,
     r"set_body: 'body_id' must be an integer >= 0, got -1"),
    ("set_body-region", lambda: fm.set_body(particles(), 1, lambda x: True), ValueError,
     r"set_body: 'region\(x\)' must return one bool per particle"),
    ("RigidLoad-force", lambda: fm.RigidLoad((math.nan, 0.0)), ValueError,
     r"RigidLoad: 'force' must be a finite vector"),
    ("ExplicitContact-rigid", lambda: fm.ExplicitContact(rigid={0: "fast"}), (TypeError, ValueError),
     r"ExplicitContact: 'rigid'"),
    ("penalty-polyline", penalty_without_polyline, ValueError, r"polyline"),
    # ---- base motion
    ("InputMotion-lengths", lambda: fm.InputMotion([0.0, 1.0, 2.0], [0.0, 1.0]), ValueError,
     r"InputMotion: 'values' must have one value per time in 't', shape \(3,\), got shape "
     r"\(2,\)"),
    ("InputMotion-times", lambda: fm.InputMotion([0.0, 2.0, 1.0], [0.0, 1.0, 0.0]),
     ValueError, r"InputMotion: 't' must increase"),
    ("InputMotion-kind", lambda: fm.InputMotion(*MOTION, kind="jerk"), ValueError,
     r"InputMotion: 'kind' must be one of"),
    ("rigid_base-motion", lambda: fm.rigid_base(sim(), bottom, "shake"), TypeError,
     r"rigid_base: 'motion' must be an fm.InputMotion"),
    ("rigid_base-component", lambda: fm.rigid_base(sim(), bottom, fm.InputMotion(*MOTION),
                                                   component=3), ValueError,
     r"rigid_base: 'component' must be 0 or 1, got 3"),
    ("compliant_base-density", lambda: fm.compliant_base(sim(), bottom, fm.InputMotion(*MOTION),
                                                         -1.0, 100.0, 200.0), ValueError,
     r"'density'"),
    # ---- energy monitor, observers, splitting, grid
    ("monitor_energy-every", lambda: sim().monitor_energy(every=0), ValueError,
     r"monitor_energy: 'every' must be a positive integer, got 0"),
    ("monitor_energy-tolerance", lambda: sim().monitor_energy(tolerance=-1.0), ValueError,
     r"monitor_energy: 'tolerance' must be > 0, got -1.0"),
    ("monitor_energy-integrator", lambda: sim(fm.QuasiStatic()).monitor_energy(), ValueError,
     r"monitor_energy: QuasiStatic does not record"),
    ("observe-callback", lambda: sim().observe("print"), TypeError,
     r"observe: 'callback' must be callable, got str"),
    ("enable_splitting-alpha", lambda: sim().enable_splitting(alpha=0.5), ValueError,
     r"enable_splitting: need alpha > 1 > beta, got alpha=0.5, beta=0.5"),
    ("Grid-mesh", lambda: fm.Grid("mesh.msh"), TypeError, r"Grid: 'mesh' must be a dolfinx"),
]


@pytest.fixture(autouse=True)
def case_timeout():
    """A hang ends the process with a traceback after CASE_TIMEOUT seconds."""
    faulthandler.dump_traceback_later(CASE_TIMEOUT, exit=True, file=sys.stderr)
    yield
    faulthandler.cancel_dump_traceback_later()


def test_sweep_size():
    assert len(CASES) >= 60 and len({c[0] for c in CASES}) == len(CASES)


@pytest.mark.parametrize("name,call,kind,pattern", CASES, ids=[c[0] for c in CASES])
def test_bad_input(name, call, kind, pattern):
    with pytest.raises(kind, match=pattern) as exc:
        call()
    assert "outside the mesh" not in str(exc.value) or "outside" in name
    # every rank raised the same error (a rank that did not would be stuck above, or here)
    everyone = COMM.allgather((type(exc.value).__name__, str(exc.value)))
    assert all(e[0] == everyone[0][0] for e in everyone), everyone
