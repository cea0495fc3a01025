"""Shape-function families (the "shape" stage): standard (the Lagrange basis of the particle's
cell, Simulation(shape="mpm")), gimp ("ugimp"/"cpgimp"), bspline ("bspline2": boundary-modified
quadratic B-splines on the same structured lattices as GIMP; measured against cpGIMP in
docs/guide/choosing.md, not picked by "auto"), cpdi ("cpdi1"/"cpdi2"), gauss_gimp ("gauss")
and cmpm (the composite basis of the DM-GC integrators)."""

import logging

import numpy as np

SHAPES = ("auto", "mpm", "ugimp", "cpgimp", "cpdi1", "cpdi2", "gauss", "bspline2")
_log = logging.getLogger("fenicsmpm")


def choose_shape(sim):
    """The family shape="auto" picks for `sim`, and why: (family, reason).

    The most accurate family the mesh supports, by measurement (bench techniques, mms,
    column-peers; issue 15): cpGIMP on structured axis-aligned quadrilateral/hexahedral
    grids, CPDI2 on other 2D meshes (unstructured quadrilaterals; triangles, with the
    sub-triangles of Particles.fill as domains: V3 MMS orders 1.78 / 1.39; with the edge
    diamonds of Particles.fill_edges 1.66 / 1.76, bench mms), CPDI1 on other
    3D meshes (tetrahedra: tetrahedral domains, the sub-tetrahedra of Particles.fill that tile
    the cells; hexahedra: parallelepipeds). 3D soft column on tetrahedra (BENCHMARKS L1 soft
    case, `PYTHONPATH=. python tests/test_cpdi3d.py`), max |sigma_zz + rho g d| / (rho g H)
    at 10 / 20 cells over H: one particle per cell, CPDI1 2.8 % / 1.4 % against standard MPM
    73 % / 92 %; the default 2 per cell (8 sub-tetrahedra), CPDI1 3.5 % / 1.8 % (rms 1.5 % /
    0.6 %) against 116 % / 133 % (rms 12.5 % / 15.8 %). The standard
    family where a wide one is not available or measured worse: implicit integrators with a
    plastic material (W5 softening footing at h = 0.125 / 0.0625 / 0.03125 m: curves 7.2 %
    apart with cpGIMP against 9.5 % standard at 3.0-5.8x the time; implicit Prandtl footing,
    rough: Newton stalls at |R|/|f| ~ 1e-6 with cpGIMP; 2026-12-06, docs/guide/choosing.md)
    or on meshes that are not lattices, force_integration="mixed",
    plastic materials other than VonMises and MohrCoulomb (`plastic` set: Hypoplastic; its
    pile demo converges in h with neither family: first-blow penetration -0.006 / 0.662 m at
    h = 0.3 / 0.15 m standard, -0.014 / 0.815 m cpGIMP, demos/pile_driving.py --shape). VonMises and MohrCoulomb get cpGIMP on a lattice.
    Mohr-Coulomb (2026-12-06): the L4 slope (demos/slope_failure.py, 50 x 27 cells) fails
    between strength-reduction factors 0.625 and 0.65 with cpGIMP (0.6-0.625 on 100 x 54)
    against Bishop's 0.598 (problems.slope_stability), while the standard family's slope
    creeps past the failure criterion from 0.555-0.578 on (0.5 on 100 x 54), moving away
    from it; the granular collapse meets Lube et al.'s laws at every aspect ratio with
    cpGIMP only (a = 4 height -9.1 % against -17.4 %, docs/guide/choosing.md); the weightless
    footing against c N_c at 2 / 5 / 10 cells under B/2 is 1.063 / 1.096 / 1.054 (phi 20)
    and 0.829 / 1.021 / 1.015 (phi 30) against 1.031 / 1.039 / 1.004 and 0.963 / 0.948 /
    0.945 standard (bench bearing-capacity); the softening slope (problems.softening_slope)
    runs to rest at H/8-H/64 since a cpGIMP box stops at the grid boundary (shapes.gimp),
    its two finest run-outs 7.1 % apart regularised (standard 7.7 %). VonMises gets cpGIMP on
    a lattice (with F-bar, Simulation fbar="auto"): Prandtl's smooth footing (bench
    bearing-capacity) 1.165 / 1.031 / 1.022 (2+pi) c_u at 2 / 5 / 10 cells under B/2 against
    1.065 / 0.994 / 0.852 standard; elsewhere the standard family. Implicit runs of elastic
    materials on a lattice get cpGIMP: V3 MMS with Newmark (bench mms) converges at order
    1.77 / 1.86 (displacement / stress) against -0.58 / -0.22 standard, the AMPLE column
    quasi-statically (bench self-weight) 4.36e-4 stress error at 64 cells against 8.3e-2; a
    Newmark step of the bench throughput block costs 0.87-1.07 s against 1.21-1.88 s for
    standard + the LU of before, a quasi-static one 12.9-14.5 s against 2.0-2.2 s (LU fill). Under MPI a mesh
    without the vertex ghost layer gets it (Grid.ensure_vertex_ring, called by the
    Simulation). Collective."""
    from .gimp import lattice
    grid = sim.grid
    if sim.force_integration != "particles":
        return "mpm", f"force_integration={sim.force_integration!r} needs the standard family"
    plastic = sorted({type(m).__name__ for m in sim.particles.materials if getattr(m, "plastic", False)})
    implicit = not sim.integrator.explicit
    if implicit and plastic:
        return "mpm", (f"implicit integrator with a plastic material ({', '.join(plastic)}): "
                       f"with cpGIMP Newton stalls under the rough implicit footing, and the "
                       f"W5 footing costs 3-6x for curves 7.2 % instead of 9.5 % apart")
    if set(plastic) - {"VonMises", "MohrCoulomb"}:
        return "mpm", (f"plastic material ({', '.join(plastic)}): the pile demo converges in h "
                       f"with neither family (docs/guide/choosing.md); the standard one is kept")
    try:
        lat = lattice(grid)
        if implicit and _coarse_fill(sim, lat):
            return "mpm", ("implicit integrator with fewer than 2 particles per cell and "
                           "direction (cpGIMP measured implicitly with 2 x 2 per cell)")
        return "cpgimp", "structured axis-aligned grid" + (
            " (von Mises: Prandtl's footing 1.022 (2+pi) c_u with F-bar at 10 cells under B/2, "
            "standard 0.852)" if "VonMises" in plastic else "") + (
            " (Mohr-Coulomb: the L4 slope fails at 0.625-0.65 against Bishop's 0.598, "
            "standard 0.555-0.578 and moving away under refinement)" if "MohrCoulomb" in plastic else "")
    except ValueError:
        pass
    if implicit:
        return "mpm", "implicit integrator on a mesh that is not a structured lattice (wide families not measured there)"
    if plastic:
        return "mpm", (f"plastic material ({', '.join(plastic)}) on a mesh that is not a "
                       f"structured lattice (wide families not measured there)")
    if grid.axisymmetric:
        return "mpm", "axisymmetric grid that is not a structured lattice"
    if grid.gdim == 2:
        return "cpdi2", "2D mesh that is not a structured lattice"
    return "cpdi1", "3D mesh that is not a structured lattice"


def _coarse_fill(sim, lat):
    """True when some particle's initial box (gimp.initial_half_widths: the fill spacing, the
    meridian area on axisymmetric grids) is wider than half a lattice cell: fewer than 2
    particles per cell and direction (collective). With one per cell an implicit cpGIMP box
    spans its cell, any stretch reaches past the 2-ring pattern, and Newton failed on cases of
    tests/stress/test_fuzz.py that the standard family runs."""
    from .gimp import initial_half_widths
    p = sim.particles
    r = float(np.max(initial_half_widths(sim.grid, p, lat) / lat["spacing"])) if len(p) else 0.0
    if sim.comm.size > 1:
        from mpi4py import MPI
        r = sim.comm.allreduce(r, op=MPI.MAX)
    return r > 0.25 * (1.0 + 1e-6)


def resolve_shape(sim, shape):
    """The family to use for the Simulation option `shape` ("auto" -> choose_shape, logged
    once on rank 0 with its reason), and the reason ("" when asked for by name)."""
    family, reason = (shape, "") if shape != "auto" else choose_shape(sim)
    if shape == "auto" and sim.comm.rank == 0:
        _log.info("shape='auto': %s (%s)", family, reason)
    from .cpdi import has_edge_domains
    if (family not in ("cpdi1", "cpdi2") and sim.comm.rank == 0
            and has_edge_domains(sim.grid, sim.particles)):
        import warnings
        warnings.warn(f"Simulation: the particles of Particles.fill_edges carry quadrilateral "
                      f"CPDI2 domains, which shape={family!r}"
                      f"{' (' + reason + ')' if reason else ''} does not use: it sees 1.5 "
                      f"points a cell; use Particles.fill for this scene", RuntimeWarning,
                      stacklevel=3)
    return family, reason


def wide_shape(sim, shape):
    """The evaluator of the shape family `shape` (one of SHAPES) for `sim`, or None for "mpm"
    (standard.mpm_shape, evaluated by Simulation.locate_and_shape itself)."""
    if shape in ("ugimp", "cpgimp"):
        from .gimp import GimpShape
        return GimpShape(sim, contiguous=shape == "cpgimp")
    if shape in ("cpdi1", "cpdi2"):
        from .cpdi import CpdiShape
        return CpdiShape(sim, version=int(shape[-1]))
    if shape == "gauss":
        from .gauss_gimp import GaussGimpShape
        return GaussGimpShape(sim)
    if shape == "bspline2":
        from .bspline import BsplineShape
        return BsplineShape(sim)
    return None
