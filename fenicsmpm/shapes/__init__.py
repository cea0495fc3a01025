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

    The most accurate family the mesh supports, by measurement (issue 15; the figures behind
    every row, with their commands, are in docs/guide/choosing.md):
    - cpGIMP on structured axis-aligned quadrilateral/hexahedral lattices: elastic materials
      (explicit and implicit), and explicit VonMises (with F-bar, fbar="auto") and
      MohrCoulomb (Prandtl's footing, the L4 slope, the granular collapse);
    - CPDI2 on other 2D meshes (triangles: the sub-triangles of Particles.fill as domains),
      CPDI1 on other 3D meshes (tetrahedral or parallelepiped domains), elastic materials;
    - the standard family where a wide one is not available or measured worse:
      force_integration="mixed"; implicit integrators with a plastic material (the W5
      footing's curves 7.2 % instead of 9.5 % apart with cpGIMP at 3-6x the time, Newton
      stalls under the rough implicit footing); plastic materials other than VonMises and
      MohrCoulomb (Hypoplastic: its pile demo converges in h with neither family); plastic
      materials off lattices; implicit runs off lattices or with fewer than 2 particles per
      cell and direction; axisymmetric grids that are not lattices.
    Under MPI a mesh without the vertex ghost layer gets it (Grid.ensure_vertex_ring, called
    by the Simulation). Collective."""
    from .gimp import lattice
    grid = sim.grid
    if sim.force_integration != "particles":
        return "mpm", f"force_integration={sim.force_integration!r} needs the standard family"
    plastic = sorted({type(m).__name__ for m in sim.particles.materials
                      if getattr(m, "plastic", False)})
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
            "standard 0.555-0.578 and moving away under refinement)"
            if "MohrCoulomb" in plastic else "")
    except ValueError:
        pass
    if implicit:
        return "mpm", ("implicit integrator on a mesh that is not a structured lattice (wide "
                       "families not measured there)")
    if plastic:
        return "mpm", (f"plastic material ({', '.join(plastic)}) on a mesh that is not a "
                       f"structured lattice (wide families not measured there)")
    if grid.axisymmetric:
        return "mpm", "axisymmetric grid that is not a structured lattice"
    if grid.gdim == 2:
        from dolfinx.mesh import CellType
        return "cpdi2", "2D mesh that is not a structured lattice" + (
            "; on triangles the most accurate configuration measured for elastic scenes is "
            "Particles.fill_edges with fm.Explicit(transfer='aflip') (V3 MMS: 4-5x smaller "
            "errors than Particles.fill with FLIP, docs/measured.md)"
            if grid.cell_type == CellType.triangle else "")
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
