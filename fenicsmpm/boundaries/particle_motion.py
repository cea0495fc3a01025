"""Prescribed particle displacement for the implicit integrators, by penalty: a displacement-
controlled footing, plate or wall that moves with the material instead of with the mesh
nodes (a node footing stops holding the soil once the soil under it has moved a cell).

For each selected particle p and constrained component c, a spring of stiffness k_p pulls
the particle's displacement to the prescribed one, u_c(X_p, t) (X_p its position when the
constraint was added):

    f_p = k_p (u_c(X_p, t^{n+1}) - u_p^n - du_p),   du_p = sum_j N_jp du_j,
    R_i += sum_p N_ip f_p,   K_ij += sum_p k_p N_ip N_jp   (component c only),

k_p = penalty M V_p / h^2, M = rho c_p^2 the particle's constrained modulus, h the cell size:
`penalty` times the stiffness of the particle's own material, so the constraint is met to
about 1/penalty of the elastic displacement of its cell. The target is the total
displacement, so the penalty's lag does not build up from step to step. The force the
constraint exerts on the material, sum_p f_p, is the reaction (Simulation.particle_reaction)."""
import numpy as np
from numba import njit

from ..kernels.transfer import add_block
from ..materials import constrained_moduli


class ParticleMotion:
    """One prescribed particle motion (Simulation.move_particles): `displacement(X, t)` ->
    (n, gdim) for the reference positions X of the particles selected by region(x) when it
    is added, on `components`."""

    def __init__(self, index, displacement, components, penalty):
        self.index, self.displacement = index, displacement
        self.components, self.penalty = components, float(penalty)
        self.reaction = None


def attach(sim, motion, region):
    """Mark the particles region(x) selects with motion.index + 1 and store their reference
    position, displacement and penalty stiffness (per-particle fields that migrate).
    Returns the global count."""
    p, d = sim.particles, sim.gdim
    sel = np.asarray(region(p.x))
    if sel.shape != (len(p),):
        raise ValueError(f"move_particles: 'region(x)' must return one bool per particle, "
                         f"shape ({len(p)},), got shape {sel.shape}")
    sel = sel.astype(bool)
    tag = p.add_field("motion_tag")
    x0 = p.add_field("motion_x0", (d,))
    u0 = p.add_field("motion_u0", (d,))
    k = p.add_field("motion_k")
    tag[sel] = motion.index + 1
    x0[sel] = p.x[sel]
    u0[sel] = p.u[sel]
    M = constrained_moduli(p.materials)
    k[sel] = motion.penalty * M[p.material_id[sel]] * p.V[sel] / sim.grid.h ** 2
    n = int(np.count_nonzero(sel))
    return sim.comm.allreduce(n) if sim.comm.size > 1 else n


def targets(sim, t):
    """(particles, target increment (n, d), component mask (n, d), stiffness) of the local
    particles under a prescribed motion at time t: u(X, t) - (u_p - u_p0) on the
    constrained components."""
    p, d = sim.particles, sim.gdim
    sel = np.flatnonzero(p.motion_tag) if hasattr(p, "motion_tag") else np.zeros(0, np.int64)
    target = np.zeros((len(sel), d))
    mask = np.zeros((len(sel), d))
    tag = p.motion_tag[sel].astype(np.int64) - 1 if len(sel) else sel
    for m in sim.particle_motions:
        q = np.flatnonzero(tag == m.index)
        if len(q) == 0:
            continue
        a = sel[q]
        u = np.asarray(m.displacement(p.motion_x0[a], t), dtype=float).reshape(len(q), d)
        for c in m.components:
            target[q, c] = u[:, c] - (p.u[a, c] - p.motion_u0[a, c])
            mask[q, c] = 1.0
    k = p.motion_k[sel] if len(sel) else np.zeros(0)
    return sel.astype(np.int64), target, mask, np.ascontiguousarray(k)


@njit(cache=True)
def penalty_force(sel, nodes, N, du, target, mask, k, out, f):
    """f_q = k_q mask (target_q - sum_j N_jp du_j), out_i += N_ip f_q (p = sel[q])."""
    d = du.shape[1]
    for q in range(sel.shape[0]):
        p = sel[q]
        for c in range(d):
            if mask[q, c] == 0.0:
                f[q, c] = 0.0
                continue
            s = 0.0
            for b in range(nodes.shape[1]):
                s += N[p, b] * du[nodes[p, b], c]
            f[q, c] = k[q] * (target[q, c] - s)
            for b in range(nodes.shape[1]):
                out[nodes[p, b], c] += N[p, b] * f[q, c]


@njit(cache=True)
def penalty_tangent(sel, nodes, N, mask, k, plan, nodeptr, constrained, data):
    """data += sum_q k_q N_ip N_jp on the constrained components (p = sel[q])."""
    d = mask.shape[1]
    block = np.zeros((d, d))
    for q in range(sel.shape[0]):
        p = sel[q]
        for i_ in range(nodes.shape[1]):
            i = nodes[p, i_]
            deg = nodeptr[i + 1] - nodeptr[i]
            for j_ in range(nodes.shape[1]):
                w = k[q] * N[p, i_] * N[p, j_]
                if w == 0.0:
                    continue
                for c in range(d):
                    block[c, c] = w * mask[q, c]
                add_block(data, plan[p, i_, j_], deg, i, nodes[p, j_], d, constrained, block)
