"""Checkpoint and restart (issue 6): a restarted run reproduces the continuous one bit for bit
(explicit, same rank count), to round-off for implicit and on another rank count; a run killed
between checkpoints leaves the previous one usable; failures write the last accepted state."""
import os

import numpy as np
import pytest
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.problems.absorbing_column import absorbing_column
from fenicsmpm.problems.elastic import colliding_discs, vibrating_bar
from fenicsmpm.partition import strips

WORLD = MPI.COMM_WORLD


def _state(sim):
    p = sim.particles
    return {f: getattr(p, f).copy() for f in ("x", "v", "a", "u", "stress", "F", "V", "id")}


def _same(a, b, exact=True, rtol=1e-12):
    for f in a:
        if exact:
            assert np.array_equal(a[f], b[f]), f"field {f} differs after restart"
        else:
            scale = max(np.max(np.abs(a[f])), 1e-300)
            assert np.max(np.abs(a[f] - b[f])) <= rtol * scale, f"field {f} differs after restart"


def _restart_matches(build, n1, n2, path, exact=True, rtol=1e-12):
    ref = build()
    ref.run(steps=n1 + n2)
    first = build()
    first.run(steps=n1, checkpoint=path, checkpoint_every=n1)
    again = fm.Simulation.restart(path, build)
    assert again.step_count == n1 and again.t == first.t
    again.run(steps=n2)
    assert again.t == ref.t and again.step_count == ref.step_count
    _same(_state(ref), _state(again), exact, rtol)
    return ref, again


def test_explicit_bar_restart_is_bit_for_bit(shared_tmp_path):
    build = lambda: vibrating_bar(fm.Explicit("MUSL"), n_cells=16, partitioner=strips(18, 1))[0]
    _restart_matches(build, 30, 30, os.path.join(shared_tmp_path, "ck"))


def test_restart_with_migration_and_probe_is_bit_for_bit(shared_tmp_path):
    """Discs crossing rank boundaries (strip partition under MPI); the probe's records before
    the checkpoint survive the restart."""
    def build():
        sim, _ = colliding_discs(fm.Explicit("USL"), n_cells=12, cfl=0.3, speed=0.2,
                                 partitioner=strips(12, 12))
        sim.probe((0.3, 0.3), fields=("velocity", "stress"))
        return sim
    ref, again = _restart_matches(build, 25, 25, os.path.join(shared_tmp_path, "ck"))
    a, b = ref.probes[0].data(), again.probes[0].data()
    assert len(a["t"]) == 51 and all(np.array_equal(a[c], b[c]) for c in a)


def test_absorbing_boundary_restart_is_bit_for_bit(shared_tmp_path):
    """W1 column with a viscoelastic base: the boundary springs' reference displacements are
    part of the checkpoint."""
    build = lambda: absorbing_column(fm.Explicit("MUSL"), base="viscoelastic", dx=2.0,
                                     height=40.0, partitioner=strips(1, 20, axis=1))[0]
    _restart_matches(build, 40, 40, os.path.join(shared_tmp_path, "ck"))


def _block_on_incline(contact):
    """An elastic block (two bodies side by side with `contact`) on a frictional base,
    gravity tilted 25 degrees, mu = 0.3 < tan 25: it slides, its base nodes in contact and
    slipping (status 1), the others free."""
    from dolfinx import mesh as dmesh
    msh = dmesh.create_rectangle(WORLD, [[0.0, 0.0], [3.0, 1.0]], [24, 8],
                                 dmesh.CellType.quadrilateral, partitioner=strips(24, 8))
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, fm.LinearElastic(E=1e6, nu=0.3, density=1000.0),
                          region=lambda x: (np.abs(x[:, 0] - 1.0) < 0.5) & (x[:, 1] < 0.5))
    integ = fm.Explicit()
    if contact:
        fm.set_body(p, 1, region=lambda x: x[:, 0] > 1.0)
        integ = fm.ExplicitContact("AVG", mu=0.5)   # its first half step holds the base
    g = 9.81
    sim = fm.Simulation(grid, p, integ, dt="auto", shape="mpm",
                        gravity=(g * np.sin(np.radians(25.0)), -g * np.cos(np.radians(25.0))))
    sim.add_friction(lambda x: np.isclose(x[:, 1], 0.0), mu=0.3, normal=(0.0, -1.0))
    return sim


@pytest.mark.parametrize("contact", [False, True], ids=["one-body", "contact"])
def test_frictional_base_restart_is_bit_for_bit(shared_tmp_path, contact):
    """The base's contact status (stuck / slipping / free per node and body) is part of the
    checkpoint: the first step after a restart starts from it as the continuous run does
    (fm.Explicit holds the start-of-step velocities with it; fm.ExplicitContact with USF/AVG
    the first stress update's, one status per body). Without it a 3D Mohr-Coulomb collapse
    on a rough base restarted at 0.3 s ran out 2 mm further by 0.6 s."""
    ref, again = _restart_matches(lambda: _block_on_incline(contact), 40, 40,
                                  os.path.join(shared_tmp_path, f"ck{int(contact)}"))
    status = ref.frictions[0].body_status[0] if contact else ref.frictions[0].status
    assert WORLD.allreduce(int(np.count_nonzero(status == 1))) >= 4      # sliding nodes


def test_force_driven_rigid_body_restart_is_bit_for_bit(shared_tmp_path):
    """The velocity of a force-driven rigid body (fm.RigidLoad) is part of the checkpoint
    (before, a restart set it back to zero: the block pushed by 160 N stopped dead)."""
    from dolfinx import mesh as dmesh

    def build():
        msh = dmesh.create_rectangle(WORLD, [[0.0, 0.0], [2.4, 0.6]], [24, 6],
                                     dmesh.CellType.quadrilateral, partitioner=strips(24, 6))
        grid = fm.Grid(msh)
        box = lambda a, b: (lambda x: (x[:, 0] > a) & (x[:, 0] < b) & (x[:, 1] > 0.1)  # noqa: E731
                            & (x[:, 1] < 0.5))
        mat = lambda: fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)       # noqa: E731
        p = fm.Particles.fill(grid, mat(), region=box(0.8, 1.2)) + \
            fm.Particles.fill(grid, mat(), region=box(0.2, 0.6))      # body 1: the rigid one
        law = fm.RigidLoad((160.0, 0.0))
        return fm.Simulation(grid, p, fm.ExplicitContact("MUSL", mu=0.0, rigid={1: law}),
                             dt="auto")
    ref, again = _restart_matches(build, 40, 40, os.path.join(shared_tmp_path, "ck_rigid"))
    v_ref, v_again = ref.integrator.rigid[1].v, again.integrator.rigid[1].v
    assert v_ref[0] > 0.0 and np.array_equal(v_ref, v_again)


def test_compliant_base_restart_is_bit_for_bit(shared_tmp_path):
    """A compliant base's incident velocity v_in(t) is set for the restored time (before, the
    first step after a restart used the set-up's v_in(0): particle velocities 4e-4 of their
    largest off after 200 more steps of the site-response column)."""
    from fenicsmpm.problems import soil_column as sr
    ny = int(round(sr.H / 0.5))
    build = lambda: sr.soil_column(fm.Explicit(), h=0.5, base="compliant", t_end=3.0,  # noqa: E731
                                   partitioner=strips(1, ny, axis=1))[0]
    _restart_matches(build, 200, 100, os.path.join(shared_tmp_path, "ck_compliant"))


def test_removed_mass_survives_a_restart(shared_tmp_path):
    """With on_leave="remove" the mass and count of the particles removed so far are part of
    the checkpoint (before, a restart counted from 0 again)."""
    from dolfinx import mesh as dmesh

    def build():
        msh = dmesh.create_rectangle(WORLD, [[0.0, 0.0], [2.0, 0.5]], [16, 4],
                                     dmesh.CellType.quadrilateral, partitioner=strips(16, 4))
        grid = fm.Grid(msh)
        p = fm.Particles.fill(grid, fm.LinearElastic(E=1e5, nu=0.3, density=1000.0),
                              region=lambda x: x[:, 0] > 1.5, velocity=(5.0, 0.0))
        return fm.Simulation(grid, p, fm.Explicit(), dt=2e-3, gravity=(0.0, 0.0),
                             on_leave="remove")
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        ref, again = _restart_matches(build, 40, 40, os.path.join(shared_tmp_path, "ck_removed"))
    assert ref.removed_count > 0 and again.removed_count == ref.removed_count
    assert again.removed_mass == ref.removed_mass


def test_energy_monitor_goes_on_after_a_restart(shared_tmp_path):
    """monitor_energy's work of the loads, its E_0 and its history are part of the
    checkpoint: after a restart the balance goes on as in the continuous run (before, the
    work restarted from 0 and a sliding block's balance read 125 % and warned), and its CSV
    holds the continuous run's rows."""
    import warnings
    paths = {k: os.path.join(shared_tmp_path, f"energy_{k}.csv") for k in ("ref", "restart")}

    def build(key):
        sim = _block_on_incline(False)
        sim.monitor_energy(every=5, path=paths[key])
        return sim
    ref = build("ref")
    ref.run(steps=60)
    first = build("restart")
    first.run(steps=30, checkpoint=os.path.join(shared_tmp_path, "ck_energy"), checkpoint_every=30)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)       # no false balance warning
        again = fm.Simulation.restart(os.path.join(shared_tmp_path, "ck_energy"),
                                      lambda: build("restart"))
        again.run(steps=30)
    assert again.energy() == ref.energy()
    assert ref.energy()["external_work"] > 0.0
    assert again.energy_history == ref.energy_history
    assert abs(ref.energy_history[-1]["balance_error"]) < 0.02
    if WORLD.rank == 0:
        with open(paths["ref"]) as a, open(paths["restart"]) as b:
            assert a.read() == b.read()


def test_output_goes_on_after_a_restart(shared_tmp_path):
    """A run restored from a checkpoint with a fresh fm.Output on the same directory continues
    its files: the PVD and the grid XDMF hold every frame of the continuous run once, the
    frames written after the checkpoint by the run that went on past it are replaced (before,
    the particle files were numbered from 0 again, overwriting the first frames, and the
    XDMF lost them)."""
    import re
    from dolfinx import io as dio
    out = os.path.join(shared_tmp_path, "out_restart")
    ref_out = os.path.join(shared_tmp_path, "out_ref")
    ck = os.path.join(shared_tmp_path, "ck_out")
    build = lambda: vibrating_bar(fm.Explicit("MUSL"), n_cells=8, partitioner=strips(10, 1))[0]
    ref = build()
    ref.run(steps=60, output=fm.Output(ref_out, every=10))
    first = build()
    o = fm.Output(out, every=10)
    first.run(steps=30, checkpoint=ck, checkpoint_every=30, output=o)
    first.run(steps=20, output=o)                 # went on past the checkpoint, then stopped
    again = fm.Simulation.restart(ck, build)
    again.run(steps=30, output=fm.Output(out, every=10))

    def frames(d):
        pvd = open(os.path.join(d, "particles.pvd")).read()
        xdmf = open(os.path.join(d, "grid.xdmf")).read()
        return (re.findall(r'timestep="([^"]+)"[^>]*file="([^"]+)"', pvd),
                re.findall(r'Time Value="([^"]+)"', xdmf))
    if WORLD.rank == 0:
        assert frames(out) == frames(ref_out)
        assert len(frames(out)[0]) == 7 and len(frames(out)[1]) == 2 * 6     # velocity, mass
    with dio.XDMFFile(WORLD, os.path.join(out, "grid.xdmf"), "r") as f:
        msh = f.read_mesh(name="mesh")                                   # still readable
    assert msh.topology.index_map(msh.topology.dim).size_global == 10


def test_newmark_restart_to_solver_tolerance(shared_tmp_path):
    build = lambda: vibrating_bar(fm.Newmark(), n_cells=10, partitioner=strips(12, 1))[0]
    _restart_matches(build, 6, 6, os.path.join(shared_tmp_path, "ck"), exact=False, rtol=1e-10)


def test_staged_restart_keeps_initial_stress(shared_tmp_path):
    """A checkpoint taken in a second stage (optional field stress_initial) restores it."""
    def build():
        sim, _ = vibrating_bar(fm.Explicit("MUSL"), n_cells=12, partitioner=strips(14, 1))
        sim.particles.stress[:, 0, 0] = -3.0
        sim.start_stage(initial_stress=True)
        return sim
    path = os.path.join(shared_tmp_path, "ck")
    first = build()
    first.run(steps=10, checkpoint=path, checkpoint_every=5)
    again = fm.Simulation.restart(path, build)
    assert np.array_equal(again.particles.stress_initial, first.particles.stress_initial)
    assert np.all(again.particles.stress_initial[:, 0, 0] == -3.0)


def test_run_killed_between_checkpoints_restarts_from_the_last_one(shared_tmp_path):
    path = os.path.join(shared_tmp_path, "ck")
    build = lambda: vibrating_bar(fm.Explicit("MUSL"), n_cells=16, partitioner=strips(18, 1))[0]
    ref = build()
    ref.run(steps=40)
    crashed = build()

    def crash(sim):
        if sim.step_count == 27:
            raise KeyboardInterrupt("killed")
    crashed.observe(crash)
    with pytest.raises(KeyboardInterrupt):
        crashed.run(steps=40, checkpoint=path, checkpoint_every=10)
    steps = sorted(d for d in os.listdir(path) if d.startswith("step_"))
    assert steps == ["step_00000020"], steps                 # older ones removed (keep=1)
    again = fm.Simulation.restart(path, build)
    assert again.step_count == 20
    again.run(steps=20)
    _same(_state(ref), _state(again))


def test_interrupted_checkpoint_write_leaves_previous_intact(shared_tmp_path, monkeypatch):
    """A failure while writing (disk full, kill) must not touch LATEST or the older files."""
    path = os.path.join(shared_tmp_path, "ck")
    sim = vibrating_bar(fm.Explicit("MUSL"), n_cells=8)[0]
    sim.run(steps=5)
    sim.checkpoint(path)
    sim.run(steps=5)

    def disk_full(*args, **kw):
        raise OSError("No space left on device")
    monkeypatch.setattr(np, "savez", disk_full)
    with pytest.raises(OSError):
        sim.checkpoint(path)
    monkeypatch.undo()
    WORLD.barrier()
    again = vibrating_bar(fm.Explicit("MUSL"), n_cells=8)[0].restore(path)
    assert again.step_count == 5


def test_restore_refuses_a_different_setup(shared_tmp_path):
    path = os.path.join(shared_tmp_path, "ck")
    vibrating_bar(fm.Explicit("MUSL"), n_cells=8)[0].checkpoint(path)
    with pytest.raises(ValueError, match="integrator: checkpoint 'Explicit', simulation 'Newmark'"):
        vibrating_bar(fm.Newmark(), n_cells=8)[0].restore(path)
    with pytest.raises(ValueError, match="n_nodes"):
        vibrating_bar(fm.Explicit("MUSL"), n_cells=9)[0].restore(path)
    with pytest.raises(FileNotFoundError, match="no checkpoint"):
        vibrating_bar(fm.Explicit("MUSL"), n_cells=8)[0].restore(os.path.join(path, "nothing"))
    with pytest.raises(ValueError, match="checkpoint_every"):
        vibrating_bar(fm.Explicit("MUSL"), n_cells=8)[0].run(steps=2, checkpoint=path)


@pytest.mark.skipif(WORLD.size == 1, reason="restart on another rank count needs mpirun")
def test_restart_on_another_rank_count(shared_tmp_path):
    """Checkpoint written by a serial run (rank 0, COMM_SELF), restored on all ranks: equal to
    the continuous serial run to round-off (the summation order differs)."""
    path = os.path.join(shared_tmp_path, "ck")
    build = lambda comm: colliding_discs(fm.Explicit("USL"), n_cells=12, cfl=0.3, speed=0.2,
                                         comm=comm)[0]
    ref = build(MPI.COMM_SELF)
    ref.run(steps=40)
    if WORLD.rank == 0:
        build(MPI.COMM_SELF).run(steps=20, checkpoint=path, checkpoint_every=20)
    WORLD.barrier()
    again = fm.Simulation.restart(path, lambda: build(WORLD))
    assert again.particles.n_global() == len(ref.particles)
    again.run(steps=20)
    p, r = again.particles, ref.particles
    ids = np.concatenate(WORLD.allgather(p.id))           # ids travel with the checkpoint
    x = np.concatenate(WORLD.allgather(p.x))[np.argsort(ids)]
    v = np.concatenate(WORLD.allgather(p.v))[np.argsort(ids)]
    assert np.array_equal(np.sort(ids), np.sort(r.id))
    o = np.argsort(r.id)
    assert np.max(np.abs(x - r.x[o])) <= 1e-12
    assert np.max(np.abs(v - r.v[o])) <= 1e-10 * np.max(np.abs(r.v))


class _FailsAboveDt(fm.Explicit):
    """An 'implicit' integrator whose step fails (like a Newton divergence, before changing
    any state) when dt exceeds a threshold; otherwise a USL explicit step."""
    explicit = False

    def __init__(self, max_dt):
        super().__init__("USL")
        self.max_dt, self.dts = max_dt, []

    def step(self, sim, dt):
        if dt > self.max_dt:
            raise RuntimeError(f"Newton did not converge (dt = {dt:.3g})")
        self.dts.append(dt)
        super().step(sim, dt)


def test_dt_cuts_retry_and_final_failure_writes_last_state(shared_tmp_path):
    sim, _ = vibrating_bar(fm.Explicit("USL"), n_cells=8)
    dt = sim.dt
    integ = _FailsAboveDt(max_dt=0.3 * dt)
    sim = fm.Simulation(sim.grid, sim.particles, integ, dt=dt, max_dt_cuts=2)
    with pytest.warns(UserWarning, match="retried in smaller steps") if WORLD.rank == 0 else _nothing() as w:
        sim.step()
    assert np.allclose(integ.dts, [dt / 4] * 4) and sim.step_count == 1
    if WORLD.rank == 0:     # one warning for the step: 3 cuts (dt/2, then dt/4 twice)
        msgs = [str(x.message) for x in w if "smaller steps" in str(x.message)]
        assert len(msgs) == 1 and "3 cut(s), down to dt" in msgs[0] and "4x smaller" in msgs[0], msgs
    assert np.isclose(sim.t, dt, rtol=1e-15)
    # one cut is not enough: the error propagates and the last accepted state is written
    path = os.path.join(shared_tmp_path, "ck")
    sim.max_dt_cuts = 1
    with pytest.raises(RuntimeError, match="Newton did not converge"):
        with pytest.warns(UserWarning) if WORLD.rank == 0 else _nothing():
            sim.run(steps=3, checkpoint=path, checkpoint_every=10)
    with open(os.path.join(path, "LATEST")) as f:
        assert f.read() == "step_00000001"


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_leaving_particles_removed_and_counted():
    """on_leave='remove': the block moving out through x = 1 loses exactly the particles that
    crossed, and the removed mass is accounted: remaining + removed = initial."""
    from dolfinx import mesh
    msh = mesh.create_rectangle(WORLD, [[0, 0], [1, 1]], [8, 8], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=10.0, nu=0.3, density=1.0)
    p = fm.Particles.fill(grid, mat, per_cell=2, region=lambda x: x[:, 0] > 0.6, velocity=(1.0, 0.0))
    m0 = p.total(p.mass)
    sim = fm.Simulation(grid, p, fm.Explicit("MUSL"), dt=0.005, on_leave="remove")
    with pytest.warns(UserWarning, match="removed") if WORLD.rank == 0 else _nothing():
        sim.run(steps=20)                 # rigid translation by 0.1: columns at x > 0.9 leave
    m = sim.particles.total(sim.particles.mass)
    assert sim.removed_count == 2 * 16 and np.isclose(sim.removed_mass, m0 * 2 / 6, rtol=1e-12)
    assert np.isclose(m + sim.removed_mass, m0, rtol=1e-14)
    with pytest.raises(ValueError, match="on_leave"):
        fm.Simulation(grid, sim.particles, fm.Explicit(), dt=0.005, on_leave="drop")


def test_probe_csv_is_streamed_while_the_particle_changes_rank(shared_tmp_path):
    """Nothing lost on a crash: the probe's CSV holds every row up to the current step during
    the run, written by whichever rank owns the particle (it crosses x = 0.5, the rank cut)."""
    from fenicsmpm.io import read_probe_csv
    path = os.path.join(shared_tmp_path, "probe.csv")
    sim, _ = colliding_discs(fm.Explicit("USL"), n_cells=12, cfl=0.3, speed=0.2,
                             partitioner=strips(12, 12))
    pr = sim.probe((0.39, 0.2), fields=("position", "velocity"), path=path)
    seen = []

    def check(s):
        WORLD.barrier()                                   # the owner has flushed its row
        if WORLD.rank == 0:
            seen.append(len(read_probe_csv(path)["t"]))
    sim.observe(check, every=10)
    sim.run(steps=50)
    assert WORLD.bcast(seen, root=0) == [11, 21, 31, 41, 51]
    d = pr.data()
    assert d["position_x"][0] < 0.5 < d["position_x"][-1]          # crossed the rank cut
    WORLD.barrier()
    f = read_probe_csv(path)
    assert np.array_equal(f["t"], d["t"]) and np.allclose(f["position_x"], d["position_x"])
