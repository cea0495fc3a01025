"""Ghost stabilisation of poorly filled cells for the implicit grid solve (Coombs 2020,
"Ghost stabilisation of the material point method for stable quasi-static and dynamic
analysis of large deformation problems", IJNME 121; Burman 2010's face ghost penalty).

A node that only the tail of one or two particles supports (a particle heaving into the
empty cell row above a surface, a cell left almost empty) has a stiffness row of a few
particles; when they yield (perfect plasticity: no stiffness along the flow direction) that
row is singular and Newton diverges there. The ghost penalty ties the displacement increment
of such cells to their neighbours' by penalising the jump of its normal gradient across the
faces of poorly filled cells:

    G(du, w) = gamma M sum_F h_F int_F [[grad du . n]] . [[grad w . n]] dS,

M = rho c_p^2 (the largest constrained modulus of the materials), h_F the mean cell diameter
of the face's cells, F every interior facet between two active cells (every node active) of
which at least one is poorly filled (particle volume below `fill` times its cell volume).
Newton's residual gets -G du and its Jacobian +G. The term acts on the step's increment only
(updated Lagrangian: nothing accumulates), vanishes for a field linear across the face and is
of order gamma h in the converged solution. One UFL form, compiled once, integrated over the
penalised facets only (meshtags, renewed when that set changes); the poorly filled cells are
found every step (the owned cells from their own particles, then scattered to the ghost cells
through a DG0 function). So G couples only the nodes of those facets' cell pairs (`pairs`),
and the tangent's pattern grows by just those pairs (LinearSystem.extend) instead of a second
cell ring everywhere: on the W5 footing of tests/test_implicit_footing.py (40 steps, serial)
an LU factorization of the standard family's tangent took 0.23 s with the two-ring pattern
against 0.08 s (PETSc -log_view, 167 factorizations)."""
import numpy as np
import ufl
from dolfinx import fem
import dolfinx.fem.petsc
from petsc4py import PETSc

from ..materials import constrained_moduli


class GhostPenalty:
    """The ghost matrix G of `sim` (module docstring): gamma = `factor`, cells with a particle
    volume below `fill` x their volume count as poorly filled."""

    def __init__(self, sim, factor, fill):
        grid = sim.grid
        if grid.axisymmetric:
            raise NotImplementedError("ghost > 0 needs a plane or 3D grid (got an axisymmetric "
                                      "grid: the penalty form has no hoop weighting)")
        msh = grid.mesh
        self.poor = fem.Function(fem.FunctionSpace(msh, ("DG", 0)))
        self.fill = float(fill)
        M = float(constrained_moduli(sim.particles.materials).max(initial=0.0))
        n, h = ufl.FacetNormal(msh), ufl.CellDiameter(msh)
        u, w = ufl.TrialFunction(grid.V), ufl.TestFunction(grid.V)
        self._integrand = (float(factor) * M * ufl.avg(h)
                           * ufl.inner(ufl.jump(ufl.grad(u), n), ufl.jump(ufl.grad(w), n)))
        self._msh = msh
        tdim = msh.topology.dim
        msh.topology.create_connectivity(tdim - 1, tdim)
        f2c = msh.topology.connectivity(tdim - 1, tdim)
        off = f2c.offsets
        self._facets = np.flatnonzero(np.diff(off) == 2).astype(np.int32)   # interior, local
        self._facet_cells = f2c.array[off[self._facets][:, None] + np.arange(2)]
        self._used = None               # the local facets integrated (penalised)
        self.version = 0                # counts changes of the set (collective)
        self.pairs = np.empty((0, 2), dtype=np.int64)
        self.G = self.Gz = None
        Q = self.poor.function_space
        vol = fem.petsc.assemble_vector(fem.form(ufl.TestFunction(Q) * ufl.dx))
        vol.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.volume = vol.array.copy()          # owned cells
        vol.destroy()
        self.x = fem.Function(grid.V)
        self.y = fem.Function(grid.V)

    def update(self, sim, active, constrained_owned_dofs):
        """Set the indicators from the particles and `active` nodes, assemble G and the copy
        with the constrained rows and columns zeroed (the tangent's)."""
        grid, p = sim.grid, sim.particles
        if grid.periodic is not None:      # its forces would need the tie's master-slave sum
            raise NotImplementedError("ghost > 0 is not available on periodic grids "
                                      "(Simulation.set_periodic)")
        own = grid.n_owned_cells
        filled = np.bincount(p.cell, weights=p.V, minlength=grid.n_cells)[:own]
        act = np.all(active[grid.cell_nodes], axis=1)          # every local cell
        poor = np.zeros(grid.n_cells)
        poor[:own] = filled < self.fill * self.volume
        self.poor.x.array[:] = poor
        self.poor.x.scatter_forward()
        self._select(grid, act, self.poor.x.array > 0.0)
        self.G.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(self.G, self.form)
        self.G.assemble()
        if self.Gz is None:
            self.Gz = self.G.duplicate(copy=True)
        else:
            self.G.copy(self.Gz, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self.Gz.zeroRowsColumnsLocal(constrained_owned_dofs, diag=0.0)

    def _select(self, grid, act, poor):
        """The penalised facets: interior, both cells active, one poorly filled (act, poor:
        boolean per local cell). When the set changes anywhere (collective), the form is
        restricted to the new set (dS with meshtags; dolfinx integrates the owned ones), G gets
        its pattern and `pairs` the node pairs of their cell pairs (every local one, the owned
        and the ghost facets)."""
        from dolfinx.mesh import meshtags
        fc = self._facet_cells
        use = act[fc[:, 0]] & act[fc[:, 1]] & (poor[fc[:, 0]] | poor[fc[:, 1]])
        used = self._facets[use]
        changed = self._used is None or not np.array_equal(used, self._used)
        comm = grid.comm
        if comm.size > 1:
            changed = comm.allreduce(changed)
        if not changed:
            return
        self._used = used
        tags = meshtags(self._msh, self._msh.topology.dim - 1, used,
                        np.ones(len(used), dtype=np.int32))
        dS = ufl.Measure("dS", domain=self._msh, subdomain_data=tags)
        self.ufl_form = self._integrand * dS(1)
        self.form = fem.form(self.ufl_form)
        for mat in (self.G, self.Gz):
            if mat is not None:
                mat.destroy()
        self.G = dolfinx.fem.petsc.create_matrix(self.form)
        self.Gz = None
        cn = grid.cell_nodes.astype(np.int64)
        a, b = cn[fc[use, 0]], cn[fc[use, 1]]
        nv = cn.shape[1]
        self.pairs = np.column_stack([np.repeat(a, nv, axis=1).ravel(),
                                      np.tile(b, (1, nv)).ravel()])
        self.version += 1

    def force(self, du):
        """G du as a nodal array (n_nodes, gdim), complete on every rank."""
        self.x.x.array[:] = du.ravel()
        self.G.mult(self.x.vector, self.y.vector)
        self.y.x.scatter_forward()
        return self.y.x.array.reshape(du.shape).copy()

    def destroy(self):
        for mat in (self.G, self.Gz):
            if mat is not None:
                mat.destroy()
