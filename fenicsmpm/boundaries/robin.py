"""Robin boundaries on mesh facets as UFL forms: a traction t(u, v, n) that depends on the
boundary displacement u, velocity v and the facet normal n (seed 000 method 1, "mesh
boundary").

    L(w) = sum_k int_{Gamma_k} t_k(u, v, n) . w ds      (times r on axisymmetric grids)

is assembled by dolfinx into nodal forces. For implicit runs the tangent comes from UFL:
    dL = derivative(L, u)[du] + c_v derivative(L, v)[du],   c_v = dv/du (gamma/(beta dt) for
Newmark), so any user law, nonlinear included, gets its Jacobian without hand-written code.

u is the displacement of the boundary nodes since the boundary was added (integrated from the
nodal velocities: the mesh nodes are fixed in space), v the nodal velocity.

Laws (BENCHMARKS W, seed 000 §3.1, errata applied):
  Viscous (Lysmer-Kuhlemeyer):  t = -a rho c_p (v.n) n - b rho c_s (v - (v.n) n)
  Viscoelastic (Kelvin-Voigt):  viscous + (-k_n (u.n) n - k_s (u - (u.n) n)),
      Deeks-Randolph k_n = k_s = G / (2 r_b) (default); Kellezi k_n = rho c_p^2 / r_b,
      k_s = rho c_s^2 / r_b; virtual layer (Anura3D, CB-Geo) k = rho c^2 / delta.
"""
import math

import numpy as np
import ufl
from dolfinx import fem, mesh as dmesh
import dolfinx.fem.petsc
from petsc4py import PETSc

from ..kernels.axisymmetric import radius_weight

SPRINGS = ("deeks-randolph", "kellezi", "virtual-layer")


class Robin:
    """A user Robin law: traction(u, v, n) -> UFL vector expression, on facets where(x).

    `where` may be None only for a law used by fm.ParticleLayer (which selects particles)."""

    def __init__(self, traction, where):
        if not callable(traction):
            raise TypeError("Robin: 'traction' must be callable traction(u, v, n) -> UFL expression")
        if where is not None and not callable(where):
            raise TypeError("Robin: 'where' must be callable where(x) -> bool")
        self.traction, self.where = traction, where

    def bind(self, materials):
        """Resolve material-dependent coefficients (nothing to do for a user law)."""
        return self.traction


def _material_constants(owner, materials, density, p_wave_speed, s_wave_speed):
    if density is None or p_wave_speed is None or s_wave_speed is None:
        if len(materials) != 1:
            raise ValueError(f"{owner}: several materials are in the model; give 'density', "
                             f"'p_wave_speed' and 's_wave_speed' explicitly")
        m = materials[0]
        density = m.density if density is None else density
        p_wave_speed = m.p_wave_speed if p_wave_speed is None else p_wave_speed
        s_wave_speed = m.s_wave_speed if s_wave_speed is None else s_wave_speed
    for name, val in (("density", density), ("p_wave_speed", p_wave_speed),
                      ("s_wave_speed", s_wave_speed)):
        _check_coefficient(owner, name, val, strict=True)
    return float(density), float(p_wave_speed), float(s_wave_speed)


def _check_coefficient(owner, name, value, strict=False):
    if not isinstance(value, (int, float, np.floating)) or not math.isfinite(value) \
            or value < 0 or (strict and value == 0):
        raise ValueError(f"{owner}: '{name}' must be a {'positive' if strict else 'non-negative'} "
                         f"number, got {value!r}")


class Viscous(Robin):
    """Lysmer-Kuhlemeyer dashpots: t = -a rho c_p (v.n) n - b rho c_s (v - (v.n) n).

    rho, c_p, c_s come from the (single) material unless given."""

    def __init__(self, where=None, a=1.0, b=1.0, density=None, p_wave_speed=None,
                 s_wave_speed=None):
        _check_coefficient("Viscous", "a", a)
        _check_coefficient("Viscous", "b", b)
        for name, val in (("density", density), ("p_wave_speed", p_wave_speed),
                          ("s_wave_speed", s_wave_speed)):
            if val is not None:
                _check_coefficient("Viscous", name, val, strict=True)
        self.a, self.b = float(a), float(b)
        self.constants = (density, p_wave_speed, s_wave_speed)
        super().__init__(self._law, where)

    def bind(self, materials):
        self.rho, self.cp, self.cs = _material_constants(type(self).__name__, materials, *self.constants)
        return self._law

    def _dashpot(self, v, n):
        vn = ufl.dot(v, n)
        return -self.a * self.rho * self.cp * vn * n - self.b * self.rho * self.cs * (v - vn * n)

    def _law(self, u, v, n):
        return self._dashpot(v, n)


class Viscoelastic(Viscous):
    """Kelvin-Voigt boundary: the Viscous dashpots plus springs -k_n (u.n) n - k_s u_t.

    spring: "deeks-randolph" (k = G / (2 r_b), default), "kellezi" (k_n = rho c_p^2 / r_b,
    k_s = rho c_s^2 / r_b) or "virtual-layer" (k_n = rho c_p^2 / delta, k_s = rho c_s^2 / delta).
    r_b is the distance from the source to the boundary; delta the virtual layer thickness."""

    def __init__(self, where=None, r_b=None, delta=None, spring="deeks-randolph", **kw):
        super().__init__(where, **kw)
        if spring not in SPRINGS:
            raise ValueError(f"Viscoelastic: 'spring' must be one of {SPRINGS}, got {spring!r}")
        length = delta if spring == "virtual-layer" else r_b
        lname = "delta" if spring == "virtual-layer" else "r_b"
        if length is None:
            raise ValueError(f"Viscoelastic: the '{spring}' spring needs '{lname}' (a length > 0)")
        _check_coefficient("Viscoelastic", lname, length, strict=True)
        self.spring, self.length = spring, float(length)

    def bind(self, materials):
        super().bind(materials)
        rho, cp, cs, L = self.rho, self.cp, self.cs, self.length
        if self.spring == "deeks-randolph":
            self.k_n = self.k_s = rho * cs * cs / (2.0 * L)       # G / (2 r_b)
        else:
            self.k_n, self.k_s = rho * cp * cp / L, rho * cs * cs / L
        return self._law

    def _law(self, u, v, n):
        un = ufl.dot(u, n)
        return self._dashpot(v, n) - self.k_n * un * n - self.k_s * (u - un * n)


def facets_on_boundary(grid, where, owner):
    """Exterior facets selected by where(x); ValueError if none anywhere."""
    if where is None:
        raise ValueError(f"{owner}: a mesh boundary needs 'where' (a facet locator); without it "
                         f"use the law in fm.ParticleLayer")
    msh, gdim = grid.mesh, grid.gdim
    fdim = msh.topology.dim - 1
    msh.topology.create_connectivity(fdim, msh.topology.dim)
    f = dmesh.locate_entities_boundary(msh, fdim, lambda x: where(x.T[:, :gdim]))
    n = grid.comm.allreduce(len(f)) if grid.comm.size > 1 else len(f)
    if n == 0:
        raise ValueError(f"{owner}: the locator 'where' matches no boundary facet")
    return f


class RobinForms:
    """The compiled Robin forms of a simulation: one linear form, plus one bilinear tangent
    form for implicit runs."""

    def __init__(self, grid, boundaries, materials, implicit):
        msh, gdim = grid.mesh, grid.gdim
        fdim = msh.topology.dim - 1
        facets, tags = [], []
        for k, bc in enumerate(boundaries):
            f = facets_on_boundary(grid, bc.where, type(bc).__name__)
            facets.append(f)
            tags.append(np.full(len(f), k + 1, dtype=np.int32))
        facets, tags = np.concatenate(facets), np.concatenate(tags)
        order = np.argsort(facets)
        ds = ufl.Measure("ds", domain=msh,
                         subdomain_data=dmesh.meshtags(msh, fdim, facets[order], tags[order]))
        self.grid = grid
        self.u = fem.Function(grid.V)          # boundary displacement
        self.v = fem.Function(grid.V)          # boundary velocity
        w = ufl.TestFunction(grid.V)
        nrm = ufl.FacetNormal(msh)
        r = radius_weight(grid)                   # r on axisymmetric grids
        L = sum(r * ufl.inner(bc.bind(materials)(self.u, self.v, nrm), w) * ds(k + 1)
                for k, bc in enumerate(boundaries))
        # a law that is identically zero (e.g. a = b = 0) leaves an empty form: no force
        L = ufl.algorithms.expand_derivatives(L)
        self.L = None if L.empty() else fem.form(L)
        self._buf = np.zeros(grid.n_nodes * gdim)
        self.J = self.B = None
        if implicit and self.L is not None:
            du = ufl.TrialFunction(grid.V)
            self.c_v = fem.Constant(msh, PETSc.ScalarType(0.0))
            J = ufl.algorithms.expand_derivatives(
                -(ufl.derivative(L, self.u, du) + self.c_v * ufl.derivative(L, self.v, du)))
            if not J.empty():
                self.J = fem.form(J)
                self.B = dolfinx.fem.petsc.create_matrix(self.J)

    def force(self, u, v, out):
        """out += local Robin nodal forces for boundary displacement u and velocity v."""
        if self.L is None:
            return
        self.u.x.array[:] = u.ravel()
        self.v.x.array[:] = v.ravel()
        self._buf[:] = 0.0
        fem.assemble_vector(self._buf, self.L)
        out += self._buf.reshape(out.shape)

    def tangent(self, u, v, c_v, constrained_owned_dofs):
        """-dF/du (with dv/du = c_v) as a PETSc matrix, constrained rows/columns zeroed; None
        when the law does not depend on u or v."""
        if self.J is None:
            return None
        self.u.x.array[:] = u.ravel()
        self.v.x.array[:] = v.ravel()
        self.c_v.value = c_v
        self.B.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(self.B, self.J)
        self.B.assemble()
        self.B.zeroRowsColumnsLocal(constrained_owned_dofs, diag=0.0)
        return self.B
