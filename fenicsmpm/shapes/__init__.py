"""Shape-function families (the "shape" stage): standard (the Lagrange basis of the particle's
cell, Simulation(shape="mpm")), gimp ("ugimp"/"cpgimp"), cpdi ("cpdi1"/"cpdi2"), gauss_gimp
("gauss") and cmpm (the composite basis of the DM-GC integrators)."""

SHAPES = ("mpm", "ugimp", "cpgimp", "cpdi1", "cpdi2", "gauss")


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
    return None
