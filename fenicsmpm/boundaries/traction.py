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

    value is a constant vector or a callable t -> vector (time-dependent amplitude)."""

    def __init__(self, where, value):
        if not callable(where):
            raise TypeError("Traction: 'where' must be callable where(x) -> bool")
        self.where = where
        self.value = value

    def at(self, t, gdim):
        val = np.asarray(self.value(t) if callable(self.value) else self.value, dtype=np.float64)
        if val.shape != (gdim,):
            raise ValueError(f"Traction: value must be a vector of length {gdim}, got shape {val.shape}")
        return val


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
                raise ValueError(f"add_traction: locator #{k} matches no boundary facet")
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
