"""Frictional rigid boundary on grid nodes (seed 002 §5.1, eqs 5.8-5.11, with the static check).

On the nodes of a fixed, flat boundary with outward unit normal n, after the grid update
gives the trial velocity v* (no contact force):
    v*_n = v* . n  > 0   the material presses into the boundary (compressive normal force
                         f_n = m v*_n / dt > 0): the normal velocity is removed, and
    v*_t = v* - v*_n n   is reduced by Coulomb friction, |f_t| <= mu f_n (eq 5.8):
        |v*_t| <= mu v*_n   stick (the static check the seed leaves out): v_t = 0,
        otherwise           slip:  v_t = v*_t (1 - mu v*_n / |v*_t|),
    v*_n <= 0            separation: no force.
This is the velocity form of the seed's force decomposition: the frictional force of eq 5.10
is -mu f_n t with t the slip direction, and eq 5.11 (the material stops) is the stick case,
decided here from the trial state, so a node that would reverse its tangential velocity
sticks instead. Explicit integrators only."""
import numpy as np
from numba import njit


@njit(cache=True)
def _coulomb_project(nodes, normal, mu, v):
    """Apply the projection above in place to v[nodes] (normal: unit outward normal)."""
    d = v.shape[1]
    for k in range(nodes.shape[0]):
        i = nodes[k]
        vn = 0.0
        for c in range(d):
            vn += v[i, c] * normal[c]
        if vn <= 0.0:
            continue
        vt2 = 0.0
        for c in range(d):
            t = v[i, c] - vn * normal[c]
            vt2 += t * t
        vt = np.sqrt(vt2)
        scale = 0.0 if vt <= mu * vn else 1.0 - mu * vn / vt
        for c in range(d):
            v[i, c] = scale * (v[i, c] - vn * normal[c])


class FrictionalBoundary:
    """A rigid flat boundary with Coulomb friction coefficient `mu` on the grid nodes where(x),
    outward unit normal `normal` (e.g. (0, -1) for a base at the bottom of the mesh).
    The boundary's nodes must not also be fixed in the normal direction (the contact does it,
    and lets the material separate)."""

    def __init__(self, where, mu, normal):
        if not callable(where):
            raise TypeError(f"FrictionalBoundary: 'where' must be callable where(x) -> bool, "
                            f"got {type(where).__name__}")
        if not (isinstance(mu, (int, float, np.floating)) and np.isfinite(mu) and mu >= 0):
            raise ValueError(f"FrictionalBoundary: 'mu' must be a finite number >= 0, got {mu!r}")
        n = np.asarray(normal, dtype=np.float64)
        if n.ndim != 1 or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
            raise ValueError(f"FrictionalBoundary: 'normal' must be a non-zero vector, got {normal!r}")
        self.where, self.mu, self.normal = where, float(mu), n / np.linalg.norm(n)
        self.nodes = None

    def bind(self, grid):
        if self.normal.shape != (grid.gdim,):
            raise ValueError(f"FrictionalBoundary: 'normal' must have length {grid.gdim}, "
                             f"got {self.normal.shape[0]}")
        nodes = grid.nodes_where(self.where)
        if grid.global_count(nodes[: grid.n_owned_nodes]) == 0:
            raise ValueError("FrictionalBoundary: the locator 'where' matches no grid node")
        self.nodes = np.ascontiguousarray(np.flatnonzero(nodes), dtype=np.int64)
        return self

    def apply(self, v):
        """Project the trial nodal velocities v (n_nodes, gdim) in place."""
        _coulomb_project(self.nodes, self.normal, self.mu, v)
