"""Von Mises (undrained clay) elasto-plasticity with linear softening of c_u to a residual.

Seed 000 ch. 5 (L1344-1349, L1420): elastic-perfectly plastic von Mises soil with post-peak
softening (Wang & Hicks 2016), c_peak = 10 kPa, c_res = 3 kPa, H = dc/d eps_p = -140 kPa, and
the yield condition sigma_dev < sqrt(3) c_u, sigma_dev = q = sqrt(3 J2).  Hence
    f = q - sqrt(3) c(eps_p),   q = sqrt(3 J2) = sqrt(3/2 s:s),
i.e. sqrt(J2) = c_u: the yield stress is sqrt(3) c_u and c_u is the strength in pure (simple)
shear, tau = c_u.  Softening (seed 000 Fig. 5.2):
    c(eps_p) = max(c_res, c_u + H eps_p),  H <= 0,
with eps_p the equivalent plastic strain sqrt(2/3 eps^p : eps^p) (work conjugate of q).

Radial return (de Souza Neto, Peric & Owen 2008, box 7.4), predictor as in LinearElastic
(Jaumann rate): q_tr - 3 G dg - sqrt(3) c(eps_p,n + dg) = 0, solved exactly on each linear
branch of c, and s = (1 - 3 G dg / q_tr) s_tr.  Consistent tangent (ibid. eq 7.120) written
as d sigma / d sigma_tr, acting on the predictor increment X:
    d sigma = tr(X)/3 I + (1 - 3 G dg/q_tr) dev(X) + 3 G (dg/q_tr - 1/(3 G + sqrt(3) H_t)) n (n:X),
n = s_tr/|s_tr|, H_t = H on the softening branch and 0 on the residual one.

History (state columns): 0 = eps_p (equivalent plastic strain); with nonlocal_length, 1 =
<eps_p>, the neighbourhood average (materials.regularisation); the step's return uses
A = (1 - m) eps_p,n + m <eps_p> (over_nonlocal, _vm_return_over).
"""
import math

import numba
import numpy as np

from ..kernels.threads import PRANGE, RETURN_CHUNK, chunk, particle_chunks
from .linear_elastic import IsotropicElasticParameters, jaumann_tangent
from .mohr_coulomb import _trial
from .regularisation import NonlocalSoftening, over_nonlocal
from .validation import check_positive, check_real

__all__ = ["VonMises", "von_mises_stress_kernel", "von_mises_tangent_kernel"]

_SQ3 = math.sqrt(3.0)


@numba.njit(cache=True)
def _deviator(S, s_out):
    """s_out = dev(S); returns q = sqrt(3/2 s:s)."""
    pm = (S[0, 0] + S[1, 1] + S[2, 2]) / 3.0
    ss = 0.0
    for i in range(3):
        for j in range(3):
            s_out[i, j] = S[i, j] - (pm if i == j else 0.0)
            ss += s_out[i, j] * s_out[i, j]
    return math.sqrt(1.5 * ss)


@numba.njit(cache=True)
def _vm_return(S, ep_n, mu, c_u, c_res, H, s_out):
    """Radial return of the predictor S: writes s_out = dev(S) and returns (dg, q_tr, H_t),
    dg = 0 for an elastic step, H_t the slope dc/d eps_p of the branch reached."""
    q = _deviator(S, s_out)
    c_n = max(c_res, c_u + H * ep_n)
    if q - _SQ3 * c_n <= 0.0:
        return 0.0, q, 0.0
    if c_u + H * ep_n > c_res:
        dg = (q - _SQ3 * (c_u + H * ep_n)) / (3.0 * mu + _SQ3 * H)
        if c_u + H * (ep_n + dg) >= c_res:
            return dg, q, H
    return (q - _SQ3 * c_res) / (3.0 * mu), q, 0.0


@numba.njit(cache=True)
def _vm_return_over(S, A, mf, mu, c_u, c_res, H, s_out):
    """Radial return with the over-nonlocal variable of the step (materials.regularisation)
    eps_p_bar = A + (1 - m) dg, A = (1 - m) eps_p,n + m <eps_p>_n frozen:
        c(dg) = max(c_res, c_0 + H_h dg),  c_0 = c_u + H A,  H_h = (1 - m) H >= 0
    (no cap at c_u: eps_p_bar < 0 where a point has strained more than its neighbourhood),
    non-decreasing in dg, so q_tr - 3 G dg - sqrt(3) c(dg) = 0 has one root, found on each
    linear branch.  Writes s_out = dev(S); returns (dg, q_tr, H_t) as _vm_return."""
    q = _deviator(S, s_out)
    c0 = c_u + H * A
    Hh = (1.0 - mf) * H
    if q - _SQ3 * max(c_res, c0) <= 0.0:
        return 0.0, q, 0.0
    if c0 < c_res:
        dg = (q - _SQ3 * c_res) / (3.0 * mu)
        if c0 + Hh * dg <= c_res:
            return dg, q, 0.0
    return (q - _SQ3 * c0) / (3.0 * mu + _SQ3 * Hh), q, Hh


@numba.njit(parallel=PRANGE, cache=True)
def von_mises_stress_kernel(idx, dF, sigma_old, sigma_new, state, lam, mu, c_u, c_res, H, nl, mf):
    """sigma_new = p_tr I + (1 - 3 G dg / q_tr) s_tr;  state[:, 0] += dg.  nl >= 0: the column
    of the over-nonlocal A with factor mf (_vm_return_over), nl = -1: local softening.
    Threaded over chunks of RETURN_CHUNK particles (kernels.threads)."""
    n = idx.shape[0]
    nc = particle_chunks(n, RETURN_CHUNK)
    if nc == 1:
        return _vm_stress(idx, dF, sigma_old, sigma_new, state, lam, mu, c_u, c_res, H, nl, mf,
                          np.int64(0), n)
    for c in numba.prange(nc):
        lo, hi = chunk(n, nc, c)
        _vm_stress(idx, dF, sigma_old, sigma_new, state, lam, mu, c_u, c_res, H, nl, mf, lo, hi)


@numba.njit(cache=True)
def _vm_stress(idx, dF, sigma_old, sigma_new, state, lam, mu, c_u, c_res, H, nl, mf, lo, hi):
    S = np.empty((3, 3))
    s = np.empty((3, 3))
    for q in range(lo, hi):
        p = idx[q]
        _trial(p, dF, sigma_old, lam, mu, S)
        if nl < 0:
            dg, qtr, _ = _vm_return(S, state[p, 0], mu, c_u, c_res, H, s)
        else:
            dg, qtr, _ = _vm_return_over(S, over_nonlocal(state, p, nl, mf), mf, mu, c_u,
                                         c_res, H, s)
        fac = 1.0 - 3.0 * mu * dg / qtr if dg > 0.0 else 1.0
        for i in range(3):
            for j in range(3):
                sigma_new[p, i, j] = S[i, j] - (1.0 - fac) * s[i, j]
        state[p, 0] += dg


@numba.njit(parallel=PRANGE, cache=True)
def von_mises_tangent_kernel(idx, dF, sigma_old, state, dsig, lam, mu, c_u, c_res, H, nl, mf):
    """dsig[p,i,j,k,l] = d sigma_new_ij / d dF_kl (consistent), from the committed state.
    Threaded over chunks of RETURN_CHUNK particles (kernels.threads)."""
    n = idx.shape[0]
    nc = particle_chunks(n, RETURN_CHUNK)
    if nc == 1:
        return _vm_tangent(idx, dF, sigma_old, state, dsig, lam, mu, c_u, c_res, H, nl, mf,
                           np.int64(0), n)
    for c in numba.prange(nc):
        lo, hi = chunk(n, nc, c)
        _vm_tangent(idx, dF, sigma_old, state, dsig, lam, mu, c_u, c_res, H, nl, mf, lo, hi)


@numba.njit(cache=True)
def _vm_tangent(idx, dF, sigma_old, state, dsig, lam, mu, c_u, c_res, H, nl, mf, lo, hi):
    S = np.empty((3, 3))
    s = np.empty((3, 3))
    E = np.empty((3, 3))
    for q in range(lo, hi):
        p = idx[q]
        _trial(p, dF, sigma_old, lam, mu, S)
        if nl < 0:
            dg, qtr, Ht = _vm_return(S, state[p, 0], mu, c_u, c_res, H, s)
        else:
            dg, qtr, Ht = _vm_return_over(S, over_nonlocal(state, p, nl, mf), mf, mu, c_u,
                                          c_res, H, s)
        alpha = 1.0
        beta = 0.0
        if dg > 0.0:
            alpha = 1.0 - 3.0 * mu * dg / qtr
            beta = 3.0 * mu * (dg / qtr - 1.0 / (3.0 * mu + _SQ3 * Ht))
            nn = math.sqrt(2.0 / 3.0) * qtr
            for i in range(3):
                for j in range(3):
                    s[i, j] /= nn
        for k in range(3):
            for l in range(3):
                for i in range(3):
                    for j in range(3):
                        E[i, j] = jaumann_tangent(i, j, k, l, lam, mu, sigma_old[p])
                tr = (E[0, 0] + E[1, 1] + E[2, 2]) / 3.0
                nx = 0.0
                for i in range(3):
                    for j in range(3):
                        nx += s[i, j] * E[i, j]
                for i in range(3):
                    for j in range(3):
                        d = E[i, j] - (tr if i == j else 0.0)
                        v = alpha * d + beta * s[i, j] * nx
                        if i == j:
                            v += tr
                        dsig[p, i, j, k, l] = v


class VonMises(NonlocalSoftening, IsotropicElasticParameters):
    """Von Mises undrained clay, f = sqrt(3 J2) - sqrt(3) c(eps_p) (seed 000 ch. 5, L1420:
    sigma_dev^peak = sqrt(3) c_u, so c_u is the pure-shear strength), with linear softening
    c(eps_p) = max(c_res, c_u + H eps_p) (seed 000 L1349).  See the module docstring.

    Parameters: E > 0, -1 < nu < 0.5, density > 0, c_u > 0, 0 <= c_res <= c_u (default c_u:
    perfectly plastic), H <= 0 with 3 G + sqrt(3) H > 0 (no snap-back of the local return);
    nonlocal_length None (local softening) or l > 0, nonlocal_m >= 1: c follows the
    over-nonlocal average of eps_p (materials.regularisation).
    History: state[:, 0] = eps_p (local), with nonlocal_length state[:, 1] = <eps_p> (module doc).
    """

    name = "VonMises"
    n_state = 1

    def __init__(self, E, nu, density, c_u, c_res=None, H=0.0, nonlocal_length=None,
                 nonlocal_m=2.0):
        owner = type(self).__name__
        self._set_parameters(E, nu, density)
        self._set_nonlocal(nonlocal_length, nonlocal_m, 1)
        self._c_u = check_positive(owner, "c_u", c_u)
        if c_res is None:
            self._c_res = self._c_u
        else:
            self._c_res = check_real(owner, "c_res", c_res)
            if not 0.0 <= self._c_res <= self._c_u:
                raise ValueError(f"{owner}: parameter 'c_res' must satisfy 0 <= c_res <= c_u "
                                 f"= {self._c_u!r} (residual <= peak), got {self._c_res!r}")
        self._H = check_real(owner, "H", H)
        if self._H > 0.0:
            raise ValueError(f"{owner}: parameter 'H' must be <= 0 (softening), got {self._H!r}")
        if not 3.0 * self.shear_modulus + _SQ3 * self._H > 0.0:
            raise ValueError(f"{owner}: parameter 'H' must satisfy 3 G + sqrt(3) H > 0 "
                             f"(G = {self.shear_modulus!r}), got {self._H!r}")

    c_u = property(lambda self: self._c_u, doc="Peak undrained shear strength.")
    c_res = property(lambda self: self._c_res, doc="Residual undrained shear strength.")
    H = property(lambda self: self._H, doc="Softening modulus dc/d eps_p (<= 0).")

    def strength(self, eps_p):
        """c(eps_p) = max(c_res, c_u + H eps_p) (seed 000 L1349)."""
        return np.maximum(self._c_res, self._c_u + self._H * np.asarray(eps_p, dtype=float))

    def _kernel_args(self):
        return (self.lame_lambda, self.shear_modulus, self._c_u, self._c_res, self._H,
                self.nonlocal_column, self.nonlocal_m)

    def stress(self, idx, dF, F_old, sigma_old, sigma_new, state):
        """Write sigma_new[idx] and the trial history state[idx]; ``F_old`` is unused."""
        von_mises_stress_kernel(np.asarray(idx, dtype=np.int64), dF, sigma_old, sigma_new,
                                state, *self._kernel_args())

    def tangent(self, idx, dF, F_old, sigma_old, sigma_new, state, dsig):
        """Write dsig[idx] = d sigma_new / d dF (consistent) from the committed ``state``."""
        von_mises_tangent_kernel(np.asarray(idx, dtype=np.int64), dF, sigma_old, state, dsig,
                                 *self._kernel_args())

    def __repr__(self):
        return (f"VonMises(E={self.E!r}, nu={self.nu!r}, density={self.density!r}, "
                f"c_u={self._c_u!r}, c_res={self._c_res!r}, H={self._H!r}{self._nonlocal_repr()})")
