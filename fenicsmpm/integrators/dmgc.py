"""DM-GC: double mapping (DM) of the material tangent and composite MPM (CMPM) stress
increments for the implicit integrators (seed 000 §2.7-2.9, eqs 2.50-2.58; BENCHMARKS.md
"DM-GC and CMPM", corrected). 2D structured quadrilateral grids with shape "ugimp"/"cpgimp".

- Forces: the simulation's GIMP functions, f_int,i = sum_p V_p P_p grad S_ip (unchanged).
- Stiffness (eqs 2.50-2.53, 2.57): the particle tangent A_p = dP/d(dF) is mapped to the nodes
  of every cell e its GIMP box overlaps with the local (iGIMP) weights, then to the cell's
  2 x 2 Gauss points, where the bilinear-element stiffness is integrated:
      A_i^e = sum_p S*_ip^e W_p (omp_e / nmp_e) A_p,       S*_ip^e W_p = prod_k (2 / L_k) int_{Omega_p,k cap e} N_i,k dx_k,
      A_g   = sum_i N_i(x_g) A_i^e,      K^e = sum_g B^T(x_g) A_g B(x_g) |J| W_g.
  S*_ip^e = (1/V_p) int_{Omega_p cap e} N_i dx is the local GIMP weight and W_p = 2^d V_p / V_e
  the particle's volume in the parent cell [-1, 1]^d (seed: "the material point's volume
  corresponding to local coordinates"); omp_e / nmp_e (original over current number of
  particles whose centre is in the particle's own cell, eq 2.51; 1 in a cell that started
  empty) corrects for particles gathering in a cell.
  Normalisation: none beyond eq 2.51, as in the seed. Since int_e N_i dxi = 1 on the parent
  cell, A_i^e is the nodal average int_e N_i A dxi / int_e N_i dxi; boxes that tile a cell
  (Particles.fill) give A_i^e = A, hence A_g = A and K^e = the Q1 finite-element stiffness,
  for a uniform material, while a cell only partly covered by material gets the covered
  fraction of it (no stiffness from empty space, which a normalised average would add).
- Stress increments (eq 2.58): dF_p = I + sum_i du_i (x) grad N^CMPM_i(x_p) over the extended
  stencil (shapes.cmpm), trimmed at the mesh boundary and at cells without particles;
  positions, velocities and accelerations are still mapped with GIMP.

The tangent is not the derivative of the residual (GIMP test functions, CMPM strains), so
Newton converges linearly rather than quadratically (V2 column: 3-4 iterations per load
step at rtol 1e-8). A node reached only by a sliver of a GIMP box (material moving into an
empty cell) has almost no mass and a stiffness the tangent misrepresents, and the iteration
stalls there (V1 bar, Newmark at dt = 5 h/c: no convergence in 100 iterations with the
default mass_tolerance 1e-12); Simulation(mass_tolerance=1e-2) leaves such nodes inactive
(V1 bar: at most 11 iterations per step). Particles crossing cells at large strain make it
worse: the AMPLE column (problems.column, uGIMP, 16 cells, 40 load steps,
mass_tolerance 1e-2) stalls at load step 8 with |R|/|f| ~ 1e-2 after 60 iterations, where
fm.QuasiStatic needs at most 4."""
import time

import numpy as np
from numba import njit

from ..kernels import transfer as kt
from ..shapes.cmpm import CompositeBasis
from ..shapes.gimp import half_widths
from .implicit import Newmark, QuasiStatic

__all__ = ["DoubleMappingQuasiStatic", "DoubleMappingNewmark"]


@njit(cache=True)
def dm_nodal(x, lbox, corr, A, origin, spacing, lo, hi, ncell, clo, cnl, ctable, nmax,
             Dn_out, touched_out):
    """A_i^e += S*_ip^e W_p corr_p A_p (eq 2.57 inner sums) for every particle p and cell e its
    box [x_p - l_p, x_p + l_p] (clipped to the grid [lo, hi]) overlaps; Dn_out (n_cells, 4, 2,
    2, 2, 2) by local cell and cell node a = a_x + 2 a_y. clo/cnl/ctable: local cell lattice
    (first index, count per axis, flat -> local cell or -1); nmax: most cells per axis a box
    overlaps. Returns -1, or a particle overlapping a cell that is not local."""
    Ik = np.zeros((2, nmax, 2))
    jf = np.empty(2, dtype=np.int64)
    nk = np.empty(2, dtype=np.int64)
    for p in range(x.shape[0]):
        for k in range(2):
            L = spacing[k]
            a = max(x[p, k] - lbox[p, k], lo[k])
            b = min(x[p, k] + lbox[p, k], hi[k])
            j1 = min(int(np.floor((a - origin[k]) / L)), ncell[k] - 1)
            j2 = min(int(np.ceil((b - origin[k]) / L)) - 1, ncell[k] - 1)
            jf[k] = j1
            nk[k] = j2 - j1 + 1
            for q in range(nk[k]):
                x0 = origin[k] + (j1 + q) * L
                s = max(a, x0)
                t = min(b, x0 + L)
                if t <= s:
                    Ik[k, q, 0] = 0.0
                    Ik[k, q, 1] = 0.0
                    continue
                # (2 / L) int_s^t of the cell's two linear functions
                Ik[k, q, 0] = ((x0 + L - s) ** 2 - (x0 + L - t) ** 2) / (L * L)
                Ik[k, q, 1] = ((t - x0) ** 2 - (s - x0) ** 2) / (L * L)
        for q0 in range(nk[0]):
            for q1 in range(nk[1]):
                if Ik[0, q0, 0] + Ik[0, q0, 1] == 0.0 or Ik[1, q1, 0] + Ik[1, q1, 1] == 0.0:
                    continue
                cx = jf[0] + q0 - clo[0]
                cy = jf[1] + q1 - clo[1]
                if cx < 0 or cx >= cnl[0] or cy < 0 or cy >= cnl[1]:
                    return p
                e = ctable[cx + cy * cnl[0]]
                if e < 0:
                    return p
                touched_out[e] = True
                for ax in range(2):
                    for ay in range(2):
                        w = Ik[0, q0, ax] * Ik[1, q1, ay] * corr[p]
                        for r in range(2):
                            for J in range(2):
                                for c in range(2):
                                    for L2 in range(2):
                                        Dn_out[e, ax + 2 * ay, r, J, c, L2] += w * A[p, r, J, c, L2]
    return -1


@njit(cache=True)
def dm_assemble(Dn, cells, elem_nodes, elem_plan, Ng, dNg, detJW, nodeptr, constrained, data):
    """data += K^e = sum_g B^T(x_g) A_g B(x_g) |J| W_g, A_g = sum_a N_a(x_g) A_a^e (eqs 2.52-2.53)
    for the listed cells; Ng (ng, 4) and dNg (ng, 4, 2) are the cell functions and physical
    gradients at its Gauss points; constrained rows and columns are skipped."""
    Ag = np.empty((2, 2, 2, 2))
    block = np.empty((2, 2))
    for e in cells:
        for g in range(Ng.shape[0]):
            for r in range(2):
                for J in range(2):
                    for c in range(2):
                        for L in range(2):
                            s = 0.0
                            for a in range(4):
                                s += Ng[g, a] * Dn[e, a, r, J, c, L]
                            Ag[r, J, c, L] = s
            for a in range(4):
                i = elem_nodes[e, a]
                deg = nodeptr[i + 1] - nodeptr[i]
                for b in range(4):
                    for r in range(2):
                        for c in range(2):
                            s = 0.0
                            for J in range(2):
                                for L in range(2):
                                    s += dNg[g, a, J] * Ag[r, J, c, L] * dNg[g, b, L]
                            block[r, c] = detJW * s
                    kt.add_block(data, elem_plan[e, a, b], deg, i, elem_nodes[e, b], 2,
                                 constrained, block)


class _DoubleMapping:
    double_mapping = True               # Simulation(fbar=True) refuses these integrators
    """DM-GC hooks for an implicit integrator (module docstring): CMPM strain increments and
    the double-mapped Gauss-point stiffness."""

    def setup(self, sim):
        """Check the grid and shape, build the Gauss-point and CMPM data (integrator protocol)."""
        name = type(self).__name__
        if sim.gdim != 2 or getattr(sim, "shape", "mpm") not in ("ugimp", "cpgimp"):
            raise ValueError(f"{name}: needs a 2D structured quadrilateral grid (dolfinx "
                             f"create_rectangle with CellType.quadrilateral) and shape='ugimp' or "
                             f"'cpgimp', got gdim={sim.gdim}, shape={getattr(sim, 'shape', 'mpm')!r}")
        if sim.axisymmetric:
            raise NotImplementedError(f"{name}: axisymmetric grids are not supported")
        super().setup(sim)
        lat = sim._wide.lat
        self.basis = b = CompositeBasis(sim.grid, lat)
        ij = b.cell_lat[:, None, :] + np.array([[0, 0], [1, 0], [0, 1], [1, 1]])[None] - lat["ilo"]
        self._elem_nodes = np.ascontiguousarray(lat["table"][ij[..., 0] + ij[..., 1] * lat["nlat"][0]],
                                                dtype=np.int64)
        self._elem_plan = np.empty((len(ij), 4, 4), dtype=np.int64)
        kt.stiffness_plan(self._elem_nodes, self.system.nodeptr, self.system.adj, 2, self._elem_plan,
                          self._elem_nodes[:0])
        L = lat["spacing"]
        gp = np.array([-1.0, 1.0]) / np.sqrt(3.0)
        xi = np.array([[gx, gy] for gy in gp for gx in gp])             # (4 Gauss points, 2)
        sgn = np.array([[-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0], [1.0, 1.0]])  # cell node a
        f = 1.0 + sgn[None, :, :] * xi[:, None, :]                        # (g, a, k)
        self._Ng = np.ascontiguousarray(0.25 * f[..., 0] * f[..., 1])
        self._dNg = np.ascontiguousarray(np.stack([0.25 * sgn[None, :, 0] * f[..., 1] * 2.0 / L[0],
                                                   0.25 * sgn[None, :, 1] * f[..., 0] * 2.0 / L[1]], axis=-1))
        self._detJW = float(L[0] * L[1] / 4.0)
        self._Dn = np.zeros((len(ij), 4, 2, 2, 2, 2))
        self._touched = np.zeros(len(ij), dtype=np.bool_)
        self._omp = None

    def solve_step(self, sim, *args, **kw):
        """Newton's solve of the step (implicit.py) after the step's DM-GC data is prepared."""
        self.prepare(sim)
        return super().solve_step(sim, *args, **kw)

    def prepare(self, sim):
        """Per step, before Newton: the CMPM stencils at the start-of-step positions (trimmed
        at cells without particles), the GIMP box half-widths and the
        weight correction omp/nmp (omp counted on the first step)."""
        t0 = time.perf_counter()
        p, d = sim.particles, sim.gdim
        nmp = np.bincount(p.cell, minlength=sim.grid.n_cells)
        if self._omp is None:
            self._omp = nmp
        omp = self._omp[p.cell]
        self._corr = np.where(omp > 0, omp / np.maximum(nmp[p.cell], 1), 1.0)
        lat = sim._wide.lat
        self._lbox = half_widths(p.gimp_l0, p.F, p.x, lat["spacing"], lat["lo"], lat["hi"],
                                 sim.shape == "cpgimp")
        rmax = float((self._lbox / lat["spacing"]).max()) if len(p) else 0.5
        self._nmax = int(np.ceil(2.0 * rmax)) + 1
        self._cmpm = self.basis.evaluate(p.x, p.cell, self.basis.material(nmp))
        sim.timers["shape"] += time.perf_counter() - t0

    def strain_increment(self, sim, du):
        """dF_p = I + sum_i du_i (x) grad N^CMPM_i(x_p) over the extended stencil (eq 2.58)."""
        nodes, _, dN = self._cmpm
        kt.incremental_F(sim.grid.D, nodes, dN, du, 1.0, sim._dF)

    def assemble_tangent(self, sim, A4, plan, diag_add, constrained, extra=None):
        """K = sum_e sum_g B^T A_g B |J| W_g (eqs 2.52-2.53, 2.57) + diag(diag_add) (+ extra)."""
        lat, b = sim._wide.lat, self.basis
        sys = self.system

        def double_mapped(data):
            self._Dn[:] = 0.0
            self._touched[:] = False
            bad = dm_nodal(sim.particles.x, self._lbox, self._corr, A4, lat["origin"],
                           lat["spacing"], lat["lo"], lat["hi"], b.ncell, b.clo, b.cnl,
                           b.ctable, self._nmax, self._Dn, self._touched)
            if bad >= 0:
                raise RuntimeError(f"{type(self).__name__}: the GIMP box of the particle at "
                                   f"{np.round(sim.particles.x[bad], 6).tolist()} overlaps a cell "
                                   f"that is not on this rank")
            dm_assemble(self._Dn, np.flatnonzero(self._touched), self._elem_nodes, self._elem_plan,
                        self._Ng, self._dNg, self._detJW, sys.nodeptr, constrained, data)
            if extra is not None:
                extra(data)

        sys.assemble(sim.nodes[:0], sim.dN[:0], sim.particles.V[:0], A4[:0], plan[:0], diag_add,
                     constrained, double_mapped)


class DoubleMappingQuasiStatic(_DoubleMapping, QuasiStatic):
    """fm.QuasiStatic with DM-GC (module docstring): GIMP forces, double-mapped stiffness,
    CMPM stress increments. Simulation(shape="ugimp" or "cpgimp") on a 2D structured
    quadrilateral grid (in parallel, created with partitioner=grid.vertex_ghost_partitioner())."""


class DoubleMappingNewmark(_DoubleMapping, Newmark):
    """fm.Newmark with DM-GC (module docstring); same requirements as DoubleMappingQuasiStatic."""
    supports_prescribed_motion = False  # not checked with the double mapping
