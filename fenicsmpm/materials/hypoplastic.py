"""Hypoplastic sand: von Wolffersdorff (1996) with the intergranular strain of Niemunis & Herle
(1997), seed 004 ch. 3 (eqs 3.1-3.23, 3.25, 3.29-3.30).  Tension positive, stresses in Pa.

Rate equation (objective Jaumann rate, seed eqs 3.1-3.4, 3.21-3.22):
    sigma° = M : D,    e' = (1 + e) tr D                                            (3.2)
    hypoplastic part   L : D + N ||D||
        L = f_b f_e / (s:s) (F^2 I + a^2 s (x) s)                                    (3.5)
        N = f_d f_b f_e a F / (s:s) (s + s*)                                          (3.6)
        s = sigma_t / tr sigma_t,  s* = s - I/3,  sigma_t = sigma - p_t I             (3.7-3.8)
        a = sqrt(3) (3 - sin phi_c) / (2 sqrt(2) sin phi_c)                          (3.9)
        F = sqrt(tan^2 psi / 8 + (2 - tan^2 psi) / (2 + sqrt(2) tan psi cos 3theta))
            - tan psi / (2 sqrt(2)),   tan psi = sqrt(3) ||s*||                       (3.10, 3.12)
        cos 3theta = -sqrt(6) tr(s*^3) / (s*:s*)^(3/2)                                (3.11)
        f_e = (e_c / e)^beta,  f_d = ((e - e_d) / (e_c - e_d))^alpha (0 for e < e_d)  (3.13)
        f_b = h_s/n (1 + e_i)/e_i (e_i0/e_c0)^beta (-tr sigma_t / h_s)^(1 - n)
              / [3 + a^2 - sqrt(3) a ((e_i0 - e_d0)/(e_c0 - e_d0))^alpha]             (3.14)
        e_i/e_i0 = e_c/e_c0 = e_d/e_d0 = exp(-(-tr sigma_t / h_s)^n)                  (3.15)
    intergranular strain delta, rho = min(||delta|| / R, 1), d = delta / ||delta||:
        delta' = (I - rho^beta_r d (x) d) : D  if d:D > 0,  D otherwise               (3.18)
        M = [rho^chi m_T + (1 - rho^chi) m_R] L
            + rho^chi (1 - m_T) (L:d) (x) d + rho^chi N (x) d   if d:D > 0
            + rho^chi (m_R - m_T) (L:d) (x) d                  if d:D <= 0             (3.22)
Printed errors of seed 004 corrected here against von Wolffersdorff (1996), Niemunis & Herle
(1997) and the public soilmodels.info UMAT (Gudehus et al. 2008; Masin, Tamagnini, Sellari; the
copy in Kratos' UmatApplication): eq 3.5 reads a^2 s_ij s_kl (not s_ik s_jl); eq 3.10 has tan psi/(2 sqrt 2)
outside the root; eq 3.12 uses the deviator s*; eq 3.16 reads (s + s*); eq 3.23 reads
N_ij d_kl (not N_ik d_jl).  m_R and m_T are input parameters (eq 3.24 is a clay formula; eq
3.25 parametrises m_T by a ratio); rho is capped at 1 as in the UMAT; for E_c of eq 3.30 see
Hypoplastic.constrained_modulus.

Units: h_s and p_t in Pa (the seed's Table 3.1 is in kPa: h_s = 5.8E6 kPa = 5.8e9 Pa,
p_t = 1.6 kPa = 1600 Pa).

Stress-free and tension states (the rule at p -> 0): the model sees the shifted stress
sigma_t = sigma - p_t I (the UMAT's cohesion shift).  A state is admissible when every principal
value of sigma_t is <= -p_min / 2 (compression); there L, N and F are finite.  A stress that
enters a step outside this set, and any sub-step that would leave the admissible set once the sub-step size has
been cut to h_min = 1e-4 of the step (the rest of the step is then one explicit Euler step), is
projected: principal values of sigma_t are capped at -p_min
(eigenvectors kept), i.e. sigma_i <= p_t - p_min.  A granular body pulled apart therefore sits at
the isotropic state sigma = (p_t - p_min) I and carries no shear, and no NaN arises.
Default p_min = p_t / 4 (the UMAT's `minstress`).

Integration (per particle, over one step with D = sym(dF - I) at constant rate): adaptive
explicit Runge-Kutta 2(3) with local extrapolation (the RKF23 of the UMAT, Tamagnini, Sellari &
Miriano 2005): k1 = f(y), k2 = f(y + h/2 k1), k3 = f(y - h k1 + 2 h k2), y_2 = y + h k2,
y_3 = y + h (k1 + 4 k2 + k3) / 6, error max(||dsigma|| / max(||sigma_t||, p_min), ||ddelta|| / R)
against `tol`, next h = 0.9 h (tol / err)^(1/3) within [h/4, 4h]; the void ratio is exact,
1 + e(t) = (1 + e_n) exp(t tr D).  The Jaumann terms omega sigma_n - sigma_n omega (and likewise
for delta) are added as in LinearElastic.  The tangent for implicit runs is numerical: central
differences of the integrated update with the sub-step sizes of the unperturbed increment.

History (state columns): 0 = void ratio e, 1-6 = delta_11, delta_22, delta_33, delta_12,
delta_13, delta_23.  A particle whose column 0 is still 0 (a fresh Particles set) is initialised
with (e_0, delta_0) on its first update; `set_state` and `geostatic` set fields explicitly.
"""
import math

import numba
import numpy as np

from ..kernels.threads import PRANGE, RETURN_CHUNK, chunk, particle_chunks
from .linear_elastic import strain_spin
from .validation import check_positive, check_real

__all__ = ["Hypoplastic", "geostatic", "hypoplastic_stress_kernel",
           "hypoplastic_tangent_kernel", "hypoplastic_tensors_kernel"]

STATE_COLUMNS = ("e", "delta_11", "delta_22", "delta_33", "delta_12", "delta_13", "delta_23")
_VI = np.array([0, 1, 2, 0, 0, 1], dtype=np.int64)      # state column 1 + k <-> delta[_VI, _VJ]
_VJ = np.array([0, 1, 2, 1, 2, 2], dtype=np.int64)
# parameter vector layout of the kernels
(_HS, _N, _ED0, _EC0, _EI0, _ALPHA, _BETA, _MR, _MT, _R, _BR, _CHI, _PT, _PMIN, _A,
 _FB0) = range(16)
_SQ2 = math.sqrt(2.0)
_SQ3 = math.sqrt(3.0)
_SQ6 = math.sqrt(6.0)
_HMIN = 1e-4          # sub-step (fraction of the step) below which an inadmissible stage
                      # triggers the projection rule
_HERR = 1e-12         # sub-step accepted whatever its error estimate
_MAXSUB = 4000        # sub-steps per particle and step before the remainder is projected


@numba.njit(cache=True)
def _ddot(A, B):
    """A : B of two 3 x 3 tensors."""
    s = 0.0
    for i in range(3):
        for j in range(3):
            s += A[i, j] * B[i, j]
    return s


@numba.njit(cache=True)
def _factors(s, e, par, sh):
    """Normalised stress sh = sigma_t / tr sigma_t (seed eq 3.7, sigma_t = sigma - p_t I) and
    (fs, F, f_d) with fs = f_b f_e / (sh:sh) (eqs 3.9-3.15 corrected, von Wolffersdorff 1996);
    fs = -1 when tr sigma_t >= 0 (no hypoplastic state)."""
    pt = par[_PT]
    tr = s[0, 0] + s[1, 1] + s[2, 2] - 3.0 * pt
    if not tr < 0.0:
        return -1.0, 0.0, 0.0
    for i in range(3):
        for j in range(3):
            sh[i, j] = (s[i, j] - (pt if i == j else 0.0)) / tr
    nn = _ddot(sh, sh)
    nd2 = nn - 1.0 / 3.0                       # s*:s* = s:s - 1/3 (tr s = 1)
    if nd2 < 0.0:
        nd2 = 0.0
    tpsi = _SQ3 * math.sqrt(nd2)
    c3t = -1.0
    if nd2 > 1e-24:
        t3 = 0.0                               # tr(s*^3)
        for i in range(3):
            for j in range(3):
                for k in range(3):
                    t3 += ((sh[i, j] - (1.0 / 3.0 if i == j else 0.0))
                           * (sh[j, k] - (1.0 / 3.0 if j == k else 0.0))
                           * (sh[k, i] - (1.0 / 3.0 if k == i else 0.0)))
        c3t = min(1.0, max(-1.0, -_SQ6 * t3 / nd2 ** 1.5))
    den = 2.0 + _SQ2 * tpsi * c3t
    arg = tpsi * tpsi / 8.0 + (2.0 - tpsi * tpsi) / max(den, 1e-12)
    F = math.sqrt(max(arg, 0.0)) - tpsi / (2.0 * _SQ2)
    ps = -tr / par[_HS]
    bauer = math.exp(-ps ** par[_N])
    ei, ec, ed = par[_EI0] * bauer, par[_EC0] * bauer, par[_ED0] * bauer
    fb = par[_FB0] * (1.0 + ei) / ei * ps ** (1.0 - par[_N])
    fe = (ec / e) ** par[_BETA]
    fd = ((e - ed) / (ec - ed)) ** par[_ALPHA] if e > ed else 0.0
    return fb * fe / nn, F, fd


@numba.njit(cache=True)
def _rates(s, d, e, D, par, sh, ds, dd):
    """ds = M : D (seed eqs 3.21-3.22, Niemunis & Herle 1997) and dd = delta rate
    (eq 3.18) at stress s, intergranular strain d, void ratio e; False if tr sigma_t >= 0."""
    fs, F, fd = _factors(s, e, par, sh)
    if fs < 0.0:
        return False
    a = par[_A]
    nd = math.sqrt(_ddot(d, d))
    rho = min(nd / par[_R], 1.0)
    inv = 1.0 / nd if nd > 1e-300 else 0.0
    load = _ddot(d, D) * inv                   # d_hat : D
    shD = _ddot(sh, D)
    shd = _ddot(sh, d) * inv
    rc = rho ** par[_CHI]
    c1 = rc * par[_MT] + (1.0 - rc) * par[_MR]
    if load > 0.0:
        cL = rc * (1.0 - par[_MT]) * load
        cN = rc * load
        cd = rho ** par[_BR] * load
    else:
        cL = rc * (par[_MR] - par[_MT]) * load
        cN = 0.0
        cd = 0.0
    for i in range(3):
        for j in range(3):
            dh = d[i, j] * inv
            LD = fs * (F * F * D[i, j] + a * a * sh[i, j] * shD)
            Ld = fs * (F * F * dh + a * a * sh[i, j] * shd)
            Nij = fs * fd * a * F * (sh[i, j] + sh[i, j] - (1.0 / 3.0 if i == j else 0.0))
            ds[i, j] = c1 * LD + cL * Ld + cN * Nij
            dd[i, j] = D[i, j] - cd * dh
    return True


@numba.njit(cache=True)
def _admissible(s, par):
    """True if every principal value of sigma_t = s - p_t I is below -p_min/2 (Sylvester's
    criterion on A = (p_t - p_min/2) I - s) and s is finite."""
    c = par[_PT] - 0.5 * par[_PMIN]
    a00, a11, a22 = c - s[0, 0], c - s[1, 1], c - s[2, 2]
    a01, a02, a12 = -s[0, 1], -s[0, 2], -s[1, 2]
    m2 = a00 * a11 - a01 * a01
    det = a00 * (a11 * a22 - a12 * a12) - a01 * (a01 * a22 - a12 * a02) + a02 * (a01 * a12 - a11 * a02)
    return a00 > 0.0 and m2 > 0.0 and det > 0.0


@numba.njit(cache=True)
def _project(s, par):
    """The stress-free/tension rule: principal values of sigma_t capped at -p_min, i.e.
    sigma_i <= p_t - p_min, eigenvectors kept (in place; non-finite s -> (p_t - p_min) I)."""
    cap = par[_PT] - par[_PMIN]
    finite = True
    for i in range(3):
        for j in range(3):
            finite = finite and math.isfinite(s[i, j])
    if not finite:
        for i in range(3):
            for j in range(3):
                s[i, j] = cap if i == j else 0.0
        return
    S = 0.5 * (s + s.T)
    w, V = np.linalg.eigh(S)
    for k in range(3):
        w[k] = min(w[k], cap)
    for i in range(3):
        for j in range(3):
            s[i, j] = V[i, 0] * w[0] * V[j, 0] + V[i, 1] * w[1] * V[j, 1] + V[i, 2] * w[2] * V[j, 2]


@numba.njit(cache=True)
def _cap_delta(d, R):
    """||delta|| <= R (the bound the exact flow of eq 3.18 keeps)."""
    nd = math.sqrt(_ddot(d, d))
    if nd > R:
        for i in range(3):
            for j in range(3):
                d[i, j] *= R / nd


@numba.njit(cache=True)
def _integrate(s, d, e0, D, par, tol, hseq, nfix, W):
    """Integrate sigma' = M:D, delta' = eq 3.18 over t in [0, 1] in place (s, d), with
    1 + e(t) = (1 + e0) exp(t tr D) (eq 3.2).  nfix = 0: adaptive RK2(3) (module docstring)
    recording the accepted sub-step sizes in hseq; nfix > 0: the nfix sizes given in hseq.
    Returns (number of sub-steps, number of projected sub-steps).  W: (12, 3, 3) work array."""
    k1s, k1d, k2s, k2d, k3s, k3d = W[0], W[1], W[2], W[3], W[4], W[5]
    ys, yd, hs_, hd_, sh = W[6], W[7], W[8], W[9], W[10]
    trD = D[0, 0] + D[1, 1] + D[2, 2]
    nD = math.sqrt(_ddot(D, D))
    if nD == 0.0:
        return 0, 0
    T = 0.0
    h = 1.0
    nsub = 0
    nproj = 0
    while T < 1.0 - 1e-14:
        if nfix > 0:
            if nsub >= nfix:
                break
            h = hseq[nsub]
        h = min(h, 1.0 - T)
        forced = nfix == 0 and nsub >= _MAXSUB - 1
        if forced:                     # the remainder as one projected Euler step
            h = 1.0 - T
        e1 = (1.0 + e0) * math.exp(T * trD) - 1.0
        e2 = (1.0 + e0) * math.exp((T + 0.5 * h) * trD) - 1.0
        e3 = (1.0 + e0) * math.exp((T + h) * trD) - 1.0
        ok = _rates(s, d, e1, D, par, sh, k1s, k1d) and not forced
        if ok:
            for i in range(3):
                for j in range(3):
                    ys[i, j] = s[i, j] + 0.5 * h * k1s[i, j]
                    yd[i, j] = d[i, j] + 0.5 * h * k1d[i, j]
            ok = _admissible(ys, par) and _rates(ys, yd, e2, D, par, sh, k2s, k2d)
        if ok:
            for i in range(3):
                for j in range(3):
                    ys[i, j] = s[i, j] - h * k1s[i, j] + 2.0 * h * k2s[i, j]
                    yd[i, j] = d[i, j] - h * k1d[i, j] + 2.0 * h * k2d[i, j]
            ok = _admissible(ys, par) and _rates(ys, yd, e3, D, par, sh, k3s, k3d)
        err = 0.0
        if ok:
            es = 0.0
            ed = 0.0
            sc = 0.0
            for i in range(3):
                for j in range(3):
                    hs_[i, j] = s[i, j] + h * (k1s[i, j] + 4.0 * k2s[i, j] + k3s[i, j]) / 6.0
                    hd_[i, j] = d[i, j] + h * (k1d[i, j] + 4.0 * k2d[i, j] + k3d[i, j]) / 6.0
                    es += (h * (k1s[i, j] - 2.0 * k2s[i, j] + k3s[i, j]) / 6.0) ** 2
                    ed += (h * (k1d[i, j] - 2.0 * k2d[i, j] + k3d[i, j]) / 6.0) ** 2
                    sc += (hs_[i, j] - (par[_PT] if i == j else 0.0)) ** 2
            err = max(math.sqrt(es) / max(math.sqrt(sc), par[_PMIN]),
                      math.sqrt(ed) / par[_R])
            ok = _admissible(hs_, par) and err == err
        if ok and (err <= tol or nfix > 0 or h <= _HERR):
            for i in range(3):
                for j in range(3):
                    s[i, j] = hs_[i, j]
                    d[i, j] = hd_[i, j]
            _cap_delta(d, par[_R])
        elif forced or nfix > 0 or (not ok and h <= _HMIN):
            # projection rule: the remainder of the step as one explicit Euler step (k1 from the
            # admissible start), then the cap
            if nfix == 0:
                h = 1.0 - T
            for i in range(3):
                for j in range(3):
                    s[i, j] += h * k1s[i, j]
                    d[i, j] += h * k1d[i, j]
            _project(s, par)
            _cap_delta(d, par[_R])
            nproj += 1
        else:
            h = max(0.25 * h, 0.9 * h * (tol / err) ** (1.0 / 3.0)) if ok else 0.25 * h
            continue
        if nfix == 0:
            hseq[nsub] = h
        nsub += 1
        T += h
        if nfix == 0:
            h = 4.0 * h if err == 0.0 else min(4.0 * h, 0.9 * h * (tol / err) ** (1.0 / 3.0))
    return nsub, nproj


@numba.njit(cache=True)
def _update(p, dF, sigma_old, state, par, tol, hseq, nfix, W, s, d):
    """Stress s and intergranular strain d of particle p after the increment dF (Jaumann:
    integrated M:D plus omega x - x omega with x the values at the start of the step);
    returns (e_new, sub-steps, projections)."""
    D, Om, d0 = W[11], W[12], W[13]
    strain_spin(dF, D, Om)
    for i in range(3):
        for j in range(3):
            s[i, j] = sigma_old[p, i, j]
    for k in range(6):
        d0[_VI[k], _VJ[k]] = state[p, 1 + k]
        d0[_VJ[k], _VI[k]] = state[p, 1 + k]
    for i in range(3):
        for j in range(3):
            d[i, j] = d0[i, j]
    e0 = state[p, 0]
    nproj0 = 0
    if not _admissible(s, par):
        _project(s, par)
        nproj0 = 1
    for i in range(3):            # rotation reference: the (projected) start-of-step stress
        for j in range(3):
            W[14, i, j] = s[i, j]
    nsub, nproj = _integrate(s, d, e0, D, par, tol, hseq, nfix, W)
    for i in range(3):
        for j in range(3):
            for m in range(3):
                s[i, j] += Om[i, m] * W[14, m, j] - W[14, i, m] * Om[m, j]
                d[i, j] += Om[i, m] * d0[m, j] - d0[i, m] * Om[m, j]
    _cap_delta(d, par[_R])
    e_new = (1.0 + e0) * math.exp(D[0, 0] + D[1, 1] + D[2, 2]) - 1.0
    return e_new, nsub, nproj + nproj0


@numba.njit(parallel=PRANGE, cache=True)
def hypoplastic_stress_kernel(idx, dF, sigma_old, sigma_new, state, par, tol, stats):
    """sigma_new[p] and state[p] (e, delta) after the increment dF[p] for p in idx (module
    docstring: seed 004 eqs 3.1-3.22 integrated by RK2(3)); stats += (sub-steps, projections,
    particles). Threaded over chunks of RETURN_CHUNK particles (kernels.threads); the counts
    of the chunks are added in chunk order."""
    n = idx.shape[0]
    nc = particle_chunks(n, RETURN_CHUNK)
    if nc == 1:
        _hypo_stress(idx, dF, sigma_old, sigma_new, state, par, tol, np.int64(0), n, stats)
        return
    part = np.zeros((nc, stats.shape[0]), dtype=stats.dtype)
    for c in numba.prange(nc):
        lo, hi = chunk(n, nc, c)
        _hypo_stress(idx, dF, sigma_old, sigma_new, state, par, tol, lo, hi, part[c])
    for c in range(nc):
        for k in range(stats.shape[0]):
            stats[k] += part[c, k]


@numba.njit(cache=True)
def _hypo_stress(idx, dF, sigma_old, sigma_new, state, par, tol, lo, hi, stats):
    W = np.empty((15, 3, 3))
    s = np.empty((3, 3))
    d = np.empty((3, 3))
    hseq = np.empty(_MAXSUB)
    for q in range(lo, hi):
        p = idx[q]
        e_new, nsub, nproj = _update(p, dF[p], sigma_old, state, par, tol, hseq, 0, W, s, d)
        for i in range(3):
            for j in range(3):
                sigma_new[p, i, j] = s[i, j]
        state[p, 0] = e_new
        for k in range(6):
            state[p, 1 + k] = d[_VI[k], _VJ[k]]
        stats[0] += nsub
        stats[1] += nproj
        stats[2] += 1


@numba.njit(cache=True)
def hypoplastic_tangent_kernel(idx, dF, sigma_old, state, dsig, par, tol):
    """dsig[p,i,j,k,l] = d sigma_new_ij / d dF_kl by central differences of the integrated
    update (step +-h, h = max(1e-4 ||dF - I||, 1e-9)), every perturbed run with the sub-step
    sizes of the unperturbed one, from the committed state."""
    W = np.empty((15, 3, 3))
    s = np.empty((3, 3))
    d = np.empty((3, 3))
    hseq = np.empty(_MAXSUB)
    G = np.empty((3, 3))
    sp = np.empty((3, 3))
    for q in range(idx.shape[0]):
        p = idx[q]
        for i in range(3):
            for j in range(3):
                G[i, j] = dF[p, i, j]
        nrm = 0.0
        for i in range(3):
            for j in range(3):
                nrm += (G[i, j] - (1.0 if i == j else 0.0)) ** 2
        h = max(1e-4 * math.sqrt(nrm), 1e-9)
        _, nsub, _ = _update(p, G, sigma_old, state, par, tol, hseq, 0, W, s, d)
        nfix = max(nsub, 1)
        if nsub == 0:
            hseq[0] = 1.0
        for k in range(3):
            for l in range(3):
                G[k, l] += h
                _update(p, G, sigma_old, state, par, tol, hseq, nfix, W, sp, d)
                G[k, l] -= 2.0 * h
                _update(p, G, sigma_old, state, par, tol, hseq, nfix, W, s, d)
                G[k, l] += h
                for i in range(3):
                    for j in range(3):
                        dsig[p, i, j, k, l] = (sp[i, j] - s[i, j]) / (2.0 * h)


@numba.njit(cache=True)
def hypoplastic_tensors_kernel(sigma, e, par, L, N):
    """L (n, 3, 3, 3, 3) and N (n, 3, 3) of seed eqs 3.5-3.6 (von Wolffersdorff 1996) at the
    stresses sigma (n, 3, 3) and void ratios e (n,); NaN where tr sigma_t >= 0."""
    sh = np.empty((3, 3))
    a = par[_A]
    for p in range(sigma.shape[0]):
        fs, F, fd = _factors(sigma[p], e[p], par, sh)
        for i in range(3):
            for j in range(3):
                N[p, i, j] = (fs * fd * a * F * (2.0 * sh[i, j] - (1.0 / 3.0 if i == j else 0.0))
                              if fs >= 0.0 else np.nan)
                for k in range(3):
                    for l in range(3):
                        L[p, i, j, k, l] = (fs * ((F * F if (i == k and j == l) else 0.0)
                                                  + a * a * sh[i, j] * sh[k, l])
                                            if fs >= 0.0 else np.nan)


def _range_error(name, value, rng):
    """The ValueError for a parameter outside its range (names both)."""
    return ValueError(f"Hypoplastic: parameter '{name}' must satisfy {rng}, got {value!r}")


class Hypoplastic:
    """Hypoplastic sand, von Wolffersdorff (1996) + intergranular strain (Niemunis & Herle
    1997), seed 004 eqs 3.1-3.23, 3.29-3.30 (corrected, see the module docstring).

    Parameters (SI: stresses in Pa, angles in degrees; Table 3.1 of the seed is in kPa):
        phi_c    critical friction angle, 0 < phi_c < 90
        h_s      granular hardness > 0 [Pa] (seed: 5.8E6 kPa = 5.8e9 Pa)
        n        exponent, 0 < n <= 1
        e_d0, e_c0, e_i0   void ratios at zero pressure, 0 < e_d0 < e_c0 < e_i0
        alpha >= 0, beta >= 0   pyknotropy exponents (with 3 + a^2 - sqrt(3) a
                 ((e_i0 - e_d0)/(e_c0 - e_d0))^alpha > 0 so that f_b is defined)
        m_R >= m_T >= 1   stiffness factors for 180 and 90 degree strain reversals
        R > 0    intergranular strain amplitude;  beta_r > 0, chi > 0  exponents
        p_t >= 0 tension shift [Pa] (sigma_t = sigma - p_t I); p_min > 0 the small-pressure cap
                 [Pa] (default p_t / 4; see the module docstring for the p -> 0 rule)
        density > 0 [kg/m^3];  e_0 initial void ratio, e_d0 <= e_0 <= e_i0
        delta_0  initial intergranular strain: None (0) or a symmetric 3 x 3 tensor with
                 ||delta_0|| <= R
        p_max > 0 [Pa]   mean effective stress at which `p_wave_speed` is evaluated (the largest
                 expected; default 1e6)
        tol      relative error tolerance of the RK2(3) sub-stepping, 0 < tol <= 0.1
    History: state[:, 0] = e, state[:, 1:7] = delta (11, 22, 33, 12, 13, 23).
    `stats` counts (accepted sub-steps, projections by the p -> 0 rule, particle updates) over
    all `stress` calls.
    """

    plastic = True       # flows at the critical state (shapes.choose_shape)

    name = "Hypoplastic"
    n_state = 7
    state_columns = STATE_COLUMNS

    def __init__(self, phi_c, h_s, n, e_d0, e_c0, e_i0, alpha, beta, m_R, m_T, R, beta_r, chi,
                 density, e_0, p_t=0.0, p_min=None, delta_0=None, p_max=1e6, tol=1e-4):
        o = "Hypoplastic"
        v = {k: check_real(o, k, x) for k, x in dict(
            phi_c=phi_c, h_s=h_s, n=n, e_d0=e_d0, e_c0=e_c0, e_i0=e_i0, alpha=alpha, beta=beta,
            m_R=m_R, m_T=m_T, R=R, beta_r=beta_r, chi=chi, density=density, e_0=e_0, p_t=p_t,
            p_max=p_max, tol=tol).items()}
        if not 0.0 < v["phi_c"] < 90.0:
            raise _range_error("phi_c", v["phi_c"], "0 < phi_c < 90 (degrees)")
        for k in ("h_s", "R", "beta_r", "chi", "density", "p_max"):
            check_positive(o, k, v[k])
        if not 0.0 < v["n"] <= 1.0:
            raise _range_error("n", v["n"], "0 < n <= 1")
        if not v["e_d0"] > 0.0:
            raise _range_error("e_d0", v["e_d0"], "0 < e_d0 < e_c0 < e_i0")
        if not v["e_d0"] < v["e_c0"]:
            raise _range_error("e_c0", v["e_c0"], f"e_d0 < e_c0 < e_i0 (e_d0 = {v['e_d0']!r})")
        if not v["e_c0"] < v["e_i0"]:
            raise _range_error("e_i0", v["e_i0"], f"e_i0 > e_c0 > e_d0 (e_c0 = {v['e_c0']!r})")
        for k in ("alpha", "beta", "p_t"):
            if not v[k] >= 0.0:
                raise _range_error(k, v[k], f"{k} >= 0")
        if not v["m_T"] >= 1.0:
            raise _range_error("m_T", v["m_T"], "1 <= m_T <= m_R")
        if not v["m_R"] >= v["m_T"]:
            raise _range_error("m_R", v["m_R"], f"m_R >= m_T (m_T = {v['m_T']!r})")
        if not 0.0 < v["tol"] <= 0.1:
            raise _range_error("tol", v["tol"], "0 < tol <= 0.1")
        if not v["e_d0"] <= v["e_0"] <= v["e_i0"]:
            raise _range_error("e_0", v["e_0"], f"e_d0 <= e_0 <= e_i0 ([{v['e_d0']!r}, "
                               f"{v['e_i0']!r}] at zero pressure)")
        if p_min is None:
            v["p_min"] = 0.25 * v["p_t"]
            if v["p_min"] == 0.0:
                raise ValueError("Hypoplastic: parameter 'p_min' must be > 0: give p_t > 0 "
                                 "(p_min defaults to p_t / 4) or p_min explicitly")
        else:
            v["p_min"] = check_positive(o, "p_min", p_min)
        sphi = math.sin(math.radians(v["phi_c"]))
        a = _SQ3 * (3.0 - sphi) / (2.0 * _SQ2 * sphi)
        den = 3.0 + a * a - _SQ3 * a * ((v["e_i0"] - v["e_d0"]) / (v["e_c0"] - v["e_d0"])) ** v["alpha"]
        if not den > 0.0:
            raise _range_error("alpha", v["alpha"], "3 + a^2 - sqrt(3) a ((e_i0 - e_d0)/(e_c0 - "
                               f"e_d0))^alpha > 0 (f_b of eq 3.14 defined; here {den:.4g})")
        if delta_0 is None:
            d0 = np.zeros((3, 3))
        else:
            d0 = np.asarray(delta_0, dtype=np.float64)
            if d0.shape != (3, 3) or not np.all(np.isfinite(d0)) or not np.allclose(d0, d0.T):
                raise ValueError(f"Hypoplastic: parameter 'delta_0' must be a finite symmetric "
                                 f"3 x 3 tensor, got {delta_0!r}")
            if np.linalg.norm(d0) > v["R"] * (1.0 + 1e-12):
                raise _range_error("delta_0", f"||delta_0|| = {np.linalg.norm(d0):.4g}",
                                   f"||delta_0|| <= R = {v['R']!r}")
        self.params = v
        self.delta_0 = d0
        self._density = v["density"]
        self.a = a
        fb0 = v["h_s"] / v["n"] * (v["e_i0"] / v["e_c0"]) ** v["beta"] / den
        self._par = np.array([v["h_s"], v["n"], v["e_d0"], v["e_c0"], v["e_i0"], v["alpha"],
                              v["beta"], v["m_R"], v["m_T"], v["R"], v["beta_r"], v["chi"],
                              v["p_t"], v["p_min"], a, fb0])
        self.tol = v["tol"]
        self.stats = np.zeros(3, dtype=np.int64)    # sub-steps, projections, particle updates

    def __getattr__(self, name):
        """The validated parameters as attributes (m.phi_c, m.R, m.p_t, ...)."""
        params = self.__dict__.get("params", {})
        if name in params:
            return params[name]
        raise AttributeError(name)

    @property
    def density(self):
        """Mass density [kg/m^3]."""
        return self._density

    @property
    def M_c(self):
        """Critical stress ratio q/p in triaxial compression, 6 sin phi_c / (3 - sin phi_c)."""
        s = math.sin(math.radians(self.params["phi_c"]))
        return 6.0 * s / (3.0 - s)

    def characteristic_void_ratios(self, p):
        """(e_d, e_c, e_i) at mean effective stress p [Pa] (seed eq 3.15 with -tr sigma_t =
        3 (p + p_t))."""
        v = self.params
        b = np.exp(-(3.0 * (np.asarray(p, dtype=float) + v["p_t"]) / v["h_s"]) ** v["n"])
        return v["e_d0"] * b, v["e_c0"] * b, v["e_i0"] * b

    def check_void_ratio(self, e, p, name="e_0"):
        """ValueError unless e_d(p) <= e <= e_i(p) (eq 3.15) for every pair (e, p [Pa])."""
        e, p = np.broadcast_arrays(np.asarray(e, dtype=float), np.asarray(p, dtype=float))
        ed, _, ei = self.characteristic_void_ratios(p)
        bad = np.ravel(~((e >= ed * (1.0 - 1e-12)) & (e <= ei * (1.0 + 1e-12))))
        if np.any(bad):
            k = np.flatnonzero(bad)[0]
            raise ValueError(f"Hypoplastic: parameter '{name}' must satisfy e_d(p) <= {name} <= "
                             f"e_i(p) = [{np.ravel(ed)[k]:.4g}, {np.ravel(ei)[k]:.4g}] at p = "
                             f"{np.ravel(p)[k]:.4g} Pa, got {np.ravel(e)[k]!r}")

    def constrained_modulus(self, p, e=None):
        """E_c of seed eqs 3.26-3.30 at isotropic stress p [Pa] (sigma_t = -(p + p_t) I):
        L = f_b f_e (3 + a^2/3); the largest branch of eq 3.30 is m_R L (rho = 0, or any 180
        degree reversal); loading at rho = 1 gives L - N with N = a f_b f_d f_e (eq 3.29: the
        '+ rho^chi N' printed in eq 3.30 carries the sign of the tension-positive N of eq 3.6
        for D = -e_yy).  e: None for the stiffest admissible state e = e_d(p)."""
        v = self.params
        ps = 3.0 * (p + v["p_t"]) / v["h_s"]
        ed, ec, ei = self.characteristic_void_ratios(p)
        e = ed if e is None else e
        fb = self._par[_FB0] * (1.0 + ei) / ei * ps ** (1.0 - v["n"])
        return v["m_R"] * fb * (ec / e) ** v["beta"] * (3.0 + self.a ** 2 / 3.0)

    @property
    def p_wave_speed(self):
        """c_p = sqrt(E_c / rho) with E_c of eq 3.30 at p = p_max and e = e_d(p_max) (an upper
        bound over the void ratios).  At anisotropic stress L_2222 can exceed the isotropic value
        (by ~1.6 at sigma_1/sigma_3 = 3); the explicit cfl < 1 is the margin for that."""
        return float(math.sqrt(self.constrained_modulus(self.params["p_max"]) / self._density))

    def state_p_wave_speed(self, stress):
        """The same bound at the largest mean effective stress p = -tr(sigma)/3 of `stress`
        (n, 3, 3) when it exceeds p_max (the state outgrew the p_wave_speed that dt="auto" used;
        guards.check_wave_speed warns), else p_wave_speed."""
        p = float(-np.trace(stress, axis1=1, axis2=2).min() / 3.0) if len(stress) else 0.0
        if p <= self.params["p_max"]:
            return self.p_wave_speed
        return float(math.sqrt(self.constrained_modulus(p) / self._density))

    def tensors(self, stress, e):
        """(L, N) of eqs 3.5-3.6 at stresses (n, 3, 3) and void ratios (n,)."""
        s = np.ascontiguousarray(np.reshape(stress, (-1, 3, 3)), dtype=np.float64)
        e = np.ascontiguousarray(np.broadcast_to(np.asarray(e, dtype=float), (len(s),)))
        L = np.empty((len(s), 3, 3, 3, 3))
        N = np.empty((len(s), 3, 3))
        hypoplastic_tensors_kernel(s, e, self._par, L, N)
        return L, N

    def _initialise(self, idx, sigma_old, state):
        """Fresh particles (state[:, 0] == 0) get (e_0, delta_0); e_0 is checked against
        [e_d(p), e_i(p)] at their pressure."""
        fresh = idx[state[idx, 0] == 0.0]
        if len(fresh):
            p = -np.trace(sigma_old[fresh], axis1=1, axis2=2) / 3.0
            self.check_void_ratio(self.params["e_0"], np.maximum(p, 0.0))
            state[fresh, 0] = self.params["e_0"]
            state[fresh, 1:7] = self.delta_0[_VI, _VJ]

    def stress(self, idx, dF, F_old, sigma_old, sigma_new, state):
        """Write sigma_new[idx] and the trial history state[idx] (e, delta); F_old is unused."""
        idx = np.asarray(idx, dtype=np.int64)
        self._initialise(idx, sigma_old, state)
        hypoplastic_stress_kernel(idx, dF, sigma_old, sigma_new, state, self._par, self.tol,
                                  self.stats)

    def tangent(self, idx, dF, F_old, sigma_old, sigma_new, state, dsig):
        """Write dsig[idx] = d sigma_new / d dF, the numerical tangent of `stress` (central
        differences, fixed sub-steps) from the committed history."""
        idx = np.asarray(idx, dtype=np.int64)
        self._initialise(idx, sigma_old, state)
        hypoplastic_tangent_kernel(idx, dF, sigma_old, state, dsig, self._par, self.tol)

    def set_state(self, particles, e=None, delta=None):
        """Set the history of this material's particles: e (scalar or per-particle array of the
        local particles; default e_0), delta (3 x 3, default delta_0); e is checked against
        [e_d(p), e_i(p)] at each particle's current pressure."""
        p = particles
        k = next(i for i, m in enumerate(p.materials) if m is self)
        sel = np.flatnonzero(p.material_id == k)
        ev = np.broadcast_to(np.asarray(self.params["e_0"] if e is None else e, dtype=float),
                             (len(p),))[sel]
        pr = np.maximum(-np.trace(p.stress[sel], axis1=1, axis2=2) / 3.0, 0.0)
        self.check_void_ratio(ev, pr, name="e")
        d = self.delta_0 if delta is None else np.asarray(delta, dtype=float)
        if d.shape != (3, 3) or np.linalg.norm(d) > self.params["R"] * (1 + 1e-12):
            raise ValueError(f"Hypoplastic.set_state: 'delta' must be a 3 x 3 tensor with "
                             f"||delta|| <= R = {self.params['R']!r}")
        p.state[sel, 0] = ev
        p.state[sel, 1:7] = d[_VI, _VJ]

    def __repr__(self):
        v = self.params
        return "Hypoplastic(" + ", ".join(f"{k}={v[k]!r}" for k in v) + ")"


def geostatic(particles, material, gravity, K0=None, void_ratio="constant", surface=None):
    """K0 (geostatic) stress and void-ratio field of hypoplastic particles.

    sigma_v = -rho g d, sigma_h = K0 sigma_v (fenicsmpm.materials.initial_stress.k0_stress), default
    K0 = 1 - sin phi_c (Jaky).  void_ratio: "constant" (e_0 everywhere) or "relative" (the
    pressure-independent relative density r = (e_c0 - e_0)/(e_c0 - e_d0) kept with depth:
    e = e_c(p) - r (e_c(p) - e_d(p)), eq 3.15), checked against [e_d(p), e_i(p)].
    Collective under MPI (as k0_stress).  Returns the depths d of the local particles."""
    from .initial_stress import k0_stress
    m = material
    if void_ratio not in ("constant", "relative"):
        raise ValueError(f"geostatic: 'void_ratio' must be 'constant' or 'relative', "
                         f"got {void_ratio!r}")
    k0 = 1.0 - math.sin(math.radians(m.params["phi_c"])) if K0 is None else K0
    depth = k0_stress(particles, gravity=gravity, K0=k0, surface=surface)
    e = None
    if void_ratio == "relative":
        v = m.params
        r = (v["e_c0"] - v["e_0"]) / (v["e_c0"] - v["e_d0"])
        pr = np.maximum(-np.trace(particles.stress, axis1=1, axis2=2) / 3.0, 0.0)
        ed, ec, _ = m.characteristic_void_ratios(pr)
        e = ec - r * (ec - ed)
    m.set_state(particles, e=e)
    return depth
