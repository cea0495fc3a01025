"""Element tests of MohrCoulomb and VonMises (issue 7), plus a short MPM run.

Element tests call the material methods on small arrays (identical on every MPI rank):
- drained biaxial (plane strain) compression under a constant lateral stress -p0 reaches the
  closed-form Mohr-Coulomb peak deviator (seed 002 eq 5.1 with sigma_3 = -p0)
      q_f = sigma_3 - sigma_1 = 2 (c cos(phi) + p0 sin(phi)) / (1 - sin(phi))
  within 1 %; with softening, q follows q_f(phi(eps_d^p), c(eps_d^p)) with
  x = x_res + (x_peak - x_res) exp(-eta eps_d^p) (seed 003) and eps_d^p computed here from the
  total and elastic strains, within 1 %;
- random trial states returned to the plane, edges and apex satisfy f <= 1e-8 |sigma|;
- the consistent tangent equals a central difference of stress() to 1e-6 relative;
- psi = 0 leaves the mean stress of the predictor unchanged (zero plastic volume change);
- von Mises in simple shear follows tau = c(eps_p) = max(c_res, c_u + H eps_p) (seed 000
  ch. 5), eps_p = gamma_p / sqrt(3) from the elastic-plastic split, within 1 %;
- bad parameters raise ValueError naming the parameter.
"""
import math

import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenicsmpm as fm

E, NU, RHO = 20e6, 0.3, 2000.0


def _run(mat, dF, s0, st0):
    """stress() on all rows: (sigma_new, trial history)."""
    n = len(dF)
    out = np.zeros((n, 3, 3))
    st = st0.copy()
    mat.stress(np.arange(n), dF, None, s0, out, st)
    return out, st


def _predictor(mat, dF, s0):
    out = np.zeros((len(dF), 3, 3))
    fm.LinearElastic(mat.E, mat.nu, mat.density).stress(np.arange(len(dF)), dF, None, s0, out,
                                                        None)
    return out


def _mc_f(sig, phi_deg, c):
    """Seed 002 eq 5.1 on the principal stresses (ascending, tension positive)."""
    w = np.linalg.eigvalsh(sig)
    ph = np.radians(phi_deg)
    return 0.5 * (w[:, 2] - w[:, 0]) + 0.5 * (w[:, 0] + w[:, 2]) * np.sin(ph) - c * np.cos(ph)


def _classify(sig_tr, sig):
    """'elastic', 'plane', 'edge' (two equal principal stresses) or 'apex' per row."""
    w = np.linalg.eigvalsh(sig)
    tol = 1e-9 * np.abs(w).max(axis=1)
    gap_lo, gap_hi = w[:, 1] - w[:, 0], w[:, 2] - w[:, 1]
    kind = np.where((gap_lo < tol) & (gap_hi < tol), "apex",
                    np.where((gap_lo < tol) | (gap_hi < tol), "edge", "plane"))
    elastic = np.abs(sig - sig_tr).max(axis=(1, 2)) <= 1e-12 * np.abs(sig_tr).max(axis=(1, 2))
    return np.where(elastic, "elastic", kind)


def _random_states(n, seed, strain=1e-3, stress=2e4):
    rng = np.random.default_rng(seed)
    s0 = rng.normal(size=(n, 3, 3)) * stress
    shift = rng.uniform(-4.0, 0.5, n) * stress
    s0 = 0.5 * (s0 + s0.transpose(0, 2, 1)) + shift[:, None, None] * np.eye(3)
    return s0, np.eye(3) + rng.normal(size=(n, 3, 3)) * strain


def _elastic_start(mat, s0):
    """Scale the initial stresses into the yield surface (so sigma_old is admissible)."""
    f = _mc_f(s0, mat.phi, mat.c)
    w = np.linalg.eigvalsh(s0)
    ok = (f < 0) & (w[:, 2] < (np.inf if mat.tension_cutoff is None else mat.tension_cutoff))
    return s0[ok]


MC_CASES = {
    "assoc-ish": dict(phi=30.0, c=10e3, psi=10.0),
    "psi0-cutoff": dict(phi=30.0, c=10e3, psi=0.0, tension_cutoff=5e3),
    "softening": dict(phi=35.0, c=8e3, psi=5.0, phi_res=25.0, c_res=2e3, eta=30.0),
}


def _biaxial(mat, p0, axial=-2e-2, steps=200):
    """Plane-strain biaxial compression: h_yy prescribed, h_zz = 0, h_xx found by Newton on
    the consistent tangent so that sigma_xx = -p0.  Returns per-step (sigma, state, eps)."""
    sig = -p0 * np.eye(3)[None].copy()
    st = np.zeros((1, mat.n_state))
    eps = np.zeros(3)
    out = []
    for _ in range(steps):
        dF = np.eye(3)[None].copy()
        dF[0, 1, 1] += axial / steps
        for _it in range(30):
            new, st_new = _run(mat, dF, sig, st)
            r = new[0, 0, 0] + p0
            if abs(r) < 1e-10 * p0:
                break
            ds = np.zeros((1, 3, 3, 3, 3))
            mat.tangent([0], dF, None, sig, None, st, ds)
            dF[0, 0, 0] -= r / ds[0, 0, 0, 0, 0]
        assert abs(r) < 1e-10 * p0, f"lateral stress control did not converge: {r}"
        eps += np.diag(dF[0]) - 1.0
        sig, st = new, st_new
        out.append((sig[0].copy(), st[0].copy(), eps.copy()))
    return out


def _q_peak(phi_deg, c, p0):
    s = math.sin(math.radians(phi_deg))
    return 2.0 * (c * math.cos(math.radians(phi_deg)) + p0 * s) / (1.0 - s)


@pytest.mark.parametrize("phi,c,psi,p0", [(30.0, 10e3, 0.0, 50e3), (20.0, 5e3, 10.0, 100e3),
                                          (42.0, 1e3, 0.0, 20e3)])
def test_biaxial_peak_deviator(phi, c, psi, p0):
    mat = fm.MohrCoulomb(E=E, nu=NU, density=RHO, phi=phi, c=c, psi=psi)
    path = _biaxial(mat, p0)
    q = np.array([s[0, 0] - s[1, 1] for s, _, _ in path])
    qf = _q_peak(phi, c, p0)
    assert abs(q.max() / qf - 1) < 0.01, f"peak deviator {q.max():.6g} vs closed form {qf:.6g}"
    assert abs(q[-1] / qf - 1) < 0.01, f"final deviator {q[-1]:.6g} vs closed form {qf:.6g}"
    sig, st, _ = path[-1]
    assert st[0] > 0, "no plastic strain at the end of the test"
    assert sig[1, 1] < sig[2, 2] < sig[0, 0], "sigma_zz is not the intermediate stress"
    # elastic start: plane-strain axial modulus E / (1 - nu^2) until yield
    s1, _, e1 = path[0]
    assert abs((s1[0, 0] - s1[1, 1]) / (-e1[1] * E / (1 - NU ** 2)) - 1) < 1e-6


def test_biaxial_softening_follows_exponential_law():
    """phi, c = x_res + (x_peak - x_res) exp(-eta eps_d^p): the deviator of each plastic step
    equals q_f(phi(eps_d^p), c(eps_d^p)), eps_d^p = sqrt(2/3) |dev eps^p| from the strains."""
    kw = dict(phi=35.0, c=8e3, psi=0.0, phi_res=25.0, c_res=2e3, eta=80.0)
    mat = fm.MohrCoulomb(E=E, nu=NU, density=RHO, **kw)
    p0 = 40e3
    path = _biaxial(mat, p0, axial=-0.1, steps=400)
    lam, mu = mat.lame_lambda, mat.shear_modulus
    worst_q, worst_k, n_plastic = 0.0, 0.0, 0
    for sig, st, eps in path:
        # total strain (xx, yy, zz); elastic part from the stress change; plastic = rest
        ds = np.diag(sig) + p0
        e_el = (ds - lam / (3 * lam + 2 * mu) * ds.sum()) / (2 * mu)
        ep = eps - e_el
        kappa = math.sqrt(2 / 3) * np.linalg.norm(ep - ep.mean())
        if kappa < 1e-6:
            continue
        n_plastic += 1
        e = math.exp(-kw["eta"] * kappa)
        phi = kw["phi_res"] + (kw["phi"] - kw["phi_res"]) * e
        c = kw["c_res"] + (kw["c"] - kw["c_res"]) * e
        qf = _q_peak(phi, c, p0)
        worst_q = max(worst_q, abs((sig[0, 0] - sig[1, 1]) / qf - 1))
        worst_k = max(worst_k, abs(st[0] / kappa - 1))
        assert abs(ep.sum()) < 1e-12, "psi = 0: plastic volume change"
    q = [s[0, 0] - s[1, 1] for s, _, _ in path]
    assert n_plastic > 300
    assert worst_q < 0.01, f"deviator off the softening curve by {100 * worst_q:.4f} %"
    assert worst_k < 1e-6, f"state eps_d^p off the strain-based value by {worst_k:.3g}"
    assert abs(max(q) / _q_peak(35.0, 8e3, p0) - 1) < 0.01
    assert abs(q[-1] / _q_peak(25.0, 2e3, p0) - 1) < 0.01, "residual strength not reached"


@pytest.mark.parametrize("case", list(MC_CASES))
def test_return_satisfies_yield(case):
    mat = fm.MohrCoulomb(E=E, nu=NU, density=RHO, **MC_CASES[case])
    s0, dF = _random_states(4000, seed=1, strain=3e-3)
    s0 = _elastic_start(mat, s0)
    dF = dF[:len(s0)]
    st0 = np.zeros((len(s0), mat.n_state))
    sig, st = _run(mat, dF, s0, st0)
    kinds = _classify(_predictor(mat, dF, s0), sig)
    counts = dict(zip(*np.unique(kinds, return_counts=True)))
    for k in ("elastic", "plane", "edge", "apex"):
        assert counts.get(k, 0) >= 10, f"too few {k} returns: {counts}"
    phi, c = mat.strength(st[:, 0])
    f = _mc_f(sig, phi, c)
    size = np.abs(sig).max(axis=(1, 2))
    assert np.all(f <= 1e-8 * size), f"max f/|sigma| = {np.max(f / size):.3g}"
    # plastic rows lie on the MC surface or on the cut-off sigma_3 = sigma_t
    s3 = np.linalg.eigvalsh(sig)[:, 2]
    on_t = np.abs(s3 - (mat.tension_cutoff or np.inf)) <= 1e-8 * size
    pl = kinds != "elastic"
    assert np.all((np.abs(f) <= 1e-8 * size)[pl] | on_t[pl])
    if mat.tension_cutoff is not None:
        assert np.all(s3 <= mat.tension_cutoff + 1e-8 * size)
        assert np.count_nonzero(on_t & pl) >= 10, "too few returns to the tension cut-off"


def test_psi_zero_no_plastic_volume_change():
    """psi = 0: every plane/edge return keeps the predictor's mean stress (tr eps^p = 0) and
    the volumetric history stays 0; psi > 0 dilates with tr eps^p = (p_tr - p) / K."""
    s0, dF = _random_states(3000, seed=2)
    for psi in (0.0, 10.0):
        mat = fm.MohrCoulomb(E=E, nu=NU, density=RHO, phi=30.0, c=10e3, psi=psi)
        s0m = _elastic_start(mat, s0)
        dFm = dF[:len(s0m)]
        sig, st = _run(mat, dFm, s0m, np.zeros((len(s0m), mat.n_state)))
        tr_ = _predictor(mat, dFm, s0m)
        kinds = _classify(tr_, sig)
        sel = (kinds == "plane") | (kinds == "edge")
        assert np.count_nonzero(sel) > 100
        dp = (np.trace(tr_, axis1=1, axis2=2) - np.trace(sig, axis1=1, axis2=2)) / 3
        scale = np.abs(tr_).max(axis=(1, 2))
        if psi == 0.0:
            assert np.all(np.abs(dp[sel]) <= 1e-10 * scale[sel])
            assert np.all(np.abs(st[sel, 1]) <= 1e-15)
        else:
            assert np.allclose(st[sel, 1], dp[sel] / mat.bulk_modulus, rtol=1e-8, atol=0)
            assert np.all(st[sel, 1] > 0), "psi > 0 must dilate"


def test_faint_deviator_is_elastic_not_a_division_by_zero():
    """A strain increment of 1e-118 (the faint front of a wave crossing a resting far field)
    on a hydrostatic state: q2^1.5 of the trial deviator underflows to 0; the elastic check
    (its closed-form eigenvalues) takes the state as hydrostatic instead of dividing by it
    (a ZeroDivisionError in the 2026-12-04 Mohr-Coulomb footing on a 10 m x 4 m domain)."""
    mat = fm.MohrCoulomb(E=E, nu=NU, density=RHO, phi=30.0, c=10e3, psi=30.0)
    s0 = np.zeros((3, 3, 3))
    s0[:] = -5e3 * np.eye(3)
    s0[2] = 0.0                                    # stress-free too
    dF = np.repeat(np.eye(3)[None], 3, axis=0)
    dF[:, 0, 1] = 1e-118
    dF[1, 0, 0] += 1e-118
    sig, st = _run(mat, dF, s0, np.zeros((3, mat.n_state)))
    assert np.array_equal(sig, _predictor(mat, dF, s0)) and np.all(st == 0.0)


def _fd_tangent(mat, dF, s0, st0, rows, h=1e-7):
    worst = 0.0
    ds = np.zeros((len(dF), 3, 3, 3, 3))
    mat.tangent(np.asarray(rows), dF, None, s0, None, st0, ds)
    for p in rows:
        fd = np.zeros((3, 3, 3, 3))
        for k in range(3):
            for l in range(3):
                dp, dm = dF[p:p + 1].copy(), dF[p:p + 1].copy()
                dp[0, k, l] += h
                dm[0, k, l] -= h
                fd[:, :, k, l] = (_run(mat, dp, s0[p:p + 1], st0[p:p + 1])[0]
                                  - _run(mat, dm, s0[p:p + 1], st0[p:p + 1])[0])[0] / (2 * h)
        worst = max(worst, np.abs(fd - ds[p]).max() / np.abs(ds[p]).max())
    return worst


@pytest.mark.parametrize("case", list(MC_CASES))
@pytest.mark.parametrize("kind", ["elastic", "plane", "edge"])
def test_mc_consistent_tangent(case, kind):
    mat = fm.MohrCoulomb(E=E, nu=NU, density=RHO, **MC_CASES[case])
    s0, dF = _random_states(2000, seed=3)
    s0 = _elastic_start(mat, s0)
    dF = dF[:len(s0)]
    st0 = np.zeros((len(s0), mat.n_state))
    st0[:, 0] = 0.01 if mat.eta > 0 else 0.0
    sig, _ = _run(mat, dF, s0, st0)
    rows = np.flatnonzero(_classify(_predictor(mat, dF, s0), sig) == kind)[:8]
    assert len(rows) >= 3
    err = _fd_tangent(mat, dF, s0, st0, rows)
    assert err < 1e-6, f"{case}/{kind}: tangent vs central difference, rel. error {err:.3g}"


VM = dict(E=2e6, nu=0.41, density=1000.0, c_u=10e3, c_res=3e3, H=-140e3)   # seed 000 ch. 5


@pytest.mark.parametrize("branch", ["elastic", "softening", "residual"])
def test_vm_consistent_tangent(branch):
    mat = fm.VonMises(**VM)
    rng = np.random.default_rng(4)
    n = 300
    s0 = rng.normal(size=(n, 3, 3)) * 3e3
    s0 = 0.5 * (s0 + s0.transpose(0, 2, 1))
    dF = np.eye(3) + rng.normal(size=(n, 3, 3)) * 5e-3
    st0 = np.abs(rng.normal(size=(n, 1))) * 0.03
    sig, st = _run(mat, dF, s0, st0)
    plastic = st[:, 0] > st0[:, 0]
    on_res = mat.c_u + mat.H * st[:, 0] < mat.c_res
    sel = {"elastic": ~plastic, "softening": plastic & ~on_res,
           "residual": plastic & on_res}[branch]
    rows = np.flatnonzero(sel)[:8]
    assert len(rows) >= 3
    err = _fd_tangent(mat, dF, s0, st0, rows)
    assert err < 1e-6, f"{branch}: tangent vs central difference, rel. error {err:.3g}"


def test_vm_simple_shear_softening_curve():
    """dF = I + dgamma e_x (x) e_y: tau = c(eps_p), eps_p = (gamma - tau/G)/sqrt(3), within 1 %,
    from the peak c_u = 10 kPa down to c_res = 3 kPa (seed 000: H = -140 kPa)."""
    mat = fm.VonMises(**VM)
    G = mat.shear_modulus
    sig = np.zeros((1, 3, 3))
    st = np.zeros((1, 1))
    dF = np.eye(3)[None].copy()
    dg = 2e-4
    dF[0, 0, 1] = dg
    gamma, worst, taus, eps = 0.0, 0.0, [], []
    for _ in range(800):
        sig, st = _run(mat, dF, sig, st)
        gamma += dg
        tau = sig[0, 0, 1]
        ep = (gamma - tau / G) / math.sqrt(3.0)
        taus.append(tau)
        eps.append(ep)
        if ep > 1e-4:
            expected = max(VM["c_res"], VM["c_u"] + VM["H"] * ep)
            worst = max(worst, abs(tau / expected - 1))
            assert abs(st[0, 0] / ep - 1) < 0.01
    assert max(eps) > 0.06, "the test must reach the residual branch"
    assert worst < 0.01, f"tau off the c(eps_p) curve by {100 * worst:.3f} %"
    assert abs(max(taus) / VM["c_u"] - 1) < 0.01
    assert abs(taus[-1] / VM["c_res"] - 1) < 0.01


def test_strength_reduction():
    mat = fm.MohrCoulomb(E=E, nu=NU, density=RHO, phi=30.0, c=10e3, psi=10.0, phi_res=20.0,
                         c_res=4e3, eta=5.0)
    r = mat.reduced(1.5)
    assert math.isclose(math.tan(math.radians(r.phi)), math.tan(math.radians(30.0)) / 1.5)
    assert math.isclose(math.tan(math.radians(r.phi_res)), math.tan(math.radians(20.0)) / 1.5)
    assert math.isclose(r.c, 10e3 / 1.5) and math.isclose(r.c_res, 4e3 / 1.5)
    assert r.psi == 10.0 and r.eta == 5.0 and r.E == E
    assert math.isclose(mat.reduced(3.0).psi, mat.reduced(3.0).phi_res)   # psi capped
    with pytest.raises(ValueError, match="factor"):
        mat.reduced(0.0)


BASE = dict(E=E, nu=NU, density=RHO)


@pytest.mark.parametrize("cls,kw,match", [
    (fm.MohrCoulomb, dict(phi=90.0, c=1.0), "'phi'.*90.0"),
    (fm.MohrCoulomb, dict(phi=-1.0, c=1.0), "'phi'.*-1.0"),
    (fm.MohrCoulomb, dict(phi=30.0, c=-5.0), "'c'.*-5.0"),
    (fm.MohrCoulomb, dict(phi=0.0, c=0.0), "'c'"),
    (fm.MohrCoulomb, dict(phi=30.0, c=1.0, psi=31.0), "'psi'.*31.0"),
    (fm.MohrCoulomb, dict(phi=30.0, c=1.0, psi=-1.0), "'psi'.*-1.0"),
    (fm.MohrCoulomb, dict(phi=30.0, c=1.0, psi=25.0, phi_res=20.0), "'psi'.*25.0"),
    (fm.MohrCoulomb, dict(phi=30.0, c=1.0, phi_res=35.0), "'phi_res'.*35.0"),
    (fm.MohrCoulomb, dict(phi=30.0, c=1.0, c_res=2.0), "'c_res'.*2.0"),
    (fm.MohrCoulomb, dict(phi=30.0, c=1.0, c_res=-1.0), "'c_res'.*-1.0"),
    (fm.MohrCoulomb, dict(phi=30.0, c=1.0, eta=-0.5), "'eta'.*-0.5"),
    (fm.MohrCoulomb, dict(phi=30.0, c=1.0, tension_cutoff=-1.0), "'tension_cutoff'.*-1.0"),
    (fm.MohrCoulomb, dict(phi=30.0, c=1.0, phi_res=0.0, c_res=0.0), "'c_res'"),
    (fm.MohrCoulomb, dict(phi=float("nan"), c=1.0), "'phi'"),
    (fm.VonMises, dict(c_u=0.0), "'c_u'.*0.0"),
    (fm.VonMises, dict(c_u=10.0, c_res=12.0), "'c_res'.*12.0"),
    (fm.VonMises, dict(c_u=10.0, c_res=-1.0), "'c_res'.*-1.0"),
    (fm.VonMises, dict(c_u=10.0, H=5.0), "'H'.*5.0"),
    (fm.VonMises, dict(c_u=10.0, H=-1e9), "'H'"),
])
def test_bad_parameters(cls, kw, match):
    with pytest.raises(ValueError, match=match):
        cls(**BASE, **kw)


def _sliding_block(comm):
    """A weak MC block (phi = 20 deg, c = 200 Pa) sliding at 1 m/s over a fixed base under
    gravity; 40 explicit MUSL steps (about 0.15 m of travel, several cells)."""
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [2.0, 0.5]], [32, 8],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    mat = fm.MohrCoulomb(E=1e5, nu=0.3, density=RHO, phi=20.0, c=200.0)
    p = fm.Particles.fill(grid, mat, per_cell=2,
                          region=lambda x: (x[:, 0] > 0.6) & (x[:, 0] < 1.1) & (x[:, 1] < 0.3),
                          velocity=(1.0, 0.0))
    sim = fm.Simulation(grid, p, fm.Explicit("MUSL"), dt="auto", gravity=(0.0, -9.81))
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0), [0, 1])
    return sim


def test_mohr_coulomb_block_under_gravity_migrates_history():
    """Serial (COMM_SELF) and distributed runs give the same history per particle id, the
    state stays finite, plastic strain develops, and (in parallel) particles change rank."""
    comm = MPI.COMM_WORLD
    ref = _sliding_block(MPI.COMM_SELF)
    sim = _sliding_block(comm)
    p = sim.particles
    ids0 = set(p.id.tolist())
    m0 = p.total(p.mass)
    ref.run(steps=40)
    sim.run(steps=40)
    assert np.all(np.isfinite(p.state)) and np.all(np.isfinite(p.stress))
    assert math.isclose(p.total(p.mass), m0, rel_tol=1e-12)
    kmax = comm.allreduce(float(p.state[:, 0].max(initial=0.0)), op=MPI.MAX)
    assert kmax > 1e-4, f"max eps_d^p = {kmax:.3g}: no plasticity"
    # match particles by their initial position x - u (ids are numbered per partition)
    r = ref.particles
    key_r, key_p = np.round((r.x - r.u) * 1e6), np.round((p.x - p.u) * 1e6)
    index = {tuple(k): i for i, k in enumerate(key_r)}
    lo = np.array([index[tuple(k)] for k in key_p], dtype=np.int64)
    diff = comm.allreduce(float(np.abs(r.state[lo] - p.state).max(initial=0.0)), op=MPI.MAX)
    assert diff <= 1e-8 * kmax, f"history differs from the serial run by {diff:.3g}"
    moved = comm.allreduce(len(set(p.id.tolist()) - ids0))
    if comm.size > 1:
        assert moved > 0, "no particle changed rank: migration of the history is not exercised"


def _iso(e):
    """An isotropic stretch of volumetric strain e, as a (1, 3, 3) dF."""
    return (1.0 + e / 3.0) * np.eye(3)[None]


def _pulled_apart(c, **options):
    """A phi = 30 deg Mohr-Coulomb particle (cohesion c, `options`) opened by 10 x 1e-3
    volumetric strain from a stress-free state; asserts it sits at the apex. Returns (mat,
    apex stress, bulk modulus K, sigma, history)."""
    mat = fm.MohrCoulomb(E=10e6, nu=0.3, density=1500.0, phi=30.0, c=c, **options)
    apex = c / np.tan(np.radians(30.0))
    K = mat.lame_lambda + 2.0 * mat.shear_modulus / 3.0
    sig, st = np.zeros((1, 3, 3)), np.zeros((1, mat.n_state))
    for _ in range(10):
        sig, st = _run(mat, _iso(1e-3), sig, st)
    assert np.allclose(sig[0], apex * np.eye(3), atol=1e-9 * max(apex, 1.0))
    return mat, apex, K, sig, st


@pytest.mark.parametrize("c", [0.0, 2e3])
def test_opened_gap_closes_without_stress(c):
    """Issue 21 item 4, MohrCoulomb(separation=True): a particle pulled apart beyond its
    strength (the apex) stores the opening as the gap g (state column 2) and carries the apex
    stress while it recompacts by up to g; only compaction beyond g is elastic:
    p = p_apex - K (eps - g), K = lambda + 2 mu / 3, exact to round-off.  (Without the gap
    the same compaction gave p = -K eps: a loose particle that had stretched to J = 38
    loaded its nodes with 38 times its volume and blew the granular collapse up.)"""
    mat, apex, K, sig, st = _pulled_apart(c, separation=True)
    assert mat.separation and "separation=True" in repr(mat) and mat.reduced(1.5).separation
    g = st[0, 2]
    assert 0.0095 < g <= 0.01                   # the opening beyond the elastic tension
    for _ in range(9):                           # close by 9e-3 < g: stress stays at the apex
        sig, st = _run(mat, _iso(-1e-3), sig, st)
        assert np.allclose(sig[0], apex * np.eye(3), atol=1e-9 * max(apex, 1.0))
    assert st[0, 2] == pytest.approx(g - 9e-3, abs=1e-15)
    sig, st = _run(mat, _iso(-2e-3), sig, st)     # closes g, then compacts elastically
    assert st[0, 2] == 0.0
    p = np.trace(sig[0]) / 3.0
    assert p == pytest.approx(apex - K * (2e-3 - (g - 9e-3)), rel=1e-12)


@pytest.mark.parametrize("c", [0.0, 2e3])
def test_without_separation_compaction_loads_at_once(c):
    """MohrCoulomb's default (separation=False): the same opening leaves no gap (state
    column 2 stays 0), so the first compaction is elastic from the apex: p = p_apex - K eps,
    exact to round-off."""
    mat, apex, K, sig, st = _pulled_apart(c)
    assert not mat.separation and "separation" not in repr(mat)
    assert not mat.reduced(1.5).separation
    assert st[0, 2] == 0.0 and st[0, 1] > 0.0095          # plastic opening, but no gap
    sig, st = _run(mat, _iso(-1e-3), sig, st)
    assert st[0, 2] == 0.0
    assert np.trace(sig[0]) / 3.0 == pytest.approx(apex - K * 1e-3, rel=1e-12)


@pytest.mark.parametrize("bad", [1, "no", None])
def test_separation_is_checked(bad):
    with pytest.raises(ValueError, match="'separation'"):
        fm.MohrCoulomb(E=10e6, nu=0.3, density=1500.0, phi=30.0, c=0.0, separation=bad)
