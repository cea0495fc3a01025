"""PETSc solver selection (options prefix, petsc_options, command line) and observers."""
import numpy as np
import pytest

import fenicsmpm as fm
from fenicsmpm.integrators.linear_system import _insert_command_line_options
from fenicsmpm.problems.elastic import vibrating_bar
from petsc4py import PETSc


def _ksp(sim):
    ksp = sim.integrator.system.ksp
    return ksp.getType(), ksp.getPC().getType()


def test_defaults_and_options_do_not_leak():
    """Newmark (dynamic) defaults to GMRES + block Jacobi, QuasiStatic to GMRES preconditioned
    by a lagged LU factorization (MUMPS on several ranks or from MUMPS_FROM_DOFS dofs on)."""
    sim, _ = vibrating_bar(fm.Newmark(petsc_options={"ksp_type": "cg", "pc_type": "jacobi"}))
    assert _ksp(sim) == ("cg", "jacobi")
    assert not sim.integrator.system.fallback, "options given: no switch to LU"
    sim2, _ = vibrating_bar(fm.Newmark())
    assert _ksp(sim2) == ("gmres", "bjacobi"), "petsc_options of one simulation leaked into the next"
    assert sim2.integrator.system.fallback
    sim3, _ = vibrating_bar(fm.QuasiStatic())
    assert _ksp(sim3) == ("gmres", "lu") and sim3.integrator.system.lagged
    sim3.run(steps=1)
    assert (sim3.integrator.system.ksp.getPC().getFactorSolverType() == "mumps") == \
        (fm_size() > 1), "a 1D bar's few dofs: PETSc's own LU serially"


def test_failed_iterative_default_switches_to_lu(monkeypatch, caplog):
    """When the default GMRES fails (here: unpreconditioned, limited to 1 iteration) the same system is solved
    again by LU, logged once, and LU stays, lagged as QuasiStatic's (the step's first
    factors kept for its further Newton iterations): the run equals an LU run to round-off."""
    from fenicsmpm.integrators import linear_system as ls
    monkeypatch.setitem(ls.ITERATIVE, "ksp_max_it", 1)
    monkeypatch.setitem(ls.ITERATIVE, "pc_type", "none")
    res = []
    for opts in (None, {"ksp_type": "preonly", "pc_type": "lu",
                        **({"pc_factor_mat_solver_type": "mumps"} if fm_size() > 1 else {})}):
        sim, _ = vibrating_bar(fm.Newmark(petsc_options=opts))
        with caplog.at_level("WARNING", logger="fenicsmpm"):
            sim.run(steps=5)
        res.append(np.concatenate(sim.comm.allgather(sim.particles.v[np.argsort(sim.particles.id)])))
        if opts is None:
            system = sim.integrator.system
            assert _ksp(sim)[1] == "lu" and not system.fallback and system.switched
            assert system.lagged and 1 <= system.factorizations <= sim.step_count, \
                (system.factorizations, sim.integrator.iterations)
            assert system.ksp.getTolerances()[0] == 1e-12       # LAGGED's, not ITERATIVE's
            assert system.ksp.getPCSide() == PETSc.PC.Side.RIGHT
            if sim.comm.rank == 0:
                assert sum("using the direct LU solver" in r.getMessage() for r in caplog.records) == 1
    assert np.max(np.abs(res[0] - res[1])) <= 1e-12 * np.max(np.abs(res[1]))


def fm_size():
    from mpi4py import MPI
    return MPI.COMM_WORLD.size


@pytest.mark.parametrize("mumps_from", [0, None])
def test_quasi_static_keeps_its_lu_factors(monkeypatch, mumps_from):
    """QuasiStatic's default KSP (the LU factors of a step's first tangent kept as GMRES's
    preconditioner for its further Newton iterations, LinearSystem._solve_lagged) factors
    fewer times than it solves (measured: 6 factorizations in 12 solves, serial) and gives
    the displacements of an LU solve at every Newton iteration to 1e-10 relative (measured
    8.9e-15), with the same Newton iterations: gravity ramped over 6 load steps on bench
    throughput's block, 24 x 24 cells, cpGIMP. mumps_from = 0: the default factors with MUMPS
    also serially (as from MUMPS_FROM_DOFS dofs on), the reference stays PETSc's own LU."""
    from fenicsmpm.bench import throughput as T
    from fenicsmpm.integrators import linear_system
    if mumps_from is not None:
        monkeypatch.setattr(linear_system, "MUMPS_FROM_DOFS", mumps_from)
    lu = {"ksp_type": "preonly", "pc_type": "lu",
          **({"pc_factor_mat_solver_type": "mumps"} if fm_size() > 1 else {})}
    res, newton = [], []
    for opts in (None, lu):
        spec = dict(name="qs", integrator="QuasiStatic", scheme="QuasiStatic", cells=24,
                    per_cell=2, steps=3, warmup=3, shape="auto",
                    **({"petsc_options": opts, "prefix": "test_lagged_"} if opts else {}))
        sim = T.build_scene(T.scene_config(spec))
        for _ in range(6):
            sim.step()
        system = sim.integrator.system
        assert system.lagged == (opts is None)
        if opts is None:
            assert (system.ksp.getPC().getFactorSolverType() == "mumps") == \
                (fm_size() > 1 or mumps_from == 0)
        if opts is None:
            assert 1 <= system.factorizations < sum(sim.integrator.iterations), \
                (system.factorizations, sim.integrator.iterations)
        newton.append(list(sim.integrator.iterations))
        # matched by initial position (ids follow the partition, which may differ between
        # the two meshes on several ranks); small: 1,760 particles
        p = sim.particles
        X = np.round(np.concatenate(sim.comm.allgather(p.x - p.u)), 9)
        u = np.concatenate(sim.comm.allgather(p.u))
        res.append(u[np.lexsort(X.T)])
    assert newton[0] == newton[1]
    assert np.max(np.abs(res[0] - res[1])) <= 1e-10 * np.max(np.abs(res[1]))


def test_failing_kept_factors_back_off(monkeypatch):
    """LinearSystem._solve_lagged when GMRES never converges with kept factors (a plastic
    tangent that changes at every Newton iteration): after a failure the rest of the step and
    the next 1, 2, 4, ... LAG_BACKOFF_MAX steps factor afresh at every solve, so the kept
    factors are tried in steps 1, 3, 6, 11, 20, 37, 54 of 60 (7 tries, 7 wasted GMRES runs);
    where they serve, every step after its first solve uses them."""
    from dolfinx import mesh
    from mpi4py import MPI
    from fenicsmpm.integrators import linear_system as ls
    grid = fm.Grid(mesh.create_rectangle(MPI.COMM_WORLD, [[0, 0], [1, 1]], [2, 2],
                                         mesh.CellType.quadrilateral))
    for serve in (False, True):
        system = ls.LinearSystem(grid)
        tried = []

        def once(fresh, tried=tried, serve=serve):
            tried.append(fresh)
            system.iterations = 1 if fresh or serve else ls.LAGGED["ksp_max_it"]
            return 1 if fresh or serve else -3         # -3: DIVERGED_ITS
        monkeypatch.setattr(system, "_lagged_once", once)
        tries = []
        for step in range(1, 61):
            system.new_step()
            n0 = len(tried)
            for _ in range(4):                         # 4 Newton solves a step
                assert system._solve_lagged() > 0
            if not all(tried[n0:]):
                tries.append(step)
                # fresh, kept (failing: the same solve again, fresh), fresh, fresh
                assert tried[n0:] == ([True, False, False, False] if serve else
                                      [True, False, True, True, True]), tried[n0:]
        assert tries == (list(range(1, 61)) if serve else [1, 3, 6, 11, 20, 37, 54]), tries
        system.destroy()


def test_command_line_options_reach_the_ksp():
    argv = ["--out", "dir", "-fenicsmpm_ksp_type", "gmres", "-fenicsmpm_ksp_rtol", "1e-11",
            "-fenicsmpm_pc_type", "jacobi"]
    _insert_command_line_options("fenicsmpm_", argv)
    try:
        sim, _ = vibrating_bar(fm.Newmark())
        assert _ksp(sim) == ("gmres", "jacobi")
        assert sim.integrator.system.ksp.getTolerances()[0] == pytest.approx(1e-11)
        assert not PETSc.Options().hasName("out"), "unrelated arguments must not enter PETSc"
    finally:
        for k in ("ksp_type", "ksp_rtol", "pc_type"):
            PETSc.Options().delValue("fenicsmpm_" + k)


def test_iterative_and_direct_give_the_same_step():
    """CG + Jacobi at a tight tolerance and the default GMRES reproduce the LU result to 1e-9
    after 10 steps."""
    res = []
    lu = {"ksp_type": "preonly", "pc_type": "lu", **({"pc_factor_mat_solver_type": "mumps"} if fm_size() > 1 else {})}
    for opts in (lu, {"ksp_type": "cg", "pc_type": "jacobi", "ksp_rtol": 1e-13}, None):
        sim, _ = vibrating_bar(fm.Newmark(petsc_options=opts))
        sim.run(steps=10)
        res.append(np.concatenate(sim.comm.allgather(sim.particles.v[np.argsort(sim.particles.id)])))
    assert np.max(np.abs(res[0] - res[1])) < 1e-9 * np.max(np.abs(res[0]))
    assert np.max(np.abs(res[0] - res[2])) < 1e-9 * np.max(np.abs(res[0]))


def test_observer_called_every_n_steps():
    sim, ex = vibrating_bar(fm.Explicit("MUSL"))
    seen = []
    sim.observe(lambda s: seen.append((s.step_count, s.energy()["kinetic"] + s.energy()["strain"])), every=5)
    sim.run(steps=20)
    assert [k for k, _ in seen] == [5, 10, 15, 20]
    assert all(abs(e / ex["energy"] - 1) < 0.02 for _, e in seen)
    with pytest.raises(ValueError, match="every"):
        sim.observe(lambda s: None, every=0)


def test_ksp_failure_names_step_time_and_reason():
    """CG limited to one iteration cannot reach rtol 1e-12: the KSP reports DIVERGED_MAX_IT and
    the error says at which step, time and Newton iteration."""
    opts = {"ksp_type": "cg", "pc_type": "none", "ksp_max_it": 1, "ksp_rtol": 1e-12}
    sim, _ = vibrating_bar(fm.Newmark(petsc_options=opts), n_cells=8)
    sim.run(steps=0)
    with pytest.raises(RuntimeError, match=r"step 0, t = 0, Newton iteration 0: KSP failed: "
                                           r"converged reason -3 \(DIVERGED_MAX_IT\) after 1 iterations"):
        sim.step()


@pytest.mark.skipif(fm_size() > 1, reason="PETSc's ILU is sequential (one rank)")
def test_user_ilu_does_not_inherit_the_lu_solver_type(monkeypatch):
    """The direct default's MUMPS (from MUMPS_FROM_DOFS dofs) applies to LU only: a user's
    ILU on a system that large solves with PETSc's ILU, and gives the displacements of the
    default solve to 1e-8 relative (GMRES to rtol 1e-12)."""
    from fenicsmpm.bench import throughput as T
    from fenicsmpm.integrators import linear_system
    monkeypatch.setattr(linear_system, "MUMPS_FROM_DOFS", 0)
    u = []
    for opts in (None, {"ksp_type": "gmres", "pc_type": "ilu", "ksp_rtol": 1e-12}):
        spec = dict(name="ilu", integrator="QuasiStatic", scheme="QuasiStatic", cells=12,
                    per_cell=2, steps=1, warmup=0, shape=None,
                    **({"petsc_options": opts, "prefix": "test_ilu_"} if opts else {}))
        sim = T.build_scene(T.scene_config(spec))
        sim.step()
        pc = sim.integrator.system.ksp.getPC()
        assert (pc.getType(), pc.getFactorSolverType()) == \
            (("lu", "mumps") if opts is None else ("ilu", "petsc"))
        u.append(sim.particles.u.copy())
    assert np.max(np.abs(u[0] - u[1])) <= 1e-8 * np.max(np.abs(u[0]))


def test_factor_options_reach_mumps_and_keep_the_lagged_default():
    """Options of the factored matrix (linear_system.FACTOR_OPTIONS, e.g. MUMPS's workspace
    mat_mumps_icntl_14) are read when PETSc factors, not by KSPSetFromOptions: they reach
    MUMPS, ask for it on a system below MUMPS_FROM_DOFS, and leave the lagged default on; the
    run matches the default one to 1e-10 relative. A misspelt one raises, naming it."""
    from fenicsmpm.bench import throughput as T
    u = []
    for opts in (None, {"mat_mumps_icntl_14": 60}):
        spec = dict(name="factor", integrator="QuasiStatic", scheme="QuasiStatic", cells=24,
                    per_cell=2, steps=1, warmup=1, shape="auto",
                    **({"petsc_options": opts, "prefix": "test_factor_"} if opts else {}))
        sim = T.build_scene(T.scene_config(spec))
        sim.step()
        system = sim.integrator.system
        assert system.lagged
        if opts:
            pc = system.ksp.getPC()
            assert pc.getFactorSolverType() == "mumps"
            assert pc.getFactorMatrix().getMumpsIcntl(14) == 60
            assert not PETSc.Options().hasName("test_factor_mat_mumps_icntl_14"), "leaked"
        p = sim.particles
        X = np.round(np.concatenate(sim.comm.allgather(p.x - p.u)), 9)
        u.append(np.concatenate(sim.comm.allgather(p.u))[np.lexsort(X.T)])
    assert np.max(np.abs(u[0] - u[1])) <= 1e-10 * np.max(np.abs(u[0]))
    spec = dict(name="factor", integrator="QuasiStatic", scheme="QuasiStatic", cells=24,
                per_cell=2, steps=1, warmup=1, shape="auto",
                petsc_options={"mat_mumps_icntl_14x": 60}, prefix="test_factor_bad_")
    sim = T.build_scene(T.scene_config(spec))
    with pytest.raises(ValueError, match="mat_mumps_icntl_14x"):
        sim.step()
