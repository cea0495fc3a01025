"""Grid-smoothed particle stress (seed 002 eqs 4.18-4.19).

    sigma_i = sum_p Phi_ip m_p sigma_p / m_i          (4.18: mass-weighted nodal stress)
    sigma_p^smooth = sum_i Phi_ip sigma_i              (4.19: interpolated back)

A constant stress is reproduced exactly (partition of unity), and the mass-weighted total
sum_p m_p sigma_p is kept exactly: sum_p m_p sum_i Phi_ip sigma_i = sum_i m_i sigma_i. The seed
uses it for output only (feeding it back "failed"); Simulation(stress_feedback="smoothed")
feeds it into the internal force of explicit runs so that the benchmark can measure it."""
import numpy as np
from numba import njit


@njit(cache=True)
def _nodal_stress(nodes, N, mass, stress, out):
    """out_i += sum_p N_ip m_p stress_p (9 components)."""
    for p in range(nodes.shape[0]):
        for a in range(nodes.shape[1]):
            w = N[p, a] * mass[p]
            i = nodes[p, a]
            for k in range(3):
                for l in range(3):
                    out[i, k, l] += w * stress[p, k, l]


@njit(cache=True)
def _interpolate(nodes, N, nodal, out):
    """out_p = sum_i N_ip nodal_i (3 x 3 values)."""
    for p in range(nodes.shape[0]):
        for k in range(3):
            for l in range(3):
                s = 0.0
                for a in range(nodes.shape[1]):
                    s += N[p, a] * nodal[nodes[p, a], k, l]
                out[p, k, l] = s


def smoothed_stress(sim, stress, m=None):
    """Eqs 4.18-4.19 for `stress` (n, 3, 3) with the current shape functions of `sim`; `m` is
    the summed nodal mass when the caller has it. Returns a new (n, 3, 3) array."""
    p, grid = sim.particles, sim.grid
    if m is None:
        m = sim.nodal_mass()
        grid.accumulate(m)
    nodal = np.zeros((grid.n_nodes, 3, 3))
    _nodal_stress(sim.nodes, sim.N, p.mass, stress, nodal)
    grid.accumulate(nodal.reshape(grid.n_nodes, 9))
    nodal /= np.where(m > 0, m, 1.0)[:, None, None]
    out = np.empty_like(stress)
    _interpolate(sim.nodes, sim.N, nodal, out)
    return out
