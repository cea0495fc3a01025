"""Frictional rigid boundary on grid nodes: unilateral, gap-consistent contact with Coulomb
friction (seed 002 §5.1, eqs 5.8-5.11, with the static check).

Gap. Each boundary node i has an outward unit normal n_i (given, or the facet-area weighted
normal of the selected boundary facets) and a gap g_i: the smallest distance between the
base plane through x_i and the material near it,
    g_i = min_p [(x_i - x_p) . n_i - r_p]   over the particles p with N_ip > 0,
with r_p = (V_p)^(1/d) / 2 the particle's half-size (per radian and radius on axisymmetric
grids: the meridian size). Material resting on the base has g = 0 (a row of particles at
h/4 with half-size h/4), material in flight g > 0.

Projection. After the grid update gives the trial velocity v* (no contact force), the normal
velocity into the base is limited by the gap, v_n <= max(g, 0) / dt:
    v*_n = v* . n  <= g / dt   no contact: free flight, approach allowed until the gap closes,
                               separation allowed;
    v*_n  > g / dt             contact with the compressive normal impulse per unit mass
                               dv_n = v*_n - g / dt (f_n = m dv_n / dt > 0), and
    v*_t = v* - v*_n n         is reduced by Coulomb friction, |f_t| <= mu f_n (eq 5.8):
        |v*_t| <= mu dv_n      stick (the static check the seed leaves out): v_t = 0,
        otherwise              slip:  v_t = v*_t (1 - mu dv_n / |v*_t|).
Cutting the approach only where the gap is closed is what keeps a body at rest: with the
plain velocity test (approach always cut, separation always allowed) the stress waves of a
body standing on the base are rectified into a climb (issue 17). Explicit integrators call
this on the trial velocity and on every velocity the stress update sees."""
import numpy as np
import ufl
from dolfinx import fem
import dolfinx.fem.petsc  # noqa: F401 (fem.petsc.assemble_vector)
from dolfinx import mesh as dmesh
from numba import njit

_FAR = 1e300          # gap of a node no particle touches


@njit(cache=True)
def node_gaps(D, nodes, N, x, V, axis_r, base_index, base_x, normals, gap):
    """gap[b] = min over particles p with N_ip > 0 at base node b of (x_b - x_p) . n_b - r_p,
    r_p = (V_p / r_p^axi)^(1/d) / 2 (module docstring); gap must be filled with _FAR."""
    d = len(D)
    for p in range(nodes.shape[0]):
        vol = V[p] / x[p, 0] if axis_r else V[p]
        r = 0.5 * vol ** (1.0 / d)
        for k in range(nodes.shape[1]):
            if N[p, k] <= 0.0:
                continue
            b = base_index[nodes[p, k]]
            if b < 0:
                continue
            g = -r
            for c in D:
                g += (base_x[b, c] - x[p, c]) * normals[b, c]
            if g < gap[b]:
                gap[b] = g


@njit(cache=True)
def coulomb_project(nodes, normals, gap, dt, mu, v, status, decide):
    """Apply the projection of the module docstring in place to v[nodes].

    decide=True (the trial velocity): contact is decided and status[k] set to 0 (no
    contact), 1 (slip) or 2 (stick). decide=False (a velocity field the stress update sees
    after that, the start-of-step or the re-mapped one): nodes in contact keep the normal
    velocity of the contact, v_n = max(g, 0) / dt, stuck ones also v_t = 0, other nodes only
    get v_n <= max(g, 0) / dt; so the strain sees the material on the base exactly where the
    momentum was."""
    d = v.shape[1]
    for k in range(nodes.shape[0]):
        i = nodes[k]
        if decide:
            status[k] = 0
        if gap[k] >= _FAR:
            continue
        allowed = max(gap[k], 0.0) / dt
        vn = 0.0
        for c in range(d):
            vn += v[i, c] * normals[k, c]
        if (decide or status[k] == 0) and vn <= allowed:
            continue
        if decide:
            dvn = vn - allowed
            vt2 = 0.0
            for c in range(d):
                t = v[i, c] - vn * normals[k, c]
                vt2 += t * t
            vt = np.sqrt(vt2)
            scale = 0.0 if vt <= mu * dvn else 1.0 - mu * dvn / vt
            status[k] = 2 if scale == 0.0 else 1
        else:
            scale = 0.0 if status[k] == 2 else 1.0
        for c in range(d):
            v[i, c] = allowed * normals[k, c] + scale * (v[i, c] - vn * normals[k, c])


def facet_normals(grid, where, owner):
    """Outward unit normals at the nodes of the exterior facets selected by where(x): the
    facet-area weighted average int_facets n . phi_i ds (one UFL form), normalised; zero rows
    at nodes on no selected facet."""
    from .robin import facets_on_boundary
    msh = grid.mesh
    fdim = msh.topology.dim - 1
    facets = np.sort(facets_on_boundary(grid, where, owner)).astype(np.int32)
    tags = dmesh.meshtags(msh, fdim, facets, np.ones(len(facets), dtype=np.int32))
    ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
    form = fem.form(ufl.inner(ufl.FacetNormal(msh), ufl.TestFunction(grid.V)) * ds(1))
    vec = fem.petsc.assemble_vector(form)
    from petsc4py import PETSc
    vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    vec.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    with vec.localForm() as loc:
        n = loc.array.reshape(-1, grid.gdim).copy()
    vec.destroy()
    length = np.linalg.norm(n, axis=1)
    on = length > 1e-12 * max(float(length.max()) if len(length) else 0.0, 1e-300)
    n[on] /= length[on, None]
    n[~on] = 0.0
    return n, on


class FrictionalBoundary:
    """A rigid frictional boundary with Coulomb coefficient `mu` on the grid nodes where(x).

    normal: the outward unit normal (e.g. (0, -1) for a base at the bottom of the mesh), or
    None: per node, from the mesh facets selected by where(x) (inclined and curved bases
    along any mesh boundary). The boundary's nodes must not also be fixed in the normal
    direction (the contact does it, and lets the material separate). After each step
    `reaction()` (collective) is the force the material exerts on the boundary."""

    def __init__(self, where, mu, normal=None):
        if not callable(where):
            raise TypeError(f"FrictionalBoundary: 'where' must be callable where(x) -> bool, "
                            f"got {type(where).__name__}")
        if not (isinstance(mu, (int, float, np.floating)) and np.isfinite(mu) and mu >= 0):
            raise ValueError(f"FrictionalBoundary: 'mu' must be a finite number >= 0, got {mu!r}")
        if normal is not None:
            n = np.asarray(normal, dtype=np.float64)
            if n.ndim != 1 or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
                raise ValueError(f"FrictionalBoundary: 'normal' must be a non-zero vector or None, "
                                 f"got {normal!r}")
            normal = n / np.linalg.norm(n)
        self.where, self.mu, self.normal = where, float(mu), normal
        self.nodes = None
        self._force = None
        self.status = None

    def bind(self, grid):
        d = grid.gdim
        if self.normal is not None and self.normal.shape != (d,):
            raise ValueError(f"FrictionalBoundary: 'normal' must have length {d}, "
                             f"got {self.normal.shape[0]}")
        nodes = grid.nodes_where(self.where)
        if grid.global_count(nodes[: grid.n_owned_nodes]) == 0:
            raise ValueError("FrictionalBoundary: the locator 'where' matches no grid node")
        if self.normal is None:
            normals, on = facet_normals(grid, self.where, "FrictionalBoundary")
            nodes &= on
        self.nodes = np.ascontiguousarray(np.flatnonzero(nodes), dtype=np.int64)
        self.normals = np.ascontiguousarray(
            np.broadcast_to(self.normal, (len(self.nodes), d)) if self.normal is not None
            else normals[self.nodes])
        self.base_x = np.ascontiguousarray(grid.node_x[self.nodes])
        self.base_index = np.full(grid.n_nodes, -1, dtype=np.int64)
        self.base_index[self.nodes] = np.arange(len(self.nodes))
        self._owned = self.nodes < grid.n_owned_nodes
        self._grid = grid
        self._force = np.zeros(d)
        self.status = np.zeros(len(self.nodes), dtype=np.int8)   # of the last trial projection
        self.body_status = {}          # per body of fm.ExplicitContact
        return self

    def gaps(self, sim, particles=None):
        """The gap g_i of every boundary node (module docstring) from the particles (indices,
        default all) at their current positions; collective (the minimum over ranks)."""
        p, grid = sim.particles, self._grid
        sel = slice(None) if particles is None else particles
        g = np.full(len(self.nodes), _FAR)
        node_gaps(grid.D, sim.nodes[sel], sim.N[sel], p.x[sel], p.V[sel], grid.axisymmetric,
                  self.base_index, self.base_x, self.normals, g)
        if grid.comm.size > 1:
            g = -grid.reduce_max(-g, self.nodes)
        return g

    def apply(self, v, gap, dt, mass, status=None, add=False):
        """Project the trial nodal velocities v (n_nodes, gdim) in place for the gaps `gap`
        (from `gaps`) and decide which nodes are in contact (into `status`, default the
        boundary's own; one per body in fm.ExplicitContact). The force on the boundary, sum of
        m (v_trial - v) / dt over owned nodes (nodal mass `mass`), is kept for `reaction`
        (added to the kept one with `add`, for the bodies of a multi-body run)."""
        before = v[self.nodes].copy()
        coulomb_project(self.nodes, self.normals, gap, dt, self.mu, v,
                        self.status if status is None else status, True)
        dv = (before - v[self.nodes])[self._owned]
        f = (mass[self.nodes][self._owned, None] * dv).sum(axis=0) / dt
        self._force = self._force + f if add else f

    def hold(self, v, gap, dt, status=None):
        """Constrain a velocity field the stress update sees (the start-of-step or the
        re-mapped one) in place, consistently with the last `apply` (coulomb_project)."""
        coulomb_project(self.nodes, self.normals, gap, dt, self.mu, v,
                        self.status if status is None else status, False)

    def checkpoint_arrays(self):
        """The contact status the next step starts from (`hold` before any `apply`), as nodal
        arrays over the grid's local nodes (-1 off the boundary): "status", and "body<b>" per
        body of fm.ExplicitContact. Written by Simulation.checkpoint, matched to the nodes by
        their coordinates on restore (restore_arrays), so a restarted run starts each node
        stuck, sliding or free as the continuous run does."""
        def nodal(status):
            a = np.full(self._grid.n_nodes, -1, dtype=np.int8)
            a[self.nodes] = status
            return a
        out = {"status": nodal(self.status)}
        out.update({f"body{b}": nodal(st) for b, st in self.body_status.items()})
        return out

    def restore_arrays(self, arrays):
        """Set the contact status from nodal arrays written by checkpoint_arrays."""
        for name, a in arrays.items():
            st = np.ascontiguousarray(a[self.nodes], dtype=np.int8)
            if name == "status":
                self.status = st
            else:
                self.body_status[int(name[len("body"):])] = st

    def reaction(self):
        """Force the material exerted on the boundary in the last step (sum over ranks:
        collective). Its normal part is the base's normal load, its tangential part friction."""
        f = self._force
        return self._grid.comm.allreduce(f) if self._grid.comm.size > 1 else f.copy()
