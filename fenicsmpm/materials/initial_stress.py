"""K0 initial (geostatic) stress of a particle cloud (BENCHMARKS L1, seed 002 §4.3).

    sigma_v = -rho g d,   sigma_h = K0 sigma_v,   shear stresses 0   (compression negative),

with d the depth of a particle below the free surface; the vertical axis is the last
coordinate (y in 2D, z in 3D) and "horizontal" means every other direction, including the
out-of-plane zz of plane strain.  The default K0 = nu / (1 - nu) is the lateral stress ratio
of one-dimensional elastic loading (the gravity-column state of L1, and the K0 = nu/(1 - nu)
of the column collapse L3) and is used for every material, MohrCoulomb included; pass
K0 = 1 - sin(phi) explicitly for Jaky's normally consolidated value.
"""
import numpy as np
from mpi4py import MPI

__all__ = ["k0_stress"]


def _cloud_surface(p, xs, comm):
    """Height of the top of the particle cloud above each particle: the maximum of
    y_q + l_q (l_q = V_q^(1/gdim) / 2, the particle half-size) over the particles q of the
    particle's vertical column.  Columns are bins of width min_q 2 l_q centred on the
    particles of a regular fill; the per-column maxima are combined with one MPI allreduce of
    a per-column array (no gathering of particle arrays)."""
    n = len(p)
    half = 0.5 * np.power(p.V, 1.0 / p.gdim)
    lo = np.full(xs.shape[1], np.inf)
    hi = -lo
    width = np.array([np.inf])
    if n:
        lo[:], hi[:], width[0] = xs.min(axis=0), xs.max(axis=0), 2.0 * half.min()
    for arr, op in ((lo, MPI.MIN), (hi, MPI.MAX), (width, MPI.MIN)):
        comm.Allreduce(MPI.IN_PLACE, arr, op=op)
    origin = lo - 0.5 * width[0]
    nb = np.floor((hi - origin) / width[0]).astype(np.int64) + 1
    b = np.clip(np.floor((xs - origin) / width[0]).astype(np.int64), 0, nb - 1)
    flat = np.ravel_multi_index(tuple(b.T), tuple(nb))
    top = np.full(int(np.prod(nb)), -np.inf)
    np.maximum.at(top, flat, p.x[:, -1] + half)
    comm.Allreduce(MPI.IN_PLACE, top, op=MPI.MAX)
    return top[flat]


def k0_stress(particles, density=None, gravity=9.81, K0=None, surface=None):
    """Set ``particles.stress`` to the K0 state sigma_v = -rho g d, sigma_h = K0 sigma_v.

    density: None (each particle's mass / V), a scalar, or an array over the local particles.
    gravity: g > 0 (acceleration magnitude, acting along -last axis).
    K0: None (nu / (1 - nu) of each particle's material), a scalar, or a local array.
    surface: a callable height(x) -> (n,) for positions x of shape (n, gdim), or None for the
        top of the particle cloud per vertical column (see _cloud_surface).
    Collective under MPI when surface is None.  Returns the depths d (local particles).
    """
    p = particles
    comm = p.grid.comm
    g = float(gravity)
    if not (np.isfinite(g) and g > 0.0):
        raise ValueError(f"k0_stress: 'gravity' must be > 0, got {gravity!r}")
    rho = p.mass / p.V if density is None else np.broadcast_to(
        np.asarray(density, dtype=np.float64), (len(p),))
    if np.any(~(rho > 0.0)):
        raise ValueError(f"k0_stress: 'density' must be > 0, got {rho[~(rho > 0.0)][0]!r}")
    if K0 is None:
        nu = np.array([m.nu if hasattr(m, "nu") else np.nan for m in p.materials])[p.material_id]
        if np.any(np.isnan(nu)):
            raise ValueError("k0_stress: 'K0' must be given for materials without Poisson's "
                             "ratio nu")
        k0 = nu / (1.0 - nu)
    else:
        k0 = np.broadcast_to(np.asarray(K0, dtype=np.float64), (len(p),))
        if np.any(~(k0 >= 0.0)):
            raise ValueError(f"k0_stress: 'K0' must be >= 0, got {k0[~(k0 >= 0.0)][0]!r}")
    y = p.x[:, -1]
    if surface is None:
        top = _cloud_surface(p, p.x[:, :-1], comm)
    else:
        top = np.broadcast_to(np.asarray(surface(p.x), dtype=np.float64), (len(p),))
    d = np.maximum(top - y, 0.0)
    sv = -rho * g * d
    p.stress[:] = 0.0
    for i in range(p.gdim - 1):
        p.stress[:, i, i] = k0 * sv
    p.stress[:, p.gdim - 1, p.gdim - 1] = sv
    if p.gdim == 2:
        p.stress[:, 2, 2] = k0 * sv
    return d
