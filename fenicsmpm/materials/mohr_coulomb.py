"""Non-associated Mohr-Coulomb elasto-plasticity with tension cut-off and exponential softening.

Principal stresses sigma_1 <= sigma_2 <= sigma_3, tension positive (seed 002 eqs 5.1-5.4):
    yield      f = 1/2 (sigma_3 - sigma_1) + 1/2 (sigma_1 + sigma_3) sin(phi) - c cos(phi)   (5.1)
    flow       d eps^p = d lambda dg/dsigma                                                 (5.3)
    potential  g = 1/2 (sigma_3 - sigma_1) + 1/2 (sigma_1 + sigma_3) sin(psi)               (5.4)
    optional tension cut-off  f_t = sigma_3 - sigma_t  (associated).
Strain softening (seed 003 eqs 20-21, the Anura3D MCSS law):
    x = x_res + (x_peak - x_res) exp(-eta eps_d^p),   x = phi, c,
with the accumulated plastic deviatoric strain eps_d^p = sum sqrt(2/3 de^p : de^p), de^p the
deviatoric part of the plastic strain increment; psi is not softened (psi <= phi_res).

Integration (Clausen, Damkilde & Andersen 2006, 2007): an elastic predictor
    sigma_tr = sigma_old + omega sigma_old - sigma_old omega + lambda tr(eps) I + 2 mu eps
(Jaumann rate as in LinearElastic), then a return in principal stress space where every yield
plane is linear and the elastic matrix is D_ij = lambda + 2 mu d_ij:
    sigma = sigma_tr - D sum_a dlambda_a b_a,   f_a(sigma, kappa_n + d kappa) = 0 (a active).
The active set is the first admissible one among the plane, the two MC edges (sigma_1 = sigma_2,
sigma_2 = sigma_3), the cut-off plane, its edges and corners (dlambda >= 0, order preserved,
all yield functions <= 0); with softening each set is solved by Newton on dlambda.  Where none
is admissible the stress returns to the MC apex sigma_i = c cot(phi), with d kappa =
sqrt(2/3) |dev sigma_tr| / (2 mu) (for psi = 0 the isochoric flow cannot reach the apex; the
apex return is then the closest admissible state, as in Clausen et al.).
Eigenvectors are unchanged by the return.  The consistent tangent is
    d sigma_p / d sigma_tr_p = I + D B J^-1 A^T     (principal, J = d f / d dlambda)
assembled with the spectral derivative (off-diagonal eigenbasis terms
(sigma_i - sigma_j) / (sigma_tr_i - sigma_tr_j)) and chained with the Jaumann elastic predictor.

Separation (issue 21 item 4): the plastic volumetric strain of returns to the apex and to the
tension cut-off is the material coming apart (a granular front thinning into loose grains).
MohrCoulomb(separation=True) keeps it as a gap g >= 0, and later compaction closes the gap
before it strains the skeleton:
    close = min(g, -tr eps) when tr eps < 0,   eps <- eps + close / 3 I,   g <- g - close,
so a particle pulled apart to many times its volume stays at the apex stress until it is back
at the volume where it separated, instead of reloading its nodes with the stress of the whole
compaction times its inflated volume (the granular collapse blew up this way,
problems.granular_collapse).  The consistent tangent ignores the gap (an implicit Newton step
closing a gap sees the elastic tangent).  The default, separation=False, opens no gap: noise
in the strain increments of a flowing mass also makes openings, and every particle that
opened one is stress-free, hence strengthless (c = 0), until compacted back; since dt="auto"
follows the state the collapse finishes without the gap, and stands taller
(docs/guide/choosing.md has the granular collapse's figures both ways).

History (state columns): 0 = eps_d^p (accumulated plastic deviatoric strain),
                         1 = eps_v^p (accumulated plastic volumetric strain, tr eps^p),
                         2 = g (the open gap, above),
                         3 = with nonlocal_length, <eps_d^p>, the neighbourhood average
                             (materials.regularisation); phi and c follow
                             A = (1 - m) eps_d^p,n + m <eps_d^p> within the step (_frozen).
"""
import math

import numba
import numpy as np

from ..kernels.threads import PRANGE, RETURN_CHUNK, chunk, particle_chunks
from .linear_elastic import IsotropicElasticParameters, jaumann_tangent
from .piola import eigh3
from .regularisation import NonlocalSoftening, over_nonlocal
from .validation import check_real

__all__ = ["MohrCoulomb", "mohr_coulomb_stress_kernel", "mohr_coulomb_tangent_kernel"]

# yield planes in principal space: (minor index, major index) for the MC planes 0-2,
# then the cut-off planes 3-5 on sigma_3, sigma_2, sigma_1
_MINOR = np.array([0, 0, 1], dtype=np.int64)
_MAJOR = np.array([2, 1, 2], dtype=np.int64)
_TCUT = np.array([2, 1, 0], dtype=np.int64)
# candidate active sets (-1 = unused), tried in order
_SETS = np.array([[0, -1, -1], [3, -1, -1], [0, 1, -1], [0, 2, -1], [3, 4, -1], [0, 3, -1],
                  [0, 2, 3], [0, 1, 3], [0, 1, 4], [0, 3, 4], [1, 3, 4], [3, 4, 5]],
                 dtype=np.int64)
_CUT_SETS = np.array([np.any(s >= 3) for s in _SETS])    # sets with a tension cut-off plane
_SQ23 = math.sqrt(2.0 / 3.0)


@numba.njit(cache=True)
def _soft(x_peak, x_res, eta, kappa):
    """x = x_res + (x_peak - x_res) exp(-eta kappa) and dx/dkappa, capped at x_peak (reached
    only by the over-nonlocal form, eta kappa < 0: see _frozen)."""
    e = math.exp(-eta * kappa)
    if e > 1.0:
        return x_peak, 0.0
    return x_res + (x_peak - x_res) * e, -eta * (x_peak - x_res) * e


@numba.njit(cache=True)
def _plane(pid, sig, sphi, cphi, c, dphi, dc, spsi, st, a, b):
    """Value of plane `pid` at principal stress `sig`; its gradient a, flow direction b;
    returns (f, df/dkappa)."""
    for i in range(3):
        a[i] = 0.0
        b[i] = 0.0
    if pid < 3:
        i = _MINOR[pid]
        j = _MAJOR[pid]
        a[i] = -0.5 * (1.0 - sphi)
        a[j] = 0.5 * (1.0 + sphi)
        b[i] = -0.5 * (1.0 - spsi)
        b[j] = 0.5 * (1.0 + spsi)
        f = 0.5 * (sig[j] - sig[i]) + 0.5 * (sig[i] + sig[j]) * sphi - c * cphi
        dfdk = (0.5 * (sig[i] + sig[j]) * cphi + c * sphi) * dphi - cphi * dc
        return f, dfdk
    k = _TCUT[pid - 3]
    a[k] = 1.0
    b[k] = 1.0
    return sig[k] - st, 0.0


@numba.njit(cache=True)
def _solve_small(J, r, m, x, M):
    """x = J[:m,:m]^-1 r[:m] by Gaussian elimination with partial pivoting (M: 3 x 4 work
    array); False if singular."""
    for i in range(m):
        for j in range(m):
            M[i, j] = J[i, j]
        M[i, m] = r[i]
    scale = 0.0
    for i in range(m):
        for j in range(m):
            scale = max(scale, abs(J[i, j]))
    for col in range(m):
        piv = col
        for i in range(col + 1, m):
            if abs(M[i, col]) > abs(M[piv, col]):
                piv = i
        if not abs(M[piv, col]) > 1e-13 * scale:
            return False
        if piv != col:
            for j in range(m + 1):
                t = M[col, j]
                M[col, j] = M[piv, j]
                M[piv, j] = t
        for i in range(col + 1, m):
            fct = M[i, col] / M[col, col]
            for j in range(col, m + 1):
                M[i, j] -= fct * M[col, j]
    for i in range(m - 1, -1, -1):
        s = M[i, m]
        for j in range(i + 1, m):
            s -= M[i, j] * x[j]
        x[i] = s / M[i, i]
    return True


@numba.njit(cache=True)
def _solve_set(sid, s_tr, kap_n, lam, mu, par, spsi, st, scale, sig, dl, Amat, Bmat, J, W, M):
    """Return onto active set _SETS[sid]: fills sig, dl, the active gradients (Amat columns),
    flow directions (Bmat columns) and the Jacobian J; returns (m, kappa) or m = -1 on failure.
    W (>= 7 x 3) and M (3 x 4) are work arrays."""
    m = 0
    for q in range(3):
        if _SETS[sid, q] >= 0:
            m += 1
    a, b, r, dfdk, ep, dkdl, step = W[0], W[1], W[2], W[3], W[4], W[5], W[6]
    for q in range(3):
        dl[q] = 0.0
    for q in range(m):                      # flow directions (independent of kappa)
        _plane(_SETS[sid, q], s_tr, 0.0, 1.0, 0.0, 0.0, 0.0, spsi, st, a, b)
        for i in range(3):
            Bmat[i, q] = b[i]
    kappa = kap_n
    soft = par[4] != 0.0            # without softening the strength is that of any kappa
    phi, dphi = _soft(par[0], par[1], par[4], kappa)
    c, dc = _soft(par[2], par[3], par[4], kappa)
    sphi = math.sin(phi)
    cphi = math.cos(phi)
    for it in range(60):
        for i in range(3):
            ep[i] = 0.0
            for q in range(m):
                ep[i] += dl[q] * Bmat[i, q]
        em = (ep[0] + ep[1] + ep[2]) / 3.0
        nd = math.sqrt((ep[0] - em) ** 2 + (ep[1] - em) ** 2 + (ep[2] - em) ** 2)
        kappa = kap_n + _SQ23 * nd
        if soft:
            phi, dphi = _soft(par[0], par[1], par[4], kappa)
            c, dc = _soft(par[2], par[3], par[4], kappa)
            sphi = math.sin(phi)
            cphi = math.cos(phi)
        tr = ep[0] + ep[1] + ep[2]
        for i in range(3):
            sig[i] = s_tr[i] - lam * tr - 2.0 * mu * ep[i]
        res = 0.0
        for q in range(m):
            f, dfdk[q] = _plane(_SETS[sid, q], sig, sphi, cphi, c, dphi, dc, spsi, st, a, b)
            r[q] = f
            res = max(res, abs(f))
            for i in range(3):
                Amat[i, q] = a[i]
        for q in range(m):
            if nd > 1e-300:
                s = 0.0
                for i in range(3):
                    s += (ep[i] - em) * Bmat[i, q]
                dkdl[q] = _SQ23 * s / nd
            else:
                dkdl[q] = 0.0
        for q in range(m):
            for w in range(m):
                trb = Bmat[0, w] + Bmat[1, w] + Bmat[2, w]
                adb = 0.0
                for i in range(3):
                    adb += Amat[i, q] * (lam * trb + 2.0 * mu * Bmat[i, w])
                J[q, w] = -adb + dfdk[q] * dkdl[w]
        if res <= 1e-13 * scale and it > 0:
            return m, kappa
        if not _solve_small(J, r, m, step, M):
            return -1, kappa
        for q in range(m):
            dl[q] -= step[q]
    return -1, kappa


@numba.njit(cache=True)
def _mc_return(s_tr, kap_n, lam, mu, par, spsi, st, sig, A, W, M, want_A=True):
    """Principal-space return of s_tr (ascending) from history kap_n; writes sig and, with
    want_A, A = d sig / d s_tr (3 x 3); returns (plastic, d eps_d^p, d eps_v^p, opening), opening
    the part of d eps_v^p from the apex and the tension cut-off (the material separating).
    W (22 x 3) and M (3 x 4) are work arrays."""
    phi, dphi = _soft(par[0], par[1], par[4], kap_n)
    c, dc = _soft(par[2], par[3], par[4], kap_n)
    sphi = math.sin(phi)
    cphi = math.cos(phi)
    a, b = W[7], W[8]
    f0, _ = _plane(0, s_tr, sphi, cphi, c, dphi, dc, spsi, st, a, b)
    for i in range(3):
        for j in range(3):
            A[i, j] = 1.0 if i == j else 0.0
        sig[i] = s_tr[i]
    scale = max(abs(s_tr[0]), abs(s_tr[2]), c, 1e-300)
    if f0 <= 0.0 and s_tr[2] <= st:
        return False, 0.0, 0.0, 0.0
    dl, X, col, ep = W[9], W[10], W[11], W[12]
    Amat, Bmat, J = W[13:16], W[16:19], W[19:22]
    tol = 1e-10 * scale
    for sid in range(_SETS.shape[0]):
        if _CUT_SETS[sid] and st == math.inf:   # no cut-off: f = sigma_k - inf never 0, inactive
            continue
        m, kappa = _solve_set(sid, s_tr, kap_n, lam, mu, par, spsi, st, scale, sig, dl,
                              Amat, Bmat, J, W, M)
        if m < 0:
            continue
        dlmax = 0.0
        for q in range(m):
            dlmax = max(dlmax, abs(dl[q]))
        ok = sig[0] <= sig[1] + tol and sig[1] <= sig[2] + tol and sig[2] <= st + tol
        for q in range(m):
            ok = ok and dl[q] >= -1e-10 * dlmax
        if not ok:
            continue
        phi, dphi = _soft(par[0], par[1], par[4], kappa)
        c, dc = _soft(par[2], par[3], par[4], kappa)
        fm, _ = _plane(0, sig, math.sin(phi), math.cos(phi), c, dphi, dc, spsi, st, a, b)
        if fm > tol:
            continue
        # A = I + D B J^-1 A^T
        for j in range(3 if want_A else 0):
            for q in range(m):
                col[q] = Amat[j, q]
            _solve_small(J, col, m, X, M)       # X = J^-1 A^T e_j
            for i in range(3):
                ep[i] = 0.0
            for q in range(m):
                for i in range(3):
                    ep[i] += Bmat[i, q] * X[q]
            tr = ep[0] + ep[1] + ep[2]
            for i in range(3):
                A[i, j] += lam * tr + 2.0 * mu * ep[i]
        epv = 0.0
        opening = 0.0
        for q in range(m):
            dv = dl[q] * (Bmat[0, q] + Bmat[1, q] + Bmat[2, q])
            epv += dv
            if _SETS[sid, q] >= 3:              # a tension cut-off plane
                opening += dv
        return True, kappa - kap_n, epv, opening
    # apex: sigma_i = c cot(phi), d kappa = sqrt(2/3) |dev s_tr| / (2 mu)
    pm = (s_tr[0] + s_tr[1] + s_tr[2]) / 3.0
    nd = math.sqrt((s_tr[0] - pm) ** 2 + (s_tr[1] - pm) ** 2 + (s_tr[2] - pm) ** 2)
    dk = _SQ23 * nd / (2.0 * mu)
    kappa = kap_n + dk
    phi, dphi = _soft(par[0], par[1], par[4], kappa)
    c, dc = _soft(par[2], par[3], par[4], kappa)
    sphi = math.sin(phi)
    pa = c * math.cos(phi) / sphi
    dpa = dc * math.cos(phi) / sphi - c * dphi / (sphi * sphi)
    for i in range(3):
        sig[i] = pa
        for j in range(3):
            A[i, j] = dpa * _SQ23 / (2.0 * mu) * (s_tr[j] - pm) / nd if nd > 1e-300 else 0.0
    dv = 3.0 * (pm - pa) / (3.0 * lam + 2.0 * mu)
    return True, dk, dv, max(dv, 0.0)


@numba.njit(cache=True)
def _trial(p, dF, sigma_old, lam, mu, S, close=0.0):
    """Jaumann elastic predictor S = sigma_old + omega sigma_old - sigma_old omega + C : eps,
    eps = sym(dF - I) + close / 3 I (close >= 0: compaction taken up by an open gap)."""
    tr = dF[p, 0, 0] + dF[p, 1, 1] + dF[p, 2, 2] - 3.0 + close
    for i in range(3):
        for j in range(3):
            hij = dF[p, i, j] - (1.0 if i == j else 0.0)
            hji = dF[p, j, i] - (1.0 if i == j else 0.0)
            v = sigma_old[p, i, j] + mu * (hij + hji) + (lam * tr if i == j else 0.0)
            if i == j:
                v += 2.0 * mu * close / 3.0
            for m in range(3):
                v += (0.5 * (dF[p, i, m] - dF[p, m, i]) * sigma_old[p, m, j]
                      - sigma_old[p, i, m] * 0.5 * (dF[p, m, j] - dF[p, j, m]))
            S[i, j] = v


@numba.njit(cache=True)
def _principal_closed_form(S, w):
    """Ascending eigenvalues of the symmetric S from its invariants (trigonometric form);
    used only to skip the eigen-decomposition of clearly elastic states."""
    pm = (S[0, 0] + S[1, 1] + S[2, 2]) / 3.0
    b00, b11, b22 = S[0, 0] - pm, S[1, 1] - pm, S[2, 2] - pm
    q2 = (b00 * b00 + b11 * b11 + b22 * b22
          + 2.0 * (S[0, 1] ** 2 + S[0, 2] ** 2 + S[1, 2] ** 2)) / 6.0
    q3 = q2 ** 1.5
    if not q3 > 0.0:                # hydrostatic, or a deviator below ~1e-108 whose q2^1.5
        w[0] = w[1] = w[2] = pm     # underflows (e.g. the faint front of a wave): pm to round-off
        return
    det = (b00 * (b11 * b22 - S[1, 2] * S[2, 1]) - S[0, 1] * (S[1, 0] * b22 - S[1, 2] * S[2, 0])
           + S[0, 2] * (S[1, 0] * S[2, 1] - b11 * S[2, 0]))
    r = min(1.0, max(-1.0, 0.5 * det / q3))
    ang = math.acos(r) / 3.0
    sq = 2.0 * math.sqrt(q2)
    w[2] = pm + sq * math.cos(ang)
    w[0] = pm + sq * math.cos(ang + 2.0 * math.pi / 3.0)
    w[1] = 3.0 * pm - w[0] - w[2]


@numba.njit(cache=True)
def _clearly_elastic(S, kap_n, par, st, w):
    """True if S lies inside the yield surfaces by more than 1e-6 of its size."""
    _principal_closed_form(S, w)
    phi, _ = _soft(par[0], par[1], par[4], kap_n)
    c, _ = _soft(par[2], par[3], par[4], kap_n)
    sphi = math.sin(phi)
    f = 0.5 * (w[2] - w[0]) + 0.5 * (w[0] + w[2]) * sphi - c * math.cos(phi)
    tol = 1e-6 * max(abs(w[0]), abs(w[2]), c)
    return f < -tol and w[2] < st - tol


@numba.njit(cache=True)
def _frozen(state, p, nl, mf, par, out):
    """(kappa_n, parameters) seen by the return of particle p: (state[p, 0], par), or with the
    column nl >= 0 of the neighbourhood average <kappa> (materials.regularisation), with
    A = (1 - m) kappa_n + m <kappa> (over_nonlocal): kappa_bar = A + (1 - m) dkappa within the
    step, i.e.
        exp(-eta kappa_bar) = exp(-eta' kappa'),  eta' = (1 - m) eta,  kappa' = A / (1 - m) + dkappa,
    so the return runs with kappa_n = A / (1 - m) and out = par with eta' (capped at the
    peak by _soft); it still returns the step's increment dkappa."""
    if nl < 0:
        return state[p, 0], par
    for k in range(4):
        out[k] = par[k]
    out[4] = (1.0 - mf) * par[4]
    return over_nonlocal(state, p, nl, mf) / (1.0 - mf), out


@numba.njit(parallel=PRANGE, cache=True)
def mohr_coulomb_stress_kernel(idx, dF, sigma_old, sigma_new, state, lam, mu, par, spsi, st, nl, mf,
                               sep=True):
    """sigma_new = principal return of the Jaumann predictor; state[:, 0:3] += (d eps_d^p,
    d eps_v^p, d g).  par = (phi_peak, phi_res, c_peak, c_res, eta), angles in radians; nl:
    see _frozen.  The gap g = state[:, 2] >= 0 (module docstring) takes up compaction first:
    close = min(g, -tr eps) when tr eps < 0, and grows by the opening of apex and cut-off
    returns (sep=False: no gap opens, MohrCoulomb(separation=False)). Threaded over chunks
    of RETURN_CHUNK particles (kernels.threads)."""
    n = idx.shape[0]
    nc = particle_chunks(n, RETURN_CHUNK)
    if nc == 1:
        return _mc_stress(idx, dF, sigma_old, sigma_new, state, lam, mu, par, spsi, st, nl, mf,
                          np.int64(0), n, sep)
    for c in numba.prange(nc):
        lo, hi = chunk(n, nc, c)
        _mc_stress(idx, dF, sigma_old, sigma_new, state, lam, mu, par, spsi, st, nl, mf, lo, hi,
                   sep)


@numba.njit(cache=True)
def _mc_stress(idx, dF, sigma_old, sigma_new, state, lam, mu, par, spsi, st, nl, mf, lo, hi, sep):
    pf = np.empty(5)
    S = np.empty((3, 3))
    sig = np.empty(3)
    A = np.empty((3, 3))
    W = np.empty((22, 3))
    M = np.empty((3, 4))
    w0 = np.empty(3)
    w = np.empty(3)
    V = np.empty((3, 3))
    for q in range(lo, hi):
        p = idx[q]
        close = 0.0
        if state[p, 2] > 0.0:
            close = min(state[p, 2], max(0.0, 3.0 - dF[p, 0, 0] - dF[p, 1, 1] - dF[p, 2, 2]))
            state[p, 2] -= close
        _trial(p, dF, sigma_old, lam, mu, S, close)
        kap, pp = _frozen(state, p, nl, mf, par, pf)
        if _clearly_elastic(S, kap, pp, st, w0):
            for i in range(3):
                for j in range(3):
                    sigma_new[p, i, j] = S[i, j]
            continue
        eigh3(S, w, V)
        plastic, dk, dv, opening = _mc_return(w, kap, lam, mu, pp, spsi, st, sig, A, W, M,
                                              False)
        if not plastic:
            for i in range(3):
                for j in range(3):
                    sigma_new[p, i, j] = S[i, j]
            continue
        for i in range(3):
            for j in range(3):
                sigma_new[p, i, j] = (V[i, 0] * sig[0] * V[j, 0] + V[i, 1] * sig[1] * V[j, 1]
                                      + V[i, 2] * sig[2] * V[j, 2])
        state[p, 0] += dk
        state[p, 1] += dv
        if sep:
            state[p, 2] += opening


@numba.njit(parallel=PRANGE, cache=True)
def mohr_coulomb_tangent_kernel(idx, dF, sigma_old, state, dsig, lam, mu, par, spsi, st, nl, mf):
    """dsig[p,i,j,k,l] = d sigma_new_ij / d dF_kl (consistent), from the committed state.
    Threaded over chunks of RETURN_CHUNK particles (kernels.threads)."""
    n = idx.shape[0]
    nc = particle_chunks(n, RETURN_CHUNK)
    if nc == 1:
        return _mc_tangent(idx, dF, sigma_old, state, dsig, lam, mu, par, spsi, st, nl, mf,
                           np.int64(0), n)
    for c in numba.prange(nc):
        lo, hi = chunk(n, nc, c)
        _mc_tangent(idx, dF, sigma_old, state, dsig, lam, mu, par, spsi, st, nl, mf, lo, hi)


@numba.njit(cache=True)
def _mc_tangent(idx, dF, sigma_old, state, dsig, lam, mu, par, spsi, st, nl, mf, lo, hi):
    pf = np.empty(5)
    S = np.empty((3, 3))
    sig = np.empty(3)
    A = np.empty((3, 3))
    X = np.empty((3, 3))
    Y = np.empty((3, 3))
    th = np.empty((3, 3))
    E = np.empty((3, 3))
    W = np.empty((22, 3))
    M = np.empty((3, 4))
    w0 = np.empty(3)
    w = np.empty(3)
    V = np.eye(3)
    for q in range(lo, hi):
        p = idx[q]
        _trial(p, dF, sigma_old, lam, mu, S)
        kap, pp = _frozen(state, p, nl, mf, par, pf)
        elastic = _clearly_elastic(S, kap, pp, st, w0)
        if not elastic:
            eigh3(S, w, V)
            _mc_return(w, kap, lam, mu, pp, spsi, st, sig, A, W, M)
            scale = max(abs(w[0]), abs(w[2]), 1e-300)
            for i in range(3):
                for j in range(3):
                    if i != j:
                        if abs(w[i] - w[j]) > 1e-10 * scale:
                            th[i, j] = (sig[i] - sig[j]) / (w[i] - w[j])
                        else:
                            th[i, j] = A[i, i] - A[i, j]
        for k in range(3):
            for l in range(3):
                # E = d sigma_tr / d dF_kl (Jaumann predictor, see LinearElastic)
                for i in range(3):
                    for j in range(3):
                        E[i, j] = jaumann_tangent(i, j, k, l, lam, mu, sigma_old[p])
                if elastic:
                    for i in range(3):
                        for j in range(3):
                            dsig[p, i, j, k, l] = E[i, j]
                    continue
                for a in range(3):
                    for b in range(3):
                        s = 0.0
                        for i in range(3):
                            for j in range(3):
                                s += V[i, a] * E[i, j] * V[j, b]
                        X[a, b] = s
                for a in range(3):
                    for b in range(3):
                        if a == b:
                            Y[a, a] = A[a, 0] * X[0, 0] + A[a, 1] * X[1, 1] + A[a, 2] * X[2, 2]
                        else:
                            Y[a, b] = th[a, b] * X[a, b]
                for i in range(3):
                    for j in range(3):
                        s = 0.0
                        for a in range(3):
                            for b in range(3):
                                s += V[i, a] * Y[a, b] * V[j, b]
                        dsig[p, i, j, k, l] = s


def _check_range(owner, name, value, lo, hi, hi_open=False, what=""):
    v = check_real(owner, name, value)
    if v < lo or v > hi or (hi_open and v == hi):
        rel = "<" if hi_open else "<="
        raise ValueError(f"{owner}: parameter '{name}' must satisfy {lo} <= {name} {rel} {hi}"
                         f"{what}, got {v!r}")
    return v


class MohrCoulomb(NonlocalSoftening, IsotropicElasticParameters):
    """Non-associated Mohr-Coulomb soil with tension cut-off and exponential softening.

    f = 1/2 (sigma_3 - sigma_1) + 1/2 (sigma_1 + sigma_3) sin(phi) - c cos(phi)  (seed 002 eq 5.1),
    g as f with psi, no cohesion (eq 5.4), principal return after Clausen et al. (2006);
    phi, c = x_res + (x_peak - x_res) exp(-eta eps_d^p) (seed 003).  See the module docstring.

    Parameters (angles in degrees, stresses in Pa, tension positive):
        E > 0, -1 < nu < 0.5, density > 0;
        0 <= phi < 90, c >= 0 (phi > 0 or c > 0);
        0 <= psi <= phi_res;  tension_cutoff: None (none) or sigma_t >= 0 on sigma_3;
        phi_res in [0, phi] (default phi), c_res in [0, c] (default c), phi_res > 0 or c_res > 0;
        eta >= 0 (softening rate; 0 = perfectly plastic);
        nonlocal_length None (local softening) or l > 0, nonlocal_m >= 1: phi and c follow the
        over-nonlocal average of eps_d^p (materials.regularisation);
        separation False (default, chosen by data: docs/guide/choosing.md) lets compaction
        strain the skeleton at once (g stays 0); True keeps the opening of apex and cut-off
        returns as the gap g (module docstring).
    History: state[:, 0] = eps_d^p, state[:, 1] = eps_v^p, state[:, 2] = the gap g, with
    nonlocal_length state[:, 3] = <eps_d^p> (module docstring).
    """

    name = "MohrCoulomb"
    n_state = 3

    def __init__(self, E, nu, density, phi, c, psi=0.0, tension_cutoff=None, phi_res=None,
                 c_res=None, eta=0.0, nonlocal_length=None, nonlocal_m=2.0, separation=False):
        owner = type(self).__name__
        if not isinstance(separation, (bool, np.bool_)):
            raise ValueError(f"{owner}: parameter 'separation' must be True or False, got "
                             f"{separation!r}")
        self._separation = bool(separation)
        self._set_parameters(E, nu, density)
        self._set_nonlocal(nonlocal_length, nonlocal_m, 3)
        self._phi = _check_range(owner, "phi", phi, 0.0, 90.0, hi_open=True, what=" degrees")
        self._c = check_real(owner, "c", c)
        if self._c < 0.0:
            raise ValueError(f"{owner}: parameter 'c' must be >= 0, got {self._c!r}")
        if self._phi == 0.0 and self._c == 0.0:
            raise ValueError(f"{owner}: parameter 'c' must be > 0 when phi = 0 (no strength), "
                             f"got {self._c!r}")
        self._phi_res = self._phi if phi_res is None else _check_range(
            owner, "phi_res", phi_res, 0.0, self._phi, what=" (residual <= peak phi)")
        self._c_res = self._c if c_res is None else _check_range(
            owner, "c_res", c_res, 0.0, self._c, what=" (residual <= peak c)")
        if self._phi_res == 0.0 and self._c_res == 0.0:
            raise ValueError(f"{owner}: parameter 'c_res' must be > 0 when phi_res = 0 "
                             f"(no residual strength), got {self._c_res!r}")
        self._psi = _check_range(owner, "psi", psi, 0.0, self._phi_res,
                                 what=" (0 <= psi <= phi_res <= phi)")
        self._eta = check_real(owner, "eta", eta)
        if self._eta < 0.0:
            raise ValueError(f"{owner}: parameter 'eta' must be >= 0, got {self._eta!r}")
        if tension_cutoff is None:
            self._st = None
        else:
            self._st = check_real(owner, "tension_cutoff", tension_cutoff)
            if self._st < 0.0:
                raise ValueError(f"{owner}: parameter 'tension_cutoff' must be >= 0 "
                                 f"(tension positive), got {self._st!r}")

    phi = property(lambda self: self._phi, doc="Peak friction angle (degrees).")
    c = property(lambda self: self._c, doc="Peak cohesion.")
    psi = property(lambda self: self._psi, doc="Dilatancy angle (degrees).")
    phi_res = property(lambda self: self._phi_res, doc="Residual friction angle (degrees).")
    c_res = property(lambda self: self._c_res, doc="Residual cohesion.")
    eta = property(lambda self: self._eta, doc="Softening rate of exp(-eta eps_d^p).")
    tension_cutoff = property(lambda self: self._st, doc="Tension cut-off on sigma_3 (or None).")
    separation = property(lambda self: self._separation,
                          doc="Whether apex and cut-off openings are kept as a gap (module docstring).")

    def strength(self, eps_d):
        """(phi [deg], c) at accumulated plastic deviatoric strain eps_d (seed 003)."""
        e = np.exp(-self._eta * np.asarray(eps_d, dtype=float))
        return (self._phi_res + (self._phi - self._phi_res) * e,
                self._c_res + (self._c - self._c_res) * e)

    def _kernel_args(self):
        par = np.array([math.radians(self._phi), math.radians(self._phi_res), self._c,
                        self._c_res, self._eta])
        st = math.inf if self._st is None else self._st
        return (self.lame_lambda, self.shear_modulus, par, math.sin(math.radians(self._psi)), st,
                self.nonlocal_column, self.nonlocal_m)

    def stress(self, idx, dF, F_old, sigma_old, sigma_new, state):
        """Write sigma_new[idx] and the trial history state[idx]; ``F_old`` is unused."""
        mohr_coulomb_stress_kernel(np.asarray(idx, dtype=np.int64), dF, sigma_old, sigma_new,
                                   state, *self._kernel_args(), self._separation)

    def tangent(self, idx, dF, F_old, sigma_old, sigma_new, state, dsig):
        """Write dsig[idx] = d sigma_new / d dF, the consistent tangent of `stress` from the
        committed history ``state``."""
        mohr_coulomb_tangent_kernel(np.asarray(idx, dtype=np.int64), dF, sigma_old, state,
                                    dsig, *self._kernel_args())

    def reduced(self, factor):
        """Strength reduction (issue 7): a new MohrCoulomb with tan(phi)/factor and c/factor,
        likewise for the residual values and the tension cut-off; psi is capped at the reduced
        residual friction angle."""
        F = check_real(type(self).__name__, "factor", factor)
        if not F > 0.0:
            raise ValueError(f"{type(self).__name__}: parameter 'factor' must be > 0, got {F!r}")

        def red(angle):
            return math.degrees(math.atan(math.tan(math.radians(angle)) / F))

        phi_res = red(self._phi_res)
        return MohrCoulomb(self.E, self.nu, self.density, red(self._phi), self._c / F,
                           psi=min(self._psi, phi_res),
                           tension_cutoff=None if self._st is None else self._st / F,
                           phi_res=min(phi_res, red(self._phi)), c_res=self._c_res / F,
                           eta=self._eta, nonlocal_length=self.nonlocal_length,
                           nonlocal_m=self.nonlocal_m, separation=self._separation)

    def __repr__(self):
        return (f"MohrCoulomb(E={self.E!r}, nu={self.nu!r}, density={self.density!r}, "
                f"phi={self._phi!r}, c={self._c!r}, psi={self._psi!r}, "
                f"tension_cutoff={self._st!r}, phi_res={self._phi_res!r}, "
                f"c_res={self._c_res!r}, eta={self._eta!r}{self._nonlocal_repr()}"
                f"{', separation=True' if self._separation else ''})")
