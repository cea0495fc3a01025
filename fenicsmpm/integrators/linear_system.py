"""The implicit grid system: a PETSc AIJ matrix with dolfinx's sparsity, filled from particle
quadrature through a precomputed CSR scatter plan, and a KSP configured by PETSc options.

Created only by implicit integrators (an explicit run builds no matrix and no KSP)."""
import numpy as np
import ufl
from dolfinx import fem
import dolfinx.fem.petsc
from petsc4py import PETSc

from ..kernels import transfer as kt

DEFAULT_PREFIX = "fenicsmpm_"


class LinearSystem:
    """K du = R on the vector P1/Q1 space of `grid`.

    The local (ghost-inclusive) CSR structure is the node adjacency of the cells expanded to
    blocks; PETSc's matrix comes from dolfinx (`create_matrix` of a mass form, so the pattern
    is dolfinx's), and every assembly is one `setValuesLocalCSR` call. Constrained dofs
    (Dirichlet or inactive nodes) get a unit diagonal and zero right-hand side.

    Solver options: PETSc options under `prefix` (default "fenicsmpm_"), e.g.
    `-fenicsmpm_ksp_type cg -fenicsmpm_pc_type gamg`, or the `petsc_options` dict. The default
    is a direct LU (MUMPS on several ranks)."""

    def __init__(self, grid, petsc_options=None, prefix=DEFAULT_PREFIX):
        self.grid = grid
        bs = self.bs = grid.gdim
        cn = grid.cell_nodes.astype(np.int64)
        nv = cn.shape[1]
        rows = np.repeat(cn, nv, axis=1).ravel()
        cols = np.tile(cn, (1, nv)).ravel()
        key = np.unique(rows * grid.n_nodes + cols)
        adj_rows = key // grid.n_nodes
        self.adj = np.ascontiguousarray(key % grid.n_nodes, dtype=np.int64)
        counts = np.bincount(adj_rows, minlength=grid.n_nodes)
        self.nodeptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.indptr, self.indices = kt.scalar_csr(self.nodeptr, self.adj, bs)
        self.diag = kt.diagonal_slots(self.nodeptr, self.adj, bs)
        self.data = np.zeros(len(self.indices))
        u, w = ufl.TrialFunction(grid.V), ufl.TestFunction(grid.V)
        self.A = dolfinx.fem.petsc.create_matrix(fem.form(ufl.inner(u, w) * ufl.dx))
        self.b = fem.Function(grid.V)
        self.x = fem.Function(grid.V)
        self.n_owned_dofs = grid.n_owned_nodes * bs
        self.ksp = PETSc.KSP().create(grid.comm)
        self.ksp.setOperators(self.A)
        self.ksp.setOptionsPrefix(prefix)
        # options: command line (-fenicsmpm_...) < built-in defaults for unset keys < the
        # petsc_options dict; what this object put into the options database is taken out
        # again after setFromOptions, so it cannot leak into the next simulation
        opts = PETSc.Options()
        _insert_command_line_options(prefix)
        merged = {"ksp_type": "preonly", "pc_type": "lu"}
        if grid.comm.size > 1:
            merged["pc_factor_mat_solver_type"] = "mumps"
        merged = {k: v for k, v in merged.items() if not opts.hasName(prefix + k)}
        merged.update(petsc_options or {})
        saved = {k: opts.getString(prefix + k) for k in merged if opts.hasName(prefix + k)}
        for k, v in merged.items():
            opts[prefix + k] = v
        self.ksp.setFromOptions()
        unused = [k for k in (petsc_options or {}) if not _option_used(prefix + k)]
        for k in merged:
            opts.delValue(prefix + k)
            if k in saved:
                opts[prefix + k] = saved[k]
        self.iterations = 0
        if unused:
            raise ValueError(f"petsc_options: PETSc did not use {sorted(unused)} (misspelt, or "
                             f"not an option of the chosen KSP/PC); see the PETSc manual pages of "
                             f"KSPSetFromOptions and PCSetFromOptions")

    def plan(self, nodes):
        """Scatter plan of the current particle-node connectivity (once per step)."""
        plan = np.empty(nodes.shape + (nodes.shape[1],), dtype=np.int64)
        kt.stiffness_plan(nodes, self.nodeptr, self.adj, self.bs, plan)
        return plan

    def assemble(self, nodes, dN, V, A4, plan, diag_add, constrained, extra=None):
        """Fill K = sum_p V_p B^T A_p B + diag(diag_add) with unit rows on constrained dofs;
        extra(data), if given, adds further particle terms to the local CSR values."""
        self.data[:] = 0.0
        kt.assemble_stiffness(self.grid.D, nodes, dN, V, A4, plan, self.nodeptr, constrained, self.data)
        if extra is not None:
            extra(self.data)
        own = self.n_owned_dofs
        d = self.diag[:own]
        if self.grid.periodic is not None:          # tied mass: on the master rows only
            diag_add = np.where(self.grid.periodic.slave_dofs(self.bs), 0.0, diag_add)
        self.data[d] += np.where(constrained[:own], 1.0, diag_add[:own])
        self.A.zeroEntries()
        self.A.setValuesLocalCSR(self.indptr, self.indices, self.data, addv=PETSc.InsertMode.ADD)
        self.A.assemble()

    def add(self, B):
        """K += B for a matrix whose pattern is within K's (dolfinx forms on the same space)."""
        self.A.axpy(1.0, B, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)

    def solve(self, R):
        """Solve K dx = R, where R (n_nodes, gdim) is complete (already summed) on every rank."""
        self.b.x.array[:] = R.ravel()
        tie = self.grid.periodic                    # master-slave reduction (boundaries.periodic)
        if tie is not None:
            self.b.x.array[tie.slave_dofs(self.bs)] = 0.0
            self.ksp.setOperators(tie.reduce(self.A))
        self.b.x.scatter_forward()
        self.ksp.solve(self.b.vector, self.x.vector)
        if tie is not None:
            tie.expand(self.x.vector.copy(), self.x.vector)
        reason = self.ksp.getConvergedReason()
        self.iterations = self.ksp.getIterationNumber()
        if reason < 0:
            raise RuntimeError(f"KSP failed: converged reason {reason} "
                               f"({_reason_name(reason)}) after {self.iterations} iterations")
        self.x.x.scatter_forward()
        return self.x.x.array.reshape(R.shape).copy()

    def destroy(self):
        self.ksp.destroy()
        self.A.destroy()


def _insert_command_line_options(prefix, argv=None):
    """Copy `-<prefix>name [value]` arguments from the command line into PETSc's options
    database (dolfinx initialises PETSc without sys.argv, so they would be ignored)."""
    import sys
    argv = sys.argv[1:] if argv is None else argv
    opts = PETSc.Options()
    for i, a in enumerate(argv):
        if a.startswith("-" + prefix):
            nxt = argv[i + 1] if i + 1 < len(argv) else None
            value = nxt if nxt is not None and not (nxt.startswith("-") and not _is_number(nxt)) else None
            if not opts.hasName(a[1:]):
                opts[a[1:]] = value if value is not None else ""


def _is_number(s):
    try:
        float(s)
        return True
    except ValueError:
        return False


_PETSC_LIB = None


def _option_used(name):
    """Whether PETSc read option `name` (no leading dash): PetscOptionsUsed, which petsc4py
    3.18 does not wrap, called in the PETSc library petsc4py loaded (found in /proc/self/maps)."""
    import ctypes
    global _PETSC_LIB
    if _PETSC_LIB is None:
        with open("/proc/self/maps") as maps:
            paths = [ln.split()[-1] for ln in maps if "/libpetsc" in ln]
        _PETSC_LIB = ctypes.CDLL(paths[0])
    used = ctypes.c_int(0)
    _PETSC_LIB.PetscOptionsUsed(None, name.encode(), ctypes.byref(used))
    return bool(used.value)


def _reason_name(code):
    for k, v in vars(PETSc.KSP.ConvergedReason).items():
        if v == code and not k.startswith("_"):
            return k
    return "unknown"
