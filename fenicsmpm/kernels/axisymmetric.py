"""Axisymmetric MPM (Sulsky & Schreyer 1996): the 2D mesh is the meridian plane (r, z) of a
body of revolution, enabled with fm.Grid(mesh, axisymmetric=True).

Everything is per radian: a particle of meridian area A_p at radius r_p has volume
V_p = r_p A_p and mass m_p = rho r_p A_p, so the particle sums of the plane formulation
become the r-weighted integrals of the axisymmetric weak form, and boundary forms are
weighted by r (int t . w r ds). The hoop component of the deformation gradient is
F_tt = r / r_0, so det F and V = det(dF) V keep the per-radian volume. With w_i the nodal
velocity (explicit) or displacement increment (implicit) and r_p the particle radius at the
start of the step (the reference configuration of the step):
  dF_p,tt = 1 + scale sum_i N_ip w_i,r / r_p                                (hoop strain),
  f_i,r  -= V_p sigma_p,tt N_ip / r_p                                       (hoop force),
  K_(ia)(jb) += V_p [ d_a0 N_i/r A_ttbL dN_jL + d_b0 dN_iJ A_aJtt N_j/r
                      + d_a0 d_b0 N_i N_j A_tttt / r^2 ]                     (hoop stiffness),
with t = the third (out-of-plane) axis, A the tangent dP/dF of the step, a, b, J, L < 2. The
in-plane terms are those of plane strain. Materials see a full 3 x 3 dF, so any material
(linear elastic, Mohr-Coulomb, ...) works unchanged. The symmetry axis r = 0 gets u_r = 0.
"""
import numpy as np
import ufl
from numba import njit

from .transfer import add_block


def radius_weight(grid):
    """The UFL factor of boundary integrals: r = x[0] on an axisymmetric grid, else 1."""
    return ufl.SpatialCoordinate(grid.mesh)[0] if grid.axisymmetric else 1.0


def meridian_area(grid, x, volume):
    """Meridian (r, z) area of particles at x with volume `volume` (per radian when axisymmetric)."""
    return volume / x[:, 0] if grid.axisymmetric else volume


def check_radius(x, owner):
    """Particles of an axisymmetric body need r = x[0] > 0 (the volume r A vanishes on the axis)."""
    if len(x) and not np.all(x[:, 0] > 0):
        raise ValueError(f"{owner}: axisymmetric particles need r = x[0] > 0, got r = "
                         f"{x[np.argmin(x[:, 0]), 0]:.6g}")


@njit(cache=True)
def hoop_strain(nodes, N, field, rigid, w, scale, r, dF):
    """dF_p,tt = 1 + scale sum_i N_ip w[i, field_p, r] / r_p, with one nodal field per column
    of w (n_nodes, n_fields, 2): a single column for single-field MPM, one per body in
    multi-velocity contact (contact.multi_velocity), where rigid bodies keep dF_tt = 1."""
    for p in range(nodes.shape[0]):
        b = field[p]
        if rigid[b]:
            continue
        s = 0.0
        for a in range(nodes.shape[1]):
            s += N[p, a] * w[nodes[p, a], b, 0]
        dF[p, 2, 2] = 1.0 + scale * s / r[p]


@njit(cache=True)
def hoop_force(nodes, N, field, V, stress, r, out):
    """out[i, field_p, r] -= V_p stress_p,tt N_ip / r_p (stress: Cauchy, or the step's first
    Piola; fields as in hoop_strain)."""
    for p in range(nodes.shape[0]):
        c = V[p] * stress[p, 2, 2] / r[p]
        b = field[p]
        for a in range(nodes.shape[1]):
            out[nodes[p, a], b, 0] -= c * N[p, a]


@njit(cache=True)
def hoop_stiffness(nodes, N, dN, V, A, r, plan, nodeptr, constrained, data):
    """data += the hoop terms of the tangent (module docstring), at the CSR offsets of
    kernels.transfer.stiffness_plan, skipping constrained rows and columns."""
    block = np.empty((2, 2))
    for p in range(nodes.shape[0]):
        for a in range(nodes.shape[1]):
            i = nodes[p, a]
            deg = nodeptr[i + 1] - nodeptr[i]
            na = N[p, a] / r[p]
            for b in range(nodes.shape[1]):
                nb = N[p, b] / r[p]
                for k in range(2):
                    for c in range(2):
                        block[k, c] = 0.0
                block[0, 0] = na * nb * A[p, 2, 2, 2, 2]
                for c in range(2):
                    s = 0.0
                    for L in range(2):
                        s += A[p, 2, 2, c, L] * dN[p, b, L]
                    block[0, c] += na * s
                for k in range(2):
                    s = 0.0
                    for J in range(2):
                        s += dN[p, a, J] * A[p, k, J, 2, 2]
                    block[k, 0] += s * nb
                for k in range(2):
                    for c in range(2):
                        block[k, c] *= V[p]
                add_block(data, plan[p, a, b], deg, i, nodes[p, b], 2, constrained, block)

