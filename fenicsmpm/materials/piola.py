"""Stress-measure conversions and energy bookkeeping used by the solvers.

All kernels are ``numba.njit(cache=True)`` loops over the particle subset
``idx`` (int64); rows not in ``idx`` are neither read nor written.
Tensors are 3x3 float64, contiguous, stacked along the first axis.
"""
import numba
import numpy as np
from numba import prange

from ..kernels.threads import PRANGE, chunk, particle_chunks

__all__ = ["first_piola", "first_piola_tangent", "strain_energy_increment",
           "det3", "inv3", "eigh3"]


@numba.njit(cache=True)
def det3(A):
    """Determinant of a 3x3 matrix (cofactor expansion along the first row)."""
    return (A[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1])
            - A[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
            + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]))


@numba.njit(cache=True)
def eigh3(S, w, V):
    """Eigen-decomposition of the symmetric 3x3 S without allocating: ascending eigenvalues in
    w (3,), orthonormal eigenvectors in the columns of V (3, 3), S = V diag(w) V^T. Cyclic
    Jacobi rotations (Golub & Van Loan 2013, alg. 8.5.3), each annihilated entry set to 0, to
    an off-diagonal norm below 1e-18 of the diagonal's: eigenvalues and reconstruction to
    about 1e-15 relative, like LAPACK's dsyevd (np.linalg.eigh), at half its cost for a 3x3;
    a plane-strain stress (S_02 = S_12 = 0) takes one rotation."""
    A00, A11, A22 = S[0, 0], S[1, 1], S[2, 2]
    A01, A02, A12 = 0.5 * (S[0, 1] + S[1, 0]), 0.5 * (S[0, 2] + S[2, 0]), 0.5 * (S[1, 2] + S[2, 1])
    for i in range(3):
        for j in range(3):
            V[i, j] = 1.0 if i == j else 0.0
    for sweep in range(32):
        off = A01 * A01 + A02 * A02 + A12 * A12
        if off == 0.0 or off <= 1e-36 * (A00 * A00 + A11 * A11 + A22 * A22):
            break
        for pq in range(3):          # rotations in the (0, 1), (0, 2), (1, 2) planes
            if pq == 0:
                app, aqq, apq = A00, A11, A01
            elif pq == 1:
                app, aqq, apq = A00, A22, A02
            else:
                app, aqq, apq = A11, A22, A12
            if apq == 0.0:
                continue
            theta = (aqq - app) / (2.0 * apq)
            t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + np.sqrt(theta * theta + 1.0))
            c = 1.0 / np.sqrt(t * t + 1.0)
            s = t * c
            app, aqq = app - t * apq, aqq + t * apq
            if pq == 0:              # the other two off-diagonal entries rotate
                A00, A11, A01 = app, aqq, 0.0
                A02, A12 = c * A02 - s * A12, s * A02 + c * A12
                p, q = 0, 1
            elif pq == 1:
                A00, A22, A02 = app, aqq, 0.0
                A01, A12 = c * A01 - s * A12, s * A01 + c * A12
                p, q = 0, 2
            else:
                A11, A22, A12 = app, aqq, 0.0
                A01, A02 = c * A01 - s * A02, s * A01 + c * A02
                p, q = 1, 2
            for k in range(3):
                vkp, vkq = V[k, p], V[k, q]
                V[k, p] = c * vkp - s * vkq
                V[k, q] = s * vkp + c * vkq
    w[0], w[1], w[2] = A00, A11, A22
    for i in range(1, 3):            # ascending, columns with their values
        j = i
        while j > 0 and w[j - 1] > w[j]:
            w[j - 1], w[j] = w[j], w[j - 1]
            for k in range(3):
                V[k, j - 1], V[k, j] = V[k, j], V[k, j - 1]
            j -= 1


@numba.njit(cache=True)
def inv3(A, Ainv):
    """Write the inverse of the 3x3 matrix ``A`` into ``Ainv`` (adjugate / det).

    Returns det(A).  A singular ``A`` yields inf/NaN entries, no exception.
    """
    d = det3(A)
    Ainv[0, 0] = A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]
    Ainv[0, 1] = A[0, 2] * A[2, 1] - A[0, 1] * A[2, 2]
    Ainv[0, 2] = A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]
    Ainv[1, 0] = A[1, 2] * A[2, 0] - A[1, 0] * A[2, 2]
    Ainv[1, 1] = A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]
    Ainv[1, 2] = A[0, 2] * A[1, 0] - A[0, 0] * A[1, 2]
    Ainv[2, 0] = A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]
    Ainv[2, 1] = A[0, 1] * A[2, 0] - A[0, 0] * A[2, 1]
    Ainv[2, 2] = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    if d == 0.0:
        for i in range(3):
            for j in range(3):
                Ainv[i, j] = np.nan
        return d
    r = 1.0 / d
    for i in range(3):
        for j in range(3):
            Ainv[i, j] *= r
    return d


@numba.njit(cache=True)
def _sigma_FinvT(sigma_p, Finv, out):
    """out_iJ = sigma_ij (dF^-1)_Jj  (sigma dF^-T) for one particle."""
    for i in range(3):
        for a in range(3):
            s = 0.0
            for j in range(3):
                s += sigma_p[i, j] * Finv[a, j]
            out[i, a] = s


@numba.njit(cache=True)
def first_piola(idx, dF, sigma, P):
    """First Piola-Kirchhoff stress relative to the start-of-step configuration.

    P = J sigma dF^{-T},  J = det dF   (Nanson / Piola transform, e.g.
    Bonet & Wood, *Nonlinear Continuum Mechanics for FE Analysis*, 2nd ed., eq. 5.42).
    Writes P[idx], shape (n, 3, 3).
    """
    Finv = np.empty((3, 3))
    sFt = np.empty((3, 3))
    for q in range(idx.shape[0]):
        p = idx[q]
        J = inv3(dF[p], Finv)
        _sigma_FinvT(sigma[p], Finv, sFt)
        for i in range(3):
            for a in range(3):
                P[p, i, a] = J * sFt[i, a]


@numba.njit(cache=True)
def _piola_tangent(idx, dF, sigma, dsig, A, m, lo, hi):
    Finv = np.empty((3, 3))
    sFt = np.empty((3, 3))
    for q in range(lo, hi):
        p = idx[q]
        J = inv3(dF[p], Finv)
        _sigma_FinvT(sigma[p], Finv, sFt)
        for i in range(m):
            for a in range(m):
                for k in range(m):
                    for L in range(m):
                        v = Finv[L, k] * sFt[i, a] - sFt[i, L] * Finv[a, k]
                        s = 0.0
                        for j in range(3):
                            s += dsig[p, i, j, k, L] * Finv[a, j]
                        A[p, i, a, k, L] = J * (v + s)


@numba.njit(parallel=PRANGE, cache=True)
def first_piola_tangent(idx, dF, sigma, dsig, A, plane=False):
    """Tangent of ``first_piola`` w.r.t. the incremental deformation gradient.

    A[p,i,J,k,L] = dP_iJ / d dF_kL
                 = J (dF^-1)_Lk sigma_ij (dF^-1)_Jj
                 + J dsig_ijkL (dF^-1)_Jj
                 - J sigma_ij (dF^-1)_Jk (dF^-1)_Lj          (sum over j),
    using dJ = J (dF^-1)_Lk d dF_kL and d(dF^-1) = -dF^-1 d(dF) dF^-1
    (Bonet & Wood 2008, sec. 2.3).  ``dsig`` = d sigma / d dF, shape (n,3,3,3,3).
    plane=True: only the in-plane entries (i, J, k, L < 2) are written (the others are left
    as they were), for a 2D stiffness that reads no more (kernels.transfer.assemble_stiffness,
    kernels.fbar.fbar_stiffness; not the axisymmetric hoop terms). Threaded over particle
    chunks (kernels.threads): the same bits on any number of threads.
    """
    m = 2 if plane else 3
    n = idx.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        _piola_tangent(idx, dF, sigma, dsig, A, m, 0, n)
        return
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _piola_tangent(idx, dF, sigma, dsig, A, m, lo, hi)


@numba.njit(cache=True)
def work_increment(dF, sigma_old, sigma_new, volume_old, volume_new, m=3):
    """1/2 (sigma_old : eps V_old + sigma_new : eps V_new), eps = sym(dF - I), for one
    particle (3x3 arrays): the trapezoidal stress work of a step (Belytschko, Liu & Moran,
    *Nonlinear FE for Continua and Structures*, sec. 6.2.6 energy balance). m = 2: the
    in-plane block (plane strain, where the out-of-plane strain is 0)."""
    so = 0.0
    sn = 0.0
    for i in range(m):
        for j in range(m):
            e = 0.5 * (dF[i, j] + dF[j, i])
            if i == j:
                e -= 1.0
            so += sigma_old[i, j] * e
            sn += sigma_new[i, j] * e
    return 0.5 * (so * volume_old + sn * volume_new)


@numba.njit(cache=True)
def strain_energy_increment(idx, dF, sigma_old, sigma_new, volume_old, volume_new, w):
    """Trapezoidal strain-work increment, accumulated into ``w`` (see work_increment).
    ``volume_old``/``volume_new``/``w`` have shape (n,)."""
    for q in range(idx.shape[0]):
        p = idx[q]
        w[p] += work_increment(dF[p], sigma_old[p], sigma_new[p], volume_old[p], volume_new[p])
