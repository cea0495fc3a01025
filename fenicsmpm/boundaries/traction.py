"""Tractions on mesh facets as UFL `ds` forms on tagged facets (assembled by dolfinx).

All tractions of a simulation share one compiled linear form
    L(w) = sum_k inner(t_k(t), w) ds(k)      (times r on axisymmetric grids),
whose constants t_k are updated every step; it is built only if a traction was added."""
import numpy as np
import ufl
from dolfinx import fem, mesh as dmesh
from petsc4py import PETSc

from ..kernels.axisymmetric import radius_weight


class Traction:
    """Traction vector value on the boundary facets selected by where(x).

    value is a constant vector or a callable t -> vector (time-dependent amplitude); `name`
    (e.g. "add_traction #0") is how errors refer to it."""

    def __init__(self, where, value, name="traction"):
        if not callable(where):
            raise TypeError(f"{name}: 'where' must be callable where(x) -> bool, got "
                            f"{type(where).__name__}")
        if not callable(value) and not _is_vector(value):
            raise TypeError(f"{name}: 'value' must be a vector or a function t -> vector, got "
                            f"{value!r}")
        self.where = where
        self.value = value
        self.name = name

    def at(self, t, gdim, nonfinite=FloatingPointError):
        """The traction vector at time t. A ValueError naming the traction if value(t) is not
        a vector of length gdim; `nonfinite` (FloatingPointError during a run, ValueError when
        the traction is added) if it is not finite."""
        raw = self.value(t) if callable(self.value) else self.value
        if not _is_vector(raw):
            raise ValueError(f"{self.name}: 'value' must give a vector of length {gdim}, got "
                             f"{raw!r} at t = {t:.6g}")
        val = np.asarray(raw, dtype=np.float64)
        if val.shape != (gdim,):
            raise ValueError(f"{self.name}: 'value' must give a vector of length {gdim}, got "
                             f"shape {val.shape} at t = {t:.6g}")
        if not np.all(np.isfinite(val)):
            raise nonfinite(f"{self.name}: 'value' gave the non-finite traction "
                                     f"{val.tolist()} at t = {t:.6g}")
        return val


def _is_vector(value):
    """Whether value converts to a 1-D float array."""
    try:
        return np.asarray(value, dtype=np.float64).ndim == 1
    except (TypeError, ValueError):
        return False


class TractionForms:
    """The compiled traction form of a simulation, assembled into a nodal force array."""

    def __init__(self, grid, tractions):
        msh, gdim = grid.mesh, grid.gdim
        fdim = msh.topology.dim - 1
        msh.topology.create_connectivity(fdim, msh.topology.dim)
        facets, tags = [], []
        for k, tr in enumerate(tractions):
            f = dmesh.locate_entities_boundary(msh, fdim, lambda x, w=tr.where: w(x.T[:, :gdim]))
            n = grid.comm.allreduce(len(f)) if grid.comm.size > 1 else len(f)
            if n == 0:
                raise ValueError(f"{tr.name}: the locator 'where' matches no boundary facet")
            facets.append(f)
            tags.append(np.full(len(f), k + 1, dtype=np.int32))
        facets = np.concatenate(facets)
        tags = np.concatenate(tags)
        order = np.argsort(facets)
        mt = dmesh.meshtags(msh, fdim, facets[order], tags[order])
        ds = ufl.Measure("ds", domain=msh, subdomain_data=mt)
        w = ufl.TestFunction(grid.V)
        self.tractions = tractions
        self.constants = [fem.Constant(msh, PETSc.ScalarType((0.0,) * gdim)) for _ in tractions]
        r = radius_weight(grid)                   # r on axisymmetric grids
        self.form = fem.form(sum(r * ufl.inner(c, w) * ds(k + 1) for k, c in enumerate(self.constants)))
        self.gdim = gdim
        self._buf = np.zeros(grid.n_nodes * gdim)

    def assemble(self, t, out):
        """out (n_nodes, gdim) += local facet contributions of the tractions at time t."""
        for tr, c in zip(self.tractions, self.constants):
            c.value[:] = tr.at(t, self.gdim)
        self._buf[:] = 0.0
        fem.assemble_vector(self._buf, self.form)
        out += self._buf.reshape(out.shape)
