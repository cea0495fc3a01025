"""Particle-layer Robin boundary (seed 000 §3.3, methods 2/4): the viscous or viscoelastic
law integrated over a layer of boundary particles with their shape functions,

    f_i = sum_{p in layer} N_ip t(u_p, v_p, n_p) a_p,

instead of over mesh facets. The layer moves with the material, so the absorbing boundary
follows it when the material boundary leaves the mesh boundary (large deformation). The
current normal and area follow Nanson's formula a_p n_p = J F^-T (A_p N_p) from the layer's
reference area vector. Per-particle data (optional fields, they migrate with the particles):
  layer_an0 (n, d): A_p N_p (zero for particles outside every layer),
  layer_coef (n, 4): c_n = a rho c_p, c_t = b rho c_s, k_n, k_s,
  layer_u0 (n, d): the particle displacement when the layer was added.
Implicit tangent (normal frozen within the step), added through the CSR scatter plan:
  K_ij += sum_p N_ip N_jp a_p [(k_n + c_v c_n) n n^T + (k_s + c_v c_t)(I - n n^T)].
"""
import warnings

import numpy as np
from numba import njit

from ..kernels.transfer import add_block
from ..materials.piola import inv3
from .robin import Viscoelastic, Viscous


class ParticleLayer:
    """A Viscous or Viscoelastic law applied on the particles selected by region(x).

    normal: outward unit normal of the boundary in the current configuration (a vector).
    thickness: the layer's thickness along the normal (area = V / thickness); default the
    particle size V^(1/d)."""

    def __init__(self, law, region, normal, thickness=None):
        if not isinstance(law, Viscous):
            raise TypeError(f"ParticleLayer: 'law' must be fm.Viscous or fm.Viscoelastic, got "
                            f"{type(law).__name__} (user UFL laws act on mesh facets only)")
        if not callable(region):
            raise TypeError("ParticleLayer: 'region' must be callable region(x) -> bool")
        n = np.asarray(normal, dtype=np.float64)
        if n.ndim != 1 or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
            raise ValueError(f"ParticleLayer: 'normal' must be a non-zero vector, got {normal!r}")
        if thickness is not None and not (thickness > 0):
            raise ValueError(f"ParticleLayer: 'thickness' must be > 0, got {thickness!r}")
        self.law, self.region, self.thickness = law, region, thickness
        self.normal = n / np.linalg.norm(n)

    def attach(self, particles):
        """Mark the layer particles and store their reference area vector and coefficients.
        Returns the global number of layer particles."""
        p = particles
        d = p.gdim
        if self.normal.shape != (d,):
            raise ValueError(f"ParticleLayer: 'normal' must have length {d}, got {self.normal.shape}")
        law = self.law
        law.bind(p.materials)
        k_n = k_s = 0.0
        if isinstance(law, Viscoelastic):
            k_n, k_s = law.k_n, law.k_s
        sel = np.asarray(self.region(p.x), dtype=bool)
        an0 = p.add_field("layer_an0", (d,))
        taken = sel & np.any(an0 != 0.0, axis=1)
        n_taken = int(np.count_nonzero(taken))
        if p.grid.comm.size > 1:
            n_taken = p.grid.comm.allreduce(n_taken)
        if n_taken and p.grid.comm.rank == 0:
            warnings.warn(f"ParticleLayer: {n_taken} particle(s) already belong to another layer; "
                          f"a particle carries one layer, the one added last", RuntimeWarning,
                          stacklevel=3)
        coef = p.add_field("layer_coef", (4,))
        u0 = p.add_field("layer_u0", (d,))
        t = p.V[sel] ** (1.0 / d) if self.thickness is None else self.thickness
        # reference configuration = the current one: the area vector is pulled back through F
        # so that Nanson's formula gives a n = (V / thickness) normal now
        an_now = (p.V[sel] / t)[:, None] * self.normal
        an0[sel] = pull_back_area(p.F[sel], an_now, d)
        coef[sel] = (law.a * law.rho * law.cp, law.b * law.rho * law.cs, k_n, k_s)
        u0[sel] = p.u[sel]
        n = int(np.count_nonzero(sel))
        n = p.grid.comm.allreduce(n) if p.grid.comm.size > 1 else n
        if n == 0:
            raise ValueError("ParticleLayer: 'region' selects no particle")
        return n


def pull_back_area(F, an, d):
    """A N = F^T a n / J (inverse of Nanson's formula), per particle (set-up only)."""
    return np.einsum("pji,pj->pi", F[:, :d, :d], an) / np.linalg.det(F)[:, None]


@njit(cache=True)
def _current_area_normal(F, an0, d, n_out):
    """a n = J F^-T (A N); returns a and writes n."""
    Finv = np.empty((3, 3))
    J = inv3(F, Finv)
    a = 0.0
    for i in range(d):
        s = 0.0
        for k in range(d):
            s += Finv[k, i] * an0[k]
        n_out[i] = J * s
        a += n_out[i] * n_out[i]
    a = np.sqrt(a)
    for i in range(d):
        n_out[i] /= a
    return a


@njit(cache=True)
def layer_force(D, layer, nodes, N, F, an0, coef, u_rel, v, out):
    """out_i += sum_{p in layer} N_ip t_p a_p with the Kelvin-Voigt traction
    t = -c_n (v.n) n - c_t (v - (v.n) n) - k_n (u.n) n - k_s (u - (u.n) n)."""
    d = len(D)
    n = np.empty(d)
    for q in range(layer.shape[0]):
        p = layer[q]
        a = _current_area_normal(F[p], an0[p], d, n)
        vn = 0.0
        un = 0.0
        for k in range(d):
            vn += v[p, k] * n[k]
            un += u_rel[p, k] * n[k]
        for k in range(d):
            t = (-coef[p, 0] * vn * n[k] - coef[p, 1] * (v[p, k] - vn * n[k])
                 - coef[p, 2] * un * n[k] - coef[p, 3] * (u_rel[p, k] - un * n[k]))
            for b in range(nodes.shape[1]):
                out[nodes[p, b], k] += N[p, b] * t * a


@njit(cache=True)
def layer_tangent(D, layer, nodes, N, F, an0, coef, c_v, plan, nodeptr, constrained, data):
    """data += sum_p N_ip N_jp a_p [(k_n + c_v c_n) n n + (k_s + c_v c_t)(I - n n)]."""
    d = len(D)
    n = np.empty(d)
    block = np.empty((d, d))
    for q in range(layer.shape[0]):
        p = layer[q]
        a = _current_area_normal(F[p], an0[p], d, n)
        cn = coef[p, 2] + c_v * coef[p, 0]
        ct = coef[p, 3] + c_v * coef[p, 1]
        for i_ in range(nodes.shape[1]):
            i = nodes[p, i_]
            deg = nodeptr[i + 1] - nodeptr[i]
            for j_ in range(nodes.shape[1]):
                w = N[p, i_] * N[p, j_] * a
                if w == 0.0:
                    continue
                for r in range(d):
                    for c in range(d):
                        block[r, c] = w * ((cn - ct) * n[r] * n[c] + (ct if r == c else 0.0))
                add_block(data, plan[p, i_, j_], deg, i, nodes[p, j_], d, constrained, block)


@njit(cache=True)
def pressure_force(D, loaded, nodes, N, F, an0, pressure, out):
    """out_i -= sum_{p in loaded} N_ip pressure a_p n_p, a_p n_p = J F^-T (A_p N_p) (Nanson):
    a follower pressure on the surface the particles carry (Simulation.add_surface_pressure)."""
    d = len(D)
    n = np.empty(d)
    for q in range(loaded.shape[0]):
        p = loaded[q]
        a = _current_area_normal(F[p], an0[p], d, n)
        for k in range(d):
            t = -pressure * a * n[k]
            for b in range(nodes.shape[1]):
                out[nodes[p, b], k] += N[p, b] * t
