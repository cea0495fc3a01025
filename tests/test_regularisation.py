"""Nonlocal regularisation of softening (issue 19, fenicsmpm.materials.regularisation), serially
and under `mpirun -n 2`.

Scene: fenicsmpm.problems.localisation.shear_layer, the W5 von Mises clay (c_u = 10 kPa,
H = -140 kPa, c_res = 3 kPa) in periodic simple shear, 0.2 m high, displacement controlled to
u = 6 mm in 60 quasi-static steps, a 2 cm weak zone at mid-height, h = 0.01 and 0.005 m.

Assertions and their reasons (figures measured with these scenes):
  * without softening (H = 0, MohrCoulomb eta = 0) a nonlocal length changes nothing: the
    same stresses and plastic strains to round-off (1e-12 relative), implicit and explicit;
  * regularised (l = 0.02 m): both meshes run to the end with Newton converging in at most
    6 iterations (measured 5); the post-peak tau(u) curves agree within 2 % of c_u at every
    step (measured 0.5 %); the band width w = sum V eps_p / (width eps_p,max) is the same
    on both meshes within 10 % (measured 0.052 / 0.051 m) and grows with l (l = 0.04 m:
    more than 1.5 times wider on the coarse mesh), so it is set by l, not h;
  * local softening: the band is one row of cells and the layer snaps back, so the run stops
    at the first softening step on both meshes (serially Newton does not converge; on 2 ranks
    the KSP returned a blown-up increment that the guards stop as inverted particles);
  * MPI: the run on the world communicator matches the serial run within 1e-8 c_u in tau
    and 1e-8 in eps_p (summation order only);
  * a restart from a checkpoint of an explicit regularised softening collapse continues to
    the uninterrupted run's state bit for bit (history columns travel with the particles).
"""
import numpy as np
import pytest
from mpi4py import MPI
from dolfinx import mesh as dmesh

import fenicsmpm as fm
from fenicsmpm.materials.regularisation import (_share_plan, _share_scans, _with_ghosts,
                                                nonlocal_average)
from fenicsmpm.problems.localisation import W5_SOIL, shear_layer, shear_layer_simulation

C_U = W5_SOIL["c_u"]


@pytest.fixture(scope="module")
def runs():
    """The regularised and local shear layers on both meshes (a few seconds in all)."""
    out = {}
    for h in (0.01, 0.005):
        out[("nl", h)] = shear_layer(h, 0.02)
        out[("local", h)] = shear_layer(h, None, steps=30)
    out[("wide", 0.01)] = shear_layer(0.01, 0.04)
    return out


def test_without_softening_the_regularisation_changes_nothing():
    perfect = dict(W5_SOIL, c_res=None, H=0.0)
    a = shear_layer(0.01, None, material=fm.VonMises(**perfect), steps=30, weak=0.0)
    b = shear_layer(0.01, None, material=fm.VonMises(**perfect, nonlocal_length=0.02), steps=30,
                    weak=0.0)
    assert a["eps_max"] > 1e-3, a["eps_max"]                     # it did flow plastically
    assert np.allclose(a["tau"], b["tau"], rtol=1e-12, atol=1e-12 * C_U)
    assert np.allclose(a["stress"], b["stress"], rtol=1e-12, atol=1e-12 * C_U)
    assert np.allclose(a["state"][:, 0], b["state"][:, 0], rtol=1e-12, atol=1e-15)


def test_mohr_coulomb_without_softening_is_unchanged():
    """Element level: random increments and history, eta = 0, with and without a length."""
    rng = np.random.default_rng(1)
    n = 200
    kw = dict(E=20e6, nu=0.3, density=2000.0, phi=30.0, c=5e3, psi=5.0, tension_cutoff=1e3)
    loc, nl = fm.MohrCoulomb(**kw), fm.MohrCoulomb(**kw, nonlocal_length=0.1)
    assert (loc.n_state, nl.n_state, nl.nonlocal_column) == (3, 4, 3)
    dF = np.eye(3) + 3e-3 * rng.standard_normal((n, 3, 3))
    dF[:, 2, :] = dF[:, :, 2] = 0.0
    dF[:, 2, 2] = 1.0
    s0 = -20e3 * np.eye(3) + 2e3 * rng.standard_normal((n, 3, 3))
    s0 = 0.5 * (s0 + s0.transpose(0, 2, 1))
    idx = np.arange(n)
    out = []
    for mat in (loc, nl):
        st = np.zeros((n, mat.n_state))
        st[:, mat.n_state - 1] = rng.uniform(0, 0.1, n) if mat is nl else 0.0
        sig, ds = np.zeros((n, 3, 3)), np.zeros((n, 3, 3, 3, 3))
        mat.stress(idx, dF, None, s0, sig, st)
        mat.tangent(idx, dF, None, s0, sig, np.zeros_like(st), ds)
        out.append((sig, st[:, :2], ds))
    assert np.mean(out[0][1][:, 0] > 0) > 0.2                     # many returns were plastic
    for a, b in zip(out[0], out[1]):
        assert np.allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(a).max())


@pytest.mark.parametrize("name", ["VonMises", "MohrCoulomb"])
def test_nonlocal_strength_at_step_start_is_that_of_A(name):
    """With kappa_bar = A at the start of a step the yield surface is the local one at
    kappa = A: the same trial stresses yield (random increments, A in the softening range;
    kappa_n = 0 and <kappa> = A / m, so A = (1 - m) 0 + m <kappa>)."""
    rng = np.random.default_rng(2)
    n = 400
    if name == "VonMises":
        kw, a = dict(W5_SOIL), rng.uniform(0.0, 0.04, n)
    else:
        kw, a = dict(E=20e6, nu=0.3, density=2000.0, phi=30.0, c=5e3, phi_res=20.0, c_res=1e3,
                     eta=20.0), rng.uniform(0.0, 0.1, n)
    cls = getattr(fm, name)
    loc, nl = cls(**kw), cls(**kw, nonlocal_length=0.1)
    dF = np.eye(3) + 2e-3 * rng.standard_normal((n, 3, 3))
    dF[:, 2, :] = dF[:, :, 2] = 0.0
    dF[:, 2, 2] = 1.0
    s0 = -20e3 * np.eye(3) + 3e3 * rng.standard_normal((n, 3, 3))
    s0 = 0.5 * (s0 + s0.transpose(0, 2, 1))
    flows = []
    for mat in (loc, nl):
        st = np.zeros((n, mat.n_state))
        st[:, 0 if mat is loc else mat.nonlocal_column] = a if mat is loc else a / mat.nonlocal_m
        mat.stress(np.arange(n), dF, None, s0, np.zeros((n, 3, 3)), st)
        flows.append(st[:, 0] - (a if mat is loc else 0.0) > 0.0)
    assert 0.1 < np.mean(flows[0]) < 0.9, np.mean(flows[0])      # both kinds of step occur
    assert np.array_equal(flows[0], flows[1])


def test_regularised_band_width_follows_length_not_mesh(runs):
    a, b, w = runs[("nl", 0.01)], runs[("nl", 0.005)], runs[("wide", 0.01)]
    assert a["completed"] and b["completed"] and w["completed"], (a["stopped"], b["stopped"])
    assert abs(a["band_width"] / b["band_width"] - 1.0) < 0.10, (a["band_width"], b["band_width"])
    assert w["band_width"] > 1.5 * a["band_width"], (w["band_width"], a["band_width"])
    assert a["band_width"] > 2.0 * 0.01                            # wider than the coarse cell
    # the post-peak branch: softening happened and both meshes agree
    assert a["tau"].max() > 0.95 * C_U and a["tau"][-1] < 0.8 * C_U, a["tau"]
    assert np.max(np.abs(a["tau"] - b["tau"])) < 0.02 * C_U, np.abs(a["tau"] - b["tau"]).max()


def test_regularised_newton_converges(runs):
    for key in (("nl", 0.01), ("nl", 0.005), ("wide", 0.01)):
        r = runs[key]
        assert len(r["newton"]) == 60 and max(r["newton"]) <= 6, (key, r["newton"])


def test_local_softening_fails_where_regularised_runs(runs):
    for h in (0.01, 0.005):
        r = runs[("local", h)]
        assert not r["completed"], r["tau"]          # Newton/KSP failure or a blown-up step


def _gather_by_id(comm, r):
    ids = comm.allgather(r["ids"])
    st = comm.allgather(r["state"])
    ids, st = np.concatenate(ids), np.concatenate(st)
    return st[np.argsort(ids)]


def _by_position(comm, r):
    """The state rows of every rank, ordered by initial position (ids depend on the partition)."""
    x0, st = np.concatenate(comm.allgather(r["x0"])), np.concatenate(comm.allgather(r["state"]))
    key = np.round(x0 / 1e-6).astype(np.int64)
    return st[np.lexsort(key.T[::-1])]


def test_mpi_matches_serial(comm):
    par = shear_layer(0.005, 0.02, comm=comm, steps=40)
    ser = shear_layer(0.005, 0.02, comm=MPI.COMM_SELF, steps=40)
    assert par["completed"] and ser["completed"]
    assert np.max(np.abs(par["tau"] - ser["tau"])) < 1e-8 * C_U
    a, b = _by_position(comm, par), _by_position(MPI.COMM_SELF, ser)
    assert a.shape == b.shape and np.max(np.abs(a - b)) < 1e-8, np.max(np.abs(a - b))
    assert par["band_width"] == pytest.approx(ser["band_width"], rel=1e-8)


def test_checkpoint_restart_carries_the_history(shared_tmp_path):
    """Explicit collapse of a regularised softening block (see _collapse): the restarted run
    is the uninterrupted one bit for bit (explicit, same partition)."""
    path = f"{shared_tmp_path}/ckpt"
    sim = _collapse_simulation(_SOFT)
    sim.run(steps=60, checkpoint=path, checkpoint_every=60, progress=False)
    assert sim.particles.total(sim.particles.state[:, 0] > 1e-3) > 0   # history to carry
    sim.run(steps=20, progress=False)
    back = fm.Simulation.restart(path, lambda: _collapse_simulation(_SOFT))
    assert back.step_count == 60
    back.run(steps=20, progress=False)
    ref = _gather_by_id(sim.comm, dict(ids=sim.particles.id, state=sim.particles.state))
    got = _gather_by_id(back.comm, dict(ids=back.particles.id, state=back.particles.state))
    assert np.array_equal(got, ref), np.abs(got - ref).max()


_KW = dict(E=1e6, nu=0.3, density=1800.0, c_u=2e3)
_SOFT = lambda: fm.VonMises(**_KW, c_res=1e3, H=-50e3, nonlocal_length=0.2)


def _collapse_simulation(material):
    """A 1 m x 1 m von Mises block collapsing under gravity on a 3 m x 1.5 m grid (h = 0.125),
    explicit MUSL, smooth left wall, fixed base."""
    msh = dmesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [3.0, 1.5]], [24, 12],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    pts = fm.Particles.fill(grid, material(), per_cell=2,
                            region=lambda x: (x[:, 0] < 1.0) & (x[:, 1] < 1.0))
    sim = fm.Simulation(grid, pts, fm.Explicit("MUSL"), dt="auto", gravity=(0.0, -9.81))
    sim.fix(lambda x: np.abs(x[:, 1]) < 1e-9)
    sim.fix(lambda x: np.abs(x[:, 0]) < 1e-9, [0])
    return sim


def _collapse(material, steps=150):
    sim = _collapse_simulation(material)
    sim.run(steps=steps, progress=False)
    p = sim.particles
    return _gather_by_id(sim.comm, dict(ids=p.id, state=np.column_stack([p.x, p.state]))), sim


def test_explicit_no_softening_unchanged_and_softening_regularised():
    a, _ = _collapse(lambda: fm.VonMises(**_KW))
    b, _ = _collapse(lambda: fm.VonMises(**_KW, nonlocal_length=0.2))
    assert a[:, 2].max() > 1e-3                                  # plastic flow happened
    assert np.allclose(a, b[:, :3], rtol=1e-12, atol=1e-12)
    c, sim = _collapse(_SOFT)
    assert np.all(np.isfinite(c)) and c[:, 2].max() > 1e-3
    # the average column <eps_p> is not the local eps_p
    assert np.abs(c[:, 3] - c[:, 2]).max() > 1e-3
    assert sim.timers["nonlocal"] > 0.0


def _brute_average(x, vol, kap, l, n_own):
    """The O(n^2) <kappa> of nonlocal_average's docstring for the first n_own points."""
    r = np.linalg.norm(x[:n_own, None, :] - x[None, :, :], axis=2)
    w = np.where(r < 3 * l, r / l ** 2 * np.exp(-(r / l) ** 2), 0.0) * vol[None, :]
    den = w.sum(axis=1)
    return np.where(den > 0, (w @ kap) / np.where(den > 0, den, 1), kap[:n_own])


def test_nonlocal_average_kernel_against_brute_force():
    """Binned search (kernel) against the O(n^2) sum on random points, ghosts included."""
    rng = np.random.default_rng(3)
    x = rng.uniform(0.0, 1.0, (400, 2))
    vol = rng.uniform(0.5, 1.5, 400)
    kap = np.where(rng.uniform(size=400) < 0.3, rng.uniform(0, 0.1, 400), 0.0)
    l, n_own = 0.07, 300
    out = np.empty(n_own)
    nonlocal_average(x, vol, kap, n_own, np.zeros(2), 0.05, l, out)
    assert np.allclose(out, _brute_average(x, vol, kap, l, n_own), rtol=1e-12, atol=1e-15)


def test_nonlocal_average_of_a_small_plastic_zone_against_brute_force():
    """Only points near kappa != 0 are scanned (the hot bins dilated by the cutoff): with the
    plastic zone in one corner the far points get exactly 0 and the near ones the O(n^2)
    average, also where the zone lies within a bin or two of the cutoff."""
    rng = np.random.default_rng(5)
    x = rng.uniform(0.0, 1.0, (1500, 2))
    vol = rng.uniform(0.5, 1.5, 1500)
    kap = np.where(np.linalg.norm(x, axis=1) < 0.08, rng.uniform(0.01, 0.1, 1500), 0.0)
    l, n_own = 0.07, 1400
    out = np.full(n_own, np.nan)
    nonlocal_average(x, vol, kap, n_own, np.zeros(2), 0.05, l, out)
    assert np.allclose(out, _brute_average(x, vol, kap, l, n_own), rtol=1e-12, atol=1e-15)
    far = np.linalg.norm(x[:n_own], axis=1) > 0.08 + 3 * l
    assert far.sum() > 1000 and np.all(out[far] == 0.0)
    assert np.count_nonzero(out) > 50


def test_share_plan_moves_the_excess_to_the_idle_ranks():
    """_share_plan: ranks above the mean hand points to ranks below it, none below min_share."""
    assert _share_plan([1000, 0], 256) == [(0, 1, 500)]
    assert _share_plan([300, 0], 256) == []
    assert _share_plan([900, 300, 0], 10) == [(0, 1, 100), (0, 2, 400)]
    assert _share_plan([0, 0], 256) == []


def test_scans_shared_between_ranks_give_the_same_bits(comm):
    """_share_scans (regularise under MPI): the plastic zone on rank 0's side; rank 0 hands
    half of its scans with their neighbourhoods to rank 1 (on 2 ranks), and every average
    has the bits of the unshared nonlocal_average on the same local and ghost points."""
    rng = np.random.default_rng(7)
    xg = rng.uniform(0.0, 1.0, (6000, 2))
    vol_g = rng.uniform(0.5, 1.5, 6000)
    kap_g = np.where(np.linalg.norm(xg, axis=1) < 0.3, rng.uniform(0.01, 0.1, 6000), 0.0)
    mine = (xg[:, 0] * comm.size).astype(int) == comm.rank
    l, hb, origin = 0.05, 0.02, np.zeros(2)
    x, vol, kap = _with_ghosts(comm, xg[mine], vol_g[mine], kap_g[mine], 3 * l)
    n_own = int(mine.sum())
    out, ref = np.full(n_own, np.nan), np.full(n_own, np.nan)
    given = _share_scans(comm, x, vol, kap, n_own, origin, hb, l, out)
    nonlocal_average(x, vol, kap, n_own, origin, hb, l, ref)
    assert np.array_equal(out, ref)
    assert np.count_nonzero(out) > 100 or comm.rank > 0
    if comm.size == 2:
        assert comm.allgather(given)[0] > 500


def test_parameters_are_checked():
    with pytest.raises(ValueError, match="nonlocal_length"):
        fm.VonMises(**W5_SOIL, nonlocal_length=-1.0)
    with pytest.raises(ValueError, match="nonlocal_m"):
        fm.MohrCoulomb(E=1e6, nu=0.3, density=1.0, phi=30, c=1.0, nonlocal_length=1.0,
                       nonlocal_m=1.0)
    m = fm.MohrCoulomb(E=1e6, nu=0.3, density=1.0, phi=30, c=1.0, eta=2.0, nonlocal_length=1.0)
    assert m.reduced(1.5).nonlocal_length == 1.0
    assert "nonlocal_length=1.0" in repr(m) and "nonlocal" not in repr(fm.VonMises(**W5_SOIL))


def test_explicit_average_refreshed_on_its_schedule():
    """Explicit runs refresh <eps_p> only at the steps refresh_due names (every REFRESH l / c_p,
    here about 4 steps), and it does change there once the block flows."""
    from fenicsmpm.materials.regularisation import REFRESH, refresh_due
    sim = _collapse_simulation(_SOFT)
    mat = sim.particles.materials[0]
    tau = REFRESH * mat.nonlocal_length / mat.p_wave_speed
    assert 2 < tau / sim.dt < 20, tau / sim.dt
    changed, due = [], []
    for _ in range(120):
        before, t0 = sim.particles.state[:, mat.nonlocal_column].copy(), sim.t
        sim.run(steps=1, progress=False)
        due.append(refresh_due(t0, sim.t - t0, tau))
        diff = np.abs(sim.particles.state[:, mat.nonlocal_column] - before).max(initial=0.0)
        changed.append(sim.comm.allreduce(diff, op=MPI.MAX) > 0.0)
    changed, due = np.array(changed), np.array(due)
    assert not np.any(changed & ~due), np.flatnonzero(changed & ~due)
    assert changed.sum() >= 5 and due.sum() < 0.5 * len(due), (changed.sum(), due.sum())


def test_refresh_due():
    from fenicsmpm.materials.regularisation import refresh_due
    assert refresh_due(0.0, 0.1, 1.0)
    steps = [refresh_due(k * 0.3, 0.3, 1.0) for k in range(10)]     # t = 0, 0.3, ..., 2.7
    assert steps == [True, False, False, False, True, False, False, True, False, False]
    assert all(refresh_due(k * 2.0, 2.0, 1.0) for k in range(5))    # dt > tau: every step
