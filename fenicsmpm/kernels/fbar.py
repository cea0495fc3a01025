"""F-bar: the volume change of the incremental deformation gradient averaged over each cell
(issue 21, volumetric locking under isochoric plastic flow; de Souza Neto et al. 1996, for
MPM Coombs, Charlton, Cortis & Augarde 2018, eq 20 ff., and Zhao, Jiang & Liang for explicit
MPM). For the particles p of a cell c, with J_p = det dF_p and V_p their volumes,
    Jbar_c = sum_p V_p J_p / sum_p V_p,       dF_p <- (Jbar_c / J_p)^(1/n) dF_p,
n = 2 on the in-plane block in plane strain (dF_33 = 1 stays), 3 in 3D and on axisymmetric
grids (the hoop stretch is part of the volume change). The deviatoric part of every particle's
increment is kept; one volume change per cell instead of one constraint per particle."""
import numpy as np
from numba import njit


@njit(cache=True)
def _det3(a):
    return (a[0, 0] * (a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1])
            - a[0, 1] * (a[1, 0] * a[2, 2] - a[1, 2] * a[2, 0])
            + a[0, 2] * (a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]))


@njit(cache=True)
def fbar(cell, V, dF, n_cells, n):
    """dF (particles, 3, 3) in place, as in the module docstring; cell: each particle's group
    (its local cell, or cell and body), < n_cells (all of a cell's particles are on the rank
    that owns it, so no communication)."""
    sv = np.zeros(n_cells)
    sj = np.zeros(n_cells)
    for p in range(len(cell)):
        c = cell[p]
        sv[c] += V[p]
        sj[c] += V[p] * _det3(dF[p])
    for p in range(len(cell)):
        c = cell[p]
        J = _det3(dF[p])
        Jb = sj[c] / sv[c]
        if J > 0.0 and Jb > 0.0:
            s = (Jb / J) ** (1.0 / n)
            for i in range(n):
                for j in range(n):
                    dF[p, i, j] *= s
