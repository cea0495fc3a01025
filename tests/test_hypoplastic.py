"""Hypoplastic sand (issue 18 parts 1-2; seed 004 ch. 3, Table 3.1 in SI units): element tests
against what the theory fixes, the numerical tangent, bad input, and the material in MPM runs
(gravity column, checkpoint/restart).  Element tests run per rank (serial and mpirun -n 2)."""
import os

import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.materials import element_test as et
from fenicsmpm.materials.hypoplastic import geostatic
from fenicsmpm.partition import strips

# seed 004 Table 3.1 (h_s = 5.8E6 kPa, p_t = 1.6 kPa) in Pa
TABLE_3_1 = dict(phi_c=30.0, h_s=5.8e9, n=0.28, e_d0=0.53, e_c0=0.84, e_i0=1.0, alpha=0.13,
                 beta=1.0, m_R=10.0, m_T=2.0, R=5e-5, beta_r=0.3, chi=1.0, density=2600.0,
                 e_0=0.65, p_t=1600.0)


def sand(**kw):
    return fm.Hypoplastic(**{**TABLE_3_1, **kw})


@pytest.mark.parametrize("case", ["loose-drained", "dense-drained", "loose-undrained"])
def test_critical_state(case):
    """Continued triaxial compression from p0 = 100 kPa ends on the critical state:
    q/(p + p_t) = M_c = 6 sin phi_c / (3 - sin phi_c) and e = e_c(p) (eq 3.15), both within 1 %
    (the model sees the shifted stress sigma - p_t I, so the critical line is q = M_c (p + p_t)).
    Axial strains (sums of increments): loose 30 %, dense 200 % (dense sand reaches the
    critical state only after large shearing)."""
    m = sand()
    e0, eps, n, drained = {"loose-drained": (0.80, -0.3, 600, True),
                           "dense-drained": (0.60, -2.0, 2000, True),
                           "loose-undrained": (0.80, -0.3, 600, False)}[case]
    h = et.triaxial(m, 100e3, e0=e0, axial_strain=eps, n=n, drained=drained)
    eta = h["q"][-1] / (h["p"][-1] + m.p_t)
    _, ec, _ = m.characteristic_void_ratios(h["p"][-1])
    err_eta, err_e = eta / m.M_c - 1.0, h["e"][-1] / ec - 1.0
    assert np.all(np.isfinite(h["sigma"]))
    assert abs(err_eta) < 0.01, f"{case}: q/(p+p_t) = {eta:.5f} vs M_c = {m.M_c:.5f} ({100 * err_eta:+.3f} %)"
    assert abs(err_e) < 0.01, f"{case}: e = {h['e'][-1]:.5f} vs e_c(p) = {ec:.5f} ({100 * err_e:+.3f} %)"
    if not drained:
        assert np.ptp(h["e"]) < 1e-10, "isochoric path changed the void ratio"


@pytest.mark.parametrize("start", ["e_i", "loose", "dense"])
def test_isotropic_compression(start):
    """Isotropic compression 10 kPa -> 50 MPa with the intergranular strain mobilised by the
    isotropic loading history (delta_0 = -R I / sqrt 3): e stays in [e_d(p), e_i(p)] and the
    relative distance r = (e_i - e)/(e_i - e_d) to the asymptote e_i(p) never grows and shrinks
by more than 10 % (measured: loose 0.043 -> 0.034, dense 0.98 -> 0.84).  Started
    on e_i the path stays on it (f_b of eq 3.14 is built for that) within 1e-5 relative."""
    m = sand()
    ed0, _, ei0 = m.characteristic_void_ratios(10e3)
    e0 = {"e_i": ei0, "loose": 0.98 * ei0, "dense": ed0 + 0.01}[start]
    el = et.Element(m, 10e3, e=e0, delta=-m.R / np.sqrt(3.0) * np.eye(3))
    while -np.trace(el.sigma[0]) / 3.0 < 50e6:
        el.step(-2e-4 / 3.0 * np.eye(3))
    h = el.history()
    ed, _, ei = m.characteristic_void_ratios(h["p"])
    r = (ei - h["e"]) / (ei - ed)
    assert np.all(h["e"] >= ed) and np.all(h["e"] <= ei * (1.0 + 1e-6)), "e left [e_d(p), e_i(p)]"
    assert np.all(np.diff(r) <= 1e-7), f"distance to e_i grew by {np.max(np.diff(r)):.3g}"
    if start == "e_i":
        assert np.max(np.abs(h["e"] / ei - 1.0)) < 1e-5
    else:
        assert r[-1] < 0.9 * r[0], f"r = {r[0]:.4f} -> {r[-1]:.4f}: no approach to e_i"


def test_reversal_stiffness():
    """After oedometric loading (100 R, rho = 1, delta along -e_yy) the tangent stiffness of a
    small increment (R / 1e4) is m_R L (eq 3.22, 180 degree reversal: +e_yy) and m_T L (90 degree:
    e_xx and a shear e_xy, orthogonal to delta), L of eq 3.5 at the current state; within 1 %."""
    m = sand()
    el = et.Element(m, 100e3, e=0.7)
    for _ in range(200):
        el.step(np.diag([0.0, -2.5e-5, 0.0]))
    d = el.state[0, 1:4]
    assert abs(-d[1] / m.R - 1.0) < 1e-9 and abs(d[0]) + abs(d[2]) < 1e-15
    L, N = m.tensors(el.sigma, el.state[:, 0])
    h = m.R * 1e-4
    shear = np.zeros((3, 3))
    shear[0, 1] = shear[1, 0] = 1.0 / np.sqrt(2.0)
    for name, E, factor in (("180", np.diag([0.0, 1.0, 0.0]), m.m_R),
                            ("90 normal", np.diag([1.0, 0.0, 0.0]), m.m_T),
                            ("90 shear", shear, m.m_T)):
        s, _ = el.trial(h * E)
        K = (s - el.sigma[0]) / h
        ref = factor * np.einsum("ijkl,kl->ij", L[0], E)
        err = np.linalg.norm(K - ref) / np.linalg.norm(ref)
        assert err < 0.01, f"{name}: stiffness differs from {factor} L by {100 * err:.3f} %"
    # continued loading: the hypoplastic L : D + N ||D|| (rho = 1, eq 3.22 reduces to eq 3.3)
    E = np.diag([0.0, -1.0, 0.0])
    s, _ = el.trial(h * E)
    ref = np.einsum("ijkl,kl->ij", L[0], E) + N[0]
    assert np.linalg.norm((s - el.sigma[0]) / h - ref) / np.linalg.norm(ref) < 0.01


def test_dense_dilates_loose_contracts():
    """Drained triaxial compression at 100 kPa to 20 % axial strain: a dense sample (e0 = 0.56,
    near e_d) dilates (final eps_v > 0) and shows a peak q/(p + p_t) above M_c that softens
    afterwards; a loose one (e0 = 0.85 > e_c) contracts monotonically (e never increases),
    with its largest stress ratio at the end (no peak) and below M_c."""
    m = sand()
    dense = et.triaxial(m, 100e3, e0=0.56, axial_strain=-0.2, n=1000)
    eta = dense["q"] / (dense["p"] + m.p_t)
    assert dense["eps_v"][-1] > 0.01, f"dense: eps_v = {dense['eps_v'][-1]:.4f}, no dilation"
    assert eta.max() > 1.1 * m.M_c, f"dense: peak ratio {eta.max():.4f} vs M_c {m.M_c:.4f}"
    assert eta[-1] < 0.95 * eta.max(), "dense: no softening after the peak"
    loose = et.triaxial(m, 100e3, e0=0.85, axial_strain=-0.2, n=1000)
    eta = loose["q"] / (loose["p"] + m.p_t)
    assert np.all(np.diff(loose["e"]) <= 1e-12), "loose: the void ratio increased"
    assert loose["eps_v"][-1] < -0.01
    assert eta.max() <= eta[-1] * (1.0 + 1e-5) and eta[-1] < m.M_c, "loose: peak before the end"


@pytest.mark.parametrize("bad, name", [
    (dict(phi_c=0.0), "phi_c"), (dict(phi_c=90.0), "phi_c"), (dict(h_s=0.0), "h_s"),
    (dict(n=0.0), "n"), (dict(n=-0.3), "n"), (dict(e_c0=0.5), "e_c0"), (dict(e_i0=0.8), "e_i0"),
    (dict(e_d0=-0.1), "e_d0"), (dict(R=0.0), "R"), (dict(m_R=1.5), "m_R"), (dict(m_T=0.5), "m_T"),
    (dict(e_0=0.4), "e_0"), (dict(e_0=1.1), "e_0"), (dict(p_t=-1.0), "p_t"),
    (dict(p_t=0.0), "p_min"), (dict(alpha=20.0), "alpha"), (dict(density=-1.0), "density"),
    (dict(delta_0=np.eye(3)), "delta_0"), (dict(tol=0.5), "tol"), (dict(chi=0.0), "chi")])
def test_bad_parameters(bad, name):
    with pytest.raises(ValueError, match=f"'{name}'"):
        sand(**bad)


def test_bad_initial_void_ratio():
    """e_0 must lie in [e_d(p), e_i(p)] at the initial pressure: 0.95 < e_i0 is fine at zero
    pressure but above e_i(100 kPa) = 0.939; the error names the range."""
    m = sand(e_0=0.95)
    with pytest.raises(ValueError, match=r"'e'.*e_i\(p\).*0\.9386"):
        et.Element(m, 100e3)
    with pytest.raises(ValueError, match="'e_0'"):       # fresh particles at their pressure
        m.stress(np.array([0]), np.eye(3)[None], None, -100e3 * np.eye(3)[None],
                 np.empty((1, 3, 3)), np.zeros((1, 7)))


def test_numerical_tangent_against_finite_differences():
    """The tangent (central differences with the unperturbed sub-steps) against central
    differences of the public stress update (tol 1e-8), at an anisotropic stress with shear,
    rho < 1 and a general dF (stretch and spin): relative Frobenius error < 1e-4."""
    m = sand(tol=1e-8)
    rng = np.random.default_rng(7)
    s0 = np.array([[-120e3, 10e3, 0.0], [10e3, -200e3, 5e3], [0.0, 5e3, -90e3]])[None]
    st = np.array([[0.7, 1e-5, -3e-5, 0.5e-5, 1e-5, 0.0, 0.0]])
    idx = np.array([0])
    for mag in (1e-6, 1e-4, 1e-3):
        dF = (np.eye(3) + mag * rng.standard_normal((3, 3)))[None]
        T = np.empty((1, 3, 3, 3, 3))
        m.tangent(idx, dF, None, s0, None, st.copy(), T)
        FD = np.empty((3, 3, 3, 3))
        h = 1e-3 * mag
        for k in range(3):
            for l in range(3):
                out = []
                for sg in (1.0, -1.0):
                    G = dF.copy()
                    G[0, k, l] += sg * h
                    sn = np.empty_like(s0)
                    m.stress(idx, G, None, s0, sn, st.copy())
                    out.append(sn[0])
                FD[:, :, k, l] = (out[0] - out[1]) / (2.0 * h)
        err = np.linalg.norm(T[0] - FD) / np.linalg.norm(FD)
        assert err < 1e-4, f"|dF - I| ~ {mag:g}: tangent vs finite differences {err:.3g}"


def test_p_wave_speed_from_constrained_modulus():
    """p_wave_speed = sqrt(E_c / rho) with E_c = m_R f_b f_e (3 + a^2/3) (eqs 3.27, 3.30,
    delta = 0) at p_max, e = e_d(p_max): equal (1e-3) to the measured oedometric stiffness
    d sigma_yy / d eps_yy of the kernel at that state."""
    m = sand(p_max=2e5)
    ed, _, _ = m.characteristic_void_ratios(2e5)
    el = et.Element(m, 2e5, e=ed, delta=np.zeros((3, 3)))
    h = 1e-9
    s, _ = el.trial(np.diag([0.0, -h, 0.0]))
    K = -(s[1, 1] - el.sigma[0, 1, 1]) / h
    c = np.sqrt(K / m.density)
    assert abs(m.p_wave_speed / c - 1.0) < 1e-3, f"{m.p_wave_speed:.6g} vs measured {c:.6g} m/s"


def test_stress_free_and_tension_states_have_no_nan():
    """The p -> 0 rule: stress-free particles pulled apart sit at sigma = (p_t - p_min) I (no
    shear, no NaN); compressed, they build up compression; a tensile input state is projected
    first; e follows 1 + e = (1 + e_0) exp(tr D)."""
    m = sand()
    pmin = m.p_t / 4.0
    idx = np.arange(3)
    sig = np.zeros((3, 3, 3))
    sig[2] = 10e3 * np.eye(3) + 3e3 * (np.eye(3)[[1, 0, 2]] - np.diag([0.0, 0.0, 1.0]))
    dF = np.stack([np.eye(3) + 1e-3 * np.diag([1.0, 1.0, 0.0]), np.eye(3) - 1e-3 * np.eye(3),
                   np.eye(3)])
    st = np.zeros((3, 7))
    out = np.empty_like(sig)
    for _ in range(20):
        m.stress(idx, dF, None, sig, out, st)
        sig[:] = out
    assert np.all(np.isfinite(sig)) and np.all(np.isfinite(st))
    assert np.allclose(sig[0], (m.p_t - pmin) * np.eye(3), rtol=0.0, atol=1e-6 * m.p_t)
    assert np.all(np.linalg.eigvalsh(sig[1]) < -10 * m.p_t), "compressed particle has no stress"
    assert np.allclose(sig[2], (m.p_t - pmin) * np.eye(3), atol=1e-6 * m.p_t)
    assert np.isclose(st[1, 0], 1.65 * np.exp(-20 * 3e-3) - 1.0, rtol=1e-12)


def _column(comm, partitioner=None, ramp=0.5, geo=False, integrator=None, tol=1e-4, p_max=60e3):
    """A 2 m hypoplastic sand column (0.5 m wide, h = 0.25, rho = 2000, g = 10), rollers on
    the sides and the base; explicit MUSL with dt = "auto" (p_max = 60 kPa) unless an
    (implicit) integrator is given, then dt = 1."""
    H, h, g = 2.0, 0.25, 10.0
    m = sand(density=2000.0, p_max=p_max, tol=tol)
    kw = {} if partitioner is None else dict(partitioner=partitioner)
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [2 * h, H + h]], [2, 9],
                                 dmesh.CellType.quadrilateral, **kw)
    grid = fm.Grid(msh)
    pts = fm.Particles.fill(grid, m, per_cell=2, region=lambda x: x[:, 1] < H)
    if geo:
        geostatic(pts, m, g, void_ratio="relative")
    if integrator is None:
        sim = fm.Simulation(grid, pts, fm.Explicit("MUSL"), dt="auto", gravity=(0.0, -g),
                            gravity_ramp=None if geo else ramp)
    else:
        sim = fm.Simulation(grid, pts, integrator, dt=1.0, gravity=(0.0, -g))
    sim.fix(lambda x: np.isclose(x[:, 0], 0.0) | np.isclose(x[:, 0], 2 * h), [0])
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0), [1])
    return sim, m


@pytest.mark.parametrize("p_max", [1e3, 60e3])
def test_dt_follows_the_state_beyond_p_max(comm, p_max):
    """dt="auto" starts from the P-wave speed at p_max. The geostatic column's largest mean
    stress is 25.8 kPa: with p_max = 1 kPa (c_p 145 m/s there, 342 m/s at 25.8 kPa) the first
    step already uses the critical step of the state, cfl h / 342 m/s (Simulation.follow_state_dt,
    issue 21), without a warning; with p_max = 60 kPa dt stays. With a fixed dt above the
    state's critical step the run warns at its start (guards.check_wave_speed, naming the
    material and p_max)."""
    import warnings
    sim, m = _column(comm, geo=True, p_max=p_max)
    dt0 = sim.dt
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        sim.run(steps=1)
    assert not [w for w in rec if "exceeds the critical step" in str(w.message)]
    p = sim.particles
    pmax = -np.trace(p.stress, axis1=1, axis2=2).min(initial=0.0) / 3.0
    pmax = comm.allreduce(float(pmax), op=MPI.MAX)
    c = m.state_p_wave_speed(np.diag([-pmax] * 3)[None])
    if p_max < 10e3:
        assert pmax > 20e3 and c > 300.0, (pmax, c)
        assert sim.dt < 0.5 * dt0 and np.isclose(sim.dt, sim.cfl * sim.grid.h / c, rtol=0.02), \
            (sim.dt, dt0, sim.cfl * sim.grid.h / c)
    else:
        assert sim.dt == dt0
    sim2, _ = _column(comm, geo=True, p_max=p_max)
    sim2.start_stage(dt=dt0, initial_stress=False)      # a fixed dt: the guard warns
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        sim2.run(steps=1)
    hit = [w for w in rec if "exceeds the critical step" in str(w.message)]
    if comm.rank == 0:
        assert len(hit) == (1 if p_max < 10e3 else 0), [str(w.message) for w in rec]
        if hit:
            assert "Hypoplastic (material 0)" in str(hit[0].message)
            assert "p_max" in str(hit[0].message)
    else:
        assert not hit


def test_column_settles_to_geostatic_stress(comm):
    """From a stress-free state, gravity ramped over 0.5 s, then held for 0.25 s: the mean
    sigma_yy of the bottom cell row equals -rho g (H - Y) at its particles (the weight above
    them) within 3 % (measured +2.2 %, serial and 2 ranks); no NaN; the kinetic energy has
    decayed."""
    sim, m = _column(comm)
    sim.run(t_end=0.75)
    p = sim.particles
    Y = (p.x - p.u)[:, 1]
    bot = Y < 0.25
    syy = p.total(p.stress[bot, 1, 1].sum())
    ref = p.total((-2000.0 * 10.0 * (2.0 - Y[bot])).sum())
    n_nan = p.total(np.count_nonzero(~np.all(np.isfinite(p.stress), axis=(1, 2))))
    assert n_nan == 0
    assert abs(syy / ref - 1.0) < 0.03, f"base sigma_yy {syy / ref:.4f} x rho g (H - Y)"
    assert p.kinetic_energy() < 1e-3 * p.total(p.mass.sum()) * 10.0 * 2.0
    assert p.total(np.count_nonzero(p.state[:, 0] == 0.0)) == 0


def test_implicit_column_with_numerical_tangent(comm):
    """The same column, quasi-static from stress-free in 10 load steps with Newton on the
    numerical tangent (material tol 1e-6, rtol 1e-6; the sub-stepped update is smooth only to
    its tolerance): at most 6 Newton iterations per load step (measured 4-5), and the bottom-row
    sigma_yy within 1 % of -rho g (H - Y) (measured +0.39 %)."""
    sim, m = _column(comm, integrator=fm.QuasiStatic(load_steps=10, rtol=1e-6), tol=1e-6)
    its = []
    for _ in range(10):
        sim.run(steps=1, progress=False)
        its.append(sim.stats["newton_iterations"])
    p = sim.particles
    Y = (p.x - p.u)[:, 1]
    bot = Y < 0.25
    ratio = p.total(p.stress[bot, 1, 1].sum()) / p.total((-2000.0 * 10.0 * (2.0 - Y[bot])).sum())
    assert max(its) <= 6, f"Newton iterations per load step {its}"
    assert abs(ratio - 1.0) < 0.01, f"base sigma_yy {ratio:.4f} x rho g (H - Y)"


def test_checkpoint_restart_carries_void_ratio_and_intergranular_strain(shared_tmp_path):
    """Geostatic start (K0 = 1 - sin phi_c, relative void-ratio field) under 1.2 g, so the
    column settles and its intergranular strain grows (a geostatic state under its own g is
    in discrete equilibrium: on exact node coordinates nothing moves), 60 explicit steps, a
    checkpoint at step 30: the restarted run's stress, void ratio and intergranular strain are
    bit for bit those of the continuous run."""
    def build():
        sim = _column(MPI.COMM_WORLD, partitioner=strips(2, 9, axis=1), geo=True)[0]
        sim.gravity = 1.2 * sim.gravity
        return sim
    ref = build()
    e_init = ref.particles.state[:, 0].copy()
    ref.run(steps=60)
    first = build()
    path = os.path.join(shared_tmp_path, "ck")
    first.run(steps=30, checkpoint=path, checkpoint_every=30)
    again = fm.Simulation.restart(path, build)
    again.run(steps=30)
    a, b = ref.particles, again.particles
    oa, ob = np.argsort(a.id), np.argsort(b.id)
    assert np.array_equal(a.state[oa], b.state[ob])
    assert np.array_equal(a.stress[oa], b.stress[ob])
    assert not np.array_equal(a.state[oa, 1:], np.zeros_like(a.state[oa, 1:]))
    assert np.all(np.abs(a.state[oa, 0] - e_init[oa]) < 1e-3)


def test_geostatic_void_ratio_field():
    """geostatic(..., void_ratio='relative') keeps r = (e_c - e)/(e_c - e_d) = (e_c0 - e_0) /
    (e_c0 - e_d0) at every depth (eq 3.15) and sets sigma_h = (1 - sin phi_c) sigma_v."""
    sim, m = _column(MPI.COMM_WORLD, geo=True)
    p = sim.particles
    pr = -np.trace(p.stress, axis1=1, axis2=2) / 3.0
    ed, ec, _ = m.characteristic_void_ratios(pr)
    r = (ec - p.state[:, 0]) / (ec - ed)
    assert np.allclose(r, (0.84 - 0.65) / (0.84 - 0.53), rtol=1e-12)
    assert np.allclose(p.stress[:, 0, 0], 0.5 * p.stress[:, 1, 1], rtol=1e-12)


def test_bench_case_quick(tmp_path):
    """The bench case in quick mode: JSON and PNG written, numbers present."""
    from fenicsmpm.bench import hypoplastic
    comm = MPI.COMM_SELF
    doc = hypoplastic.run(quick=True, out=str(tmp_path), comm=comm, verbose=False)
    names = {r["name"] for r in doc["runs"]}
    assert {"triaxial-dense", "triaxial-loose", "biaxial-seed", "oedometer", "reversal"} <= names
    assert os.path.exists(tmp_path / "hypoplastic.json")
    assert os.path.exists(tmp_path / "hypoplastic.png")
    rev = next(r for r in doc["runs"] if r["name"] == "reversal")["metrics"]
    assert abs(rev["m_R_measured"] / 10.0 - 1) < 0.01 and abs(rev["m_T_measured"] / 2.0 - 1) < 0.01
