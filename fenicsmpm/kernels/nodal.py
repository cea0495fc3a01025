"""The explicit grid update on nodal arrays, one threaded pass per formula (issue 16).

With m_i the nodal mass, (m v)_i the momentum, f_i the force, `free` the unconstrained
components and k the step's kick (dt, or dt / 2 on a leapfrog start; integrators.explicit):
    1 / m_i                     on active nodes, 0 elsewhere           (inverse_mass)
    v_i  = (m v)_i / m_i  free                                         (grid_velocity)
    v_i' = v_i + k f_i / m_i  free                                     (kicked_velocity)
    R_i  = m_i (v_i' - ((m v)_i + k f_i) / m_i) / k  on fixed active components, else 0
                                                                       (fixed_reaction)
and the particle acceleration a_p = (v_p' - v_p) / k (particle_acceleration). The numpy
expressions these replace made a temporary per operation (the reaction alone six
grid-sized arrays: 3.9 ms a step on the 263,169 nodes of bench throughput's scene, one
thread). Each formula is evaluated with the numpy expression's operations in its order, so
the results are the same bits (tests/test_nodal.py); the passes write per entry only, so
the thread count does not change them either."""
import numpy as np
from numba import njit, prange

from .threads import PRANGE, chunk, particle_chunks


@njit(cache=True)
def _inverse_mass(m, active, out, lo, hi):
    for i in range(lo, hi):
        out[i] = 1.0 / m[i] if active[i] else 0.0


@njit(parallel=PRANGE, cache=True)
def inverse_mass(m, active, out):
    """out_i = 1 / m_i where active_i, else 0 (np.divide(1, m, where=active) into zeros)."""
    n = m.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _inverse_mass(m, active, out, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _inverse_mass(m, active, out, lo, hi)


@njit(cache=True)
def _grid_velocity(mv, inv_m, free, out, lo, hi):
    for i in range(lo, hi):
        for k in range(mv.shape[1]):
            out[i, k] = mv[i, k] * inv_m[i] * (1.0 if free[i, k] else 0.0)


@njit(parallel=PRANGE, cache=True)
def grid_velocity(mv, inv_m, free, out):
    """out_ik = (m v)_ik inv_m_i free_ik (momentum * inv_m[:, None] * free)."""
    n = mv.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _grid_velocity(mv, inv_m, free, out, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _grid_velocity(mv, inv_m, free, out, lo, hi)


@njit(cache=True)
def _kicked(v0, f, inv_m, free, kick, out, lo, hi):
    for i in range(lo, hi):
        for k in range(v0.shape[1]):
            out[i, k] = v0[i, k] + kick * f[i, k] * inv_m[i] * (1.0 if free[i, k] else 0.0)


@njit(parallel=PRANGE, cache=True)
def kicked_velocity(v0, f, inv_m, free, kick, out):
    """out_ik = v0_ik + kick f_ik inv_m_i free_ik (v0 + kick * f * inv_m[:, None] * free)."""
    n = v0.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _kicked(v0, f, inv_m, free, kick, out, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _kicked(v0, f, inv_m, free, kick, out, lo, hi)


@njit(cache=True)
def _reaction(fixed, active, m, v1, mv, f, inv_m, kick, out, lo, hi):
    for i in range(lo, hi):
        for k in range(v1.shape[1]):
            if fixed[i, k] and active[i]:
                out[i, k] = m[i] * (v1[i, k] - (mv[i, k] + kick * f[i, k]) * inv_m[i]) / kick
            else:
                out[i, k] = 0.0


@njit(parallel=PRANGE, cache=True)
def fixed_reaction(fixed, active, m, v1, mv, f, inv_m, kick, out):
    """out_ik = m_i (v1_ik - (mv_ik + kick f_ik) inv_m_i) / kick on the fixed components of
    active nodes, 0 elsewhere: R = m (v - v*) / kick, the force the fixed dofs exert."""
    n = v1.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _reaction(fixed, active, m, v1, mv, f, inv_m, kick, out, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _reaction(fixed, active, m, v1, mv, f, inv_m, kick, out, lo, hi)


@njit(cache=True)
def _acceleration(v, a, kick, lo, hi):
    for p in range(lo, hi):
        for k in range(v.shape[1]):
            a[p, k] = (v[p, k] - a[p, k]) / kick


@njit(parallel=PRANGE, cache=True)
def particle_acceleration(v, a, kick):
    """a_p <- (v_p - a_p) / kick in place, a holding the start-of-step velocities."""
    n = v.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _acceleration(v, a, kick, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _acceleration(v, a, kick, lo, hi)
