"""Strain localisation scenes (issue 19): a softening shear layer and the W5 strip footing
pushed to failure, with and without the nonlocal regularisation of the softening variable
(fenicsmpm.materials.regularisation).  Soil of W5 (seed 000 ch. 5): von Mises clay, E = 2 MPa,
nu = 0.41, rho = 1000 kg/m^3, c_u = 10 kPa softening linearly (H = -140 kPa) to 3 kPa.

Band width (both scenes): the equivalent width of the plastic strain field,
    w = sum_p V_p eps_p / (L_band eps_p,max),
the area under the eps_p profile divided by its peak and the band's length L_band (the layer
width for the shear layer): one cell for a band in one row of cells, ~ the width of a
smooth profile otherwise.
"""
import math
import time

import numpy as np
from dolfinx import mesh as dmesh

from ..collective import gmax, gsum
from ..grid import Grid
from ..integrators import QuasiStatic
from ..materials import VonMises
from ..particles import Particles
from ..simulation import Simulation

__all__ = ["W5_SOIL", "W5_HALF_WIDTH", "soil", "shear_layer", "shear_layer_simulation",
           "strip_footing", "prandtl_band_length", "collapse_pressure", "centred_cell_size",
           "under_cells", "pushed_columns", "effective_half_width"]

W5_SOIL = dict(E=2.0e6, nu=0.41, density=1000.0, c_u=10.0e3, c_res=3.0e3, H=-140.0e3)
W5_HALF_WIDTH = 0.25          # the W5 footing's half-width B/2 [m]


def soil(length=None, m=2.0, softening=True):
    """The W5 von Mises clay, regularised with internal length `length` (None: local);
    softening=False keeps the peak strength c_u (perfectly plastic)."""
    kw = dict(W5_SOIL) if softening else dict(W5_SOIL, c_res=W5_SOIL["c_u"], H=0.0)
    return VonMises(**kw, nonlocal_length=length if softening else None, nonlocal_m=m)


def _run(sim, steps, record):
    """Advance up to `steps` steps, calling record() after each; returns (completed, message)."""
    for _ in range(steps):
        try:
            sim.step()
        except (RuntimeError, FloatingPointError) as err:     # every rank raises the same
            return False, str(err).splitlines()[0]
        record()
    return True, None


def shear_layer_simulation(h, length=None, comm=None, height=0.2, width=0.02, u_end=0.006,
                           steps=60, m=2.0, weak=0.005, material=None):
    """The Simulation of `shear_layer` (same arguments; `material` replaces the W5 soil)."""
    from mpi4py import MPI
    comm = MPI.COMM_WORLD if comm is None else comm
    nx, ny = max(1, int(round(width / h))), int(round(height / h))
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [width, height]], [nx, ny],
                                 dmesh.CellType.quadrilateral)
    grid = Grid(msh)
    pts = Particles.fill(grid, soil(length, m) if material is None else material, per_cell=2)
    pts.state[np.abs(pts.x[:, 1] - 0.5 * height) < 0.01, 0] = weak
    qs = QuasiStatic(displacement=lambda x, t: np.column_stack(
        [u_end * t * x[:, 1] / height, np.zeros(len(x))]))
    sim = Simulation(grid, pts, qs, dt=1.0 / steps, on_leave="periodic")
    sim.set_periodic(axis=0)
    tol = 1e-6 * h
    sim.fix(lambda x: np.abs(x[:, 1]) < tol)
    sim.fix(lambda x: np.abs(x[:, 1] - height) < tol, [0])
    sim.fix(lambda x: np.ones(len(x), dtype=bool), [1])
    return sim


def shear_layer(h, length=None, comm=None, height=0.2, width=0.02, u_end=0.006, steps=60,
                m=2.0, weak=0.005, material=None):
    """Simple shear of a periodic layer (height x width, quadrilaterals of size h, 2 x 2
    particles per cell): bottom fixed, the top moved by u(t) = u_end t in x over t in [0, 1]
    (`steps` quasi-static steps, displacement control), u_y = 0 everywhere, so the solution
    is 1D, tau(y) = tau.  Imperfection: the particles within 0.01 m of mid-height start with
    eps_p = `weak`.  Returns u (top displacement), tau (mean sigma_xy), the largest final
    eps_p, the band width w (module docstring, L = width), Newton iterations,
    completed/stop message, time split (step wall, nonlocal), ids, state, stress and initial
    positions x0 of the local particles."""
    sim = shear_layer_simulation(h, length, comm, height, width, u_end, steps, m, weak, material)
    comm, qs = sim.comm, sim.integrator
    p = sim.particles
    vol0 = gsum(comm, float(p.V.sum()))
    u, tau = [0.0], [0.0]

    def record():
        u.append(u_end * sim.t)
        tau.append(gsum(comm, float(np.sum(p.V * p.stress[:, 0, 1]))) / vol0)

    t0 = time.perf_counter()
    done, msg = _run(sim, steps, record)
    wall = gmax(comm, time.perf_counter() - t0)
    eps = p.state[:, 0]
    emax = gmax(comm, float(eps.max()) if len(p) else 0.0)
    band = gsum(comm, float(np.sum(p.V * eps))) / (width * emax) if emax > 0 else 0.0
    return dict(h=h, length=length, u=np.array(u), tau=np.array(tau), completed=done,
                stopped=msg, band_width=band, eps_max=emax,
                newton=list(qs.iterations), wall_s=wall,
                nonlocal_s=gmax(comm, sim.timers.get("nonlocal", 0.0)),
                n_particles=gsum(comm, len(p)), ids=p.id.copy(), state=p.state.copy(),
                stress=p.stress.copy(), x0=p.x - p.u)



def prandtl_band_length(half_width):
    """Length of the outer slip line of Prandtl's mechanism under a smooth strip of half-width
    b (half model): active wedge side b sqrt(2), a circular fan arc of radius b sqrt(2) over
    pi/2, passive wedge side b sqrt(2): L = b sqrt(2) (2 + pi/2)."""
    return half_width * math.sqrt(2.0) * (2.0 + 0.5 * math.pi)


def collapse_pressure(settlement, pressure, half_width=W5_HALF_WIDTH, window=(0.12, 0.16)):
    """The collapse pressure of the W5 footing at its peak strength: the mean pressure over
    the settlements window[0] B to window[1] B (B = 2 half_width), the plateau of its
    load-settlement curve.  The small-strain curve of an elastic-perfectly plastic soil scales
    with c_u / E: the W5 clay made ten times stiffer (E = 2000 c_u) reaches its limit at
    0.014-0.016 B (2.5 cells under B/2, footing="particles"), so the W5 clay (E = 200 c_u)
    reaches it near 0.15 B; at 0.1 B it is still below, and further on the embedding
    footing lifts the curve (bench bearing-capacity's w5 rows, docs/guide/choosing.md).  The
    mean is over the curve interpolated linearly.
    Raises a ValueError if the curve stops short of window[1] B."""
    if not 0.0 <= window[0] < window[1]:
        raise ValueError(f"collapse_pressure: 'window' must be (lo, hi) with 0 <= lo < hi, "
                         f"got {window!r}")
    lo, hi = (2.0 * half_width * w for w in window)
    settlement = np.asarray(settlement, dtype=float)
    if not len(settlement) or settlement[-1] < hi * (1.0 - 1e-9):
        raise ValueError(f"collapse_pressure: 'settlement' must reach {window[1]:g} B = {hi:g} m, "
                         f"got up to {settlement[-1] if len(settlement) else None!r} m")
    s = np.linspace(lo, hi, 201)
    return float(np.mean(np.interp(s, settlement, np.asarray(pressure, dtype=float))))


def under_cells(x, h, half_width):
    """The particles x (n, gdim) of the grid columns [i h, (i + 1) h] whose centre lies under a
    footing x < half_width. A rigid footing pushed through these particles (penalty on the
    particle velocity) drags the nodes of their cells, so the soil's velocity falls to zero
    across the next cell: the footing acts to the centre of the first column not pushed. With
    its edge at a cell centre (half_width / h = n + 1/2) it is exactly half_width wide; with
    its edge on a grid line (half_width / h = n) half a cell wider (measured: q too high by
    about h / (2 half_width) in bench bearing-capacity's implicit rows, 1.095 (2 + pi) c_u at
    5 cells, 1.052 at 10; with the edge at a cell centre 1.004 at 5.5 cells)."""
    return np.floor(x[:, 0] / h + 1e-9) < pushed_columns(h, half_width)


def centred_cell_size(half_width, n):
    """The cell size h = half_width / (n + 1/2): n + 1/2 cells under the half-width, the
    footing's edge at a cell centre, where the particle footing (under_cells) is exactly
    half_width wide."""
    if not n >= 0:
        raise ValueError(f"centred_cell_size: 'n' must be >= 0, got {n!r}")
    return half_width / (n + 0.5)


def pushed_columns(h, half_width):
    """The number k of grid columns [i h, (i + 1) h] whose centre lies under a footing
    x < half_width: (i + 1/2) h < half_width for i < k."""
    return math.ceil(half_width / h - 0.5 - 1e-6)


def effective_half_width(h, half_width, footing="particles"):
    """The half-width the discrete footing acts on.  footing="particles": to the centre of
    the first cell column the footing does not move, (k + 1/2) h with k the columns pushed
    (under_cells): half_width when the edge lies at a cell centre, half_width + h / 2 when it
    lies on a grid line.  Measured on Prandtl's footing (bench bearing-capacity's implicit
    rows, 30 mm): force / (2 + pi) c_u per unit effective width 1.009 / 0.995 / 1.002 with
    the edge on a grid line (2 / 5 / 10 cells) and 1.002 / 0.997 / 1.000 with the edge at a
    cell centre with every particle under the footing pushed (2.5 / 3.5 / 5.5 cells).
    footing="nodes": to the last surface node moved, k h with k = floor(half_width / h) (the
    velocity falls to zero across the cell beyond it, as in a finite element footing).
    Measured the same way (30 mm in 60 steps): 1.129 / 1.130 at 2 / 2.5 cells and 1.017 /
    1.012 at 5 / 5.5 cells per unit of k h, converging with h; per unit of (k + 1/2) h they
    read 0.90-0.92."""
    if footing == "particles":
        return (pushed_columns(h, half_width) + 0.5) * h
    return math.floor(half_width / h + 1e-6) * h


def strip_footing(h, length=None, comm=None, settlement=0.1, steps=50, width=6.0, depth=4.0,
                  half_width=W5_HALF_WIDTH, m=2.0, cuts=5, softening=True, fbar="auto", shape="auto",
                  material=None, line_search="auto", footing="nodes", ghost=0.0, rtol=1e-8,
                  rough=False):
    """The W5 strip footing (seed 000 ch. 5: half model, B/2 = 0.25 m next to the symmetry
    axis x = 0, layer 6 m wide and 4 m deep, 2 x 2 particles per cell, quadrilaterals of
    size h, with empty cells above the surface for the heave) on weightless W5 clay, pushed quasi-statically to `settlement` in `steps` steps:
    a smooth rigid footing (the top nodes with x <= B/2 moved down, u_x free: displacement
    control), bottom fixed, rollers on both sides.  Weightless, so Prandtl's (2 + pi) c_u =
    51.4 kPa is the limit pressure of the soil without softening.  Returns the
    pressure-settlement curve (p = vertical reaction / (B/2); the discrete footing acts on
    `half_width_effective`, effective_half_width), the largest eps_p, the band
    width w = sum_p V_p eps_p / (eps_p,max L), L = prandtl_band_length(B/2), Newton
    iterations, completed/stop message and the time split (step wall, nonlocal).  A step
    whose Newton fails is retried as halves, up to `cuts` times (Simulation.max_dt_cuts; 5: on
    2 ranks the W5 footing of tests/test_implicit_footing.py with Newton's defaults stopped at 64 mm on
    one of 12 SCOTCH partitions with 3 and completed with 5, but stopped there with 5 on
    another partition of dolfinx's default partitioner; with ghost=0.01, line_search=6,
    rtol=1e-6 (bench.localisation.FOOTING) it completed on every partition tried).
    softening=False: the perfectly plastic soil (peak strength); fbar: Simulation(fbar=...)
    (F-bar with its consistent tangent, kernels.fbar; "auto", the library default, turns it
    on for this von Mises soil); shape: Simulation(shape=...); material: a material instead of
    the W5 soil (then length, m and softening are not used), e.g. the Prandtl soil of
    problems.footing; line_search: fm.QuasiStatic(line_search=...); ghost:
    fm.QuasiStatic(ghost=...) (the ghost penalty of poorly filled cells, integrators.ghost);
    rtol: fm.QuasiStatic(rtol=...).
    footing="nodes" (default): the footing is the surface nodes with x <= B/2, valid while
    the settlement is well below h (the soil then leaves those nodes); "particles": the top
    particle row under B/2 is pushed down by penalty (Simulation.move_particles), so the
    footing moves with the soil, p = particle reaction / (B/2); those are the particles of the
    columns whose centre is under the footing (under_cells: the footing is exactly B/2 wide
    when its edge is at a cell centre, B/2 / h = n + 1/2, half a cell wider when the edge is on
    a grid line); rough=True holds those particles horizontally as well (a rough footing;
    footing="particles" only)."""
    from mpi4py import MPI
    if footing not in ("nodes", "particles"):
        raise ValueError(f"strip_footing: 'footing' must be 'nodes' or 'particles', got {footing!r}")
    if rough and footing != "particles":
        raise ValueError("strip_footing: 'rough' needs footing='particles'")
    comm = MPI.COMM_WORLD if comm is None else comm
    top = depth + max(2.0 * h, 0.25)               # empty cells above the soil for the heave
    nx, ny = int(round(width / h)), int(round(top / h))
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [width, ny * h]], [nx, ny],
                                 dmesh.CellType.quadrilateral)
    grid = Grid(msh)
    tol = 1e-6 * h
    pts = Particles.fill(grid, soil(length, m, softening) if material is None else material,
                         per_cell=2,
                         region=lambda x: x[:, 1] < depth)
    under = lambda x: (np.abs(x[:, 1] - depth) < tol) & (x[:, 0] <= half_width + tol)
    push = lambda x, t: np.column_stack([np.zeros(len(x)), np.full(len(x), -settlement * t)])
    qs = QuasiStatic(displacement=(lambda x, t: np.where(under(x)[:, None], push(x, t), 0.0))
                     if footing == "nodes" else None, line_search=line_search, ghost=ghost,
                     rtol=rtol)
    sim = Simulation(grid, pts, qs, dt=1.0 / steps, max_dt_cuts=cuts, fbar=fbar, shape=shape)
    sim.fix(lambda x: np.abs(x[:, 1]) < tol)
    sim.fix(lambda x: (np.abs(x[:, 0]) < tol) | (np.abs(x[:, 0] - width) < tol), [0])
    own = np.zeros(grid.n_nodes, dtype=bool)
    if footing == "nodes":
        sim.fix(under, [1])
        own[: grid.n_owned_nodes] = under(grid.node_x[: grid.n_owned_nodes])
    else:       # the top particle row under B/2, pushed down by penalty (particle_motion)
        sim.move_particles(lambda x: (x[:, 1] > depth - 0.5 * h) & under_cells(x, h, half_width),
                           push, components=[0, 1] if rough else [1])
    p = sim.particles
    s, pr = [0.0], [0.0]

    def record():
        s.append(settlement * sim.t)
        if footing == "nodes":
            pr.append(-gsum(comm, float(sim.nodal["reaction"][own, 1].sum())) / half_width)
        else:
            pr.append(-float(sim.particle_reaction(0)[1]) / half_width)

    t0 = time.perf_counter()
    done, msg = _run(sim, steps, record)
    wall = gmax(comm, time.perf_counter() - t0)
    eps = p.state[:, 0]
    emax = gmax(comm, float(eps.max()) if len(p) else 0.0)
    band = (gsum(comm, float(np.sum(p.V * eps))) / (emax * prandtl_band_length(half_width))
            if emax > 0 else 0.0)
    return dict(h=h, length=length, settlement=np.array(s), pressure=np.array(pr),
                half_width=half_width,
                half_width_effective=effective_half_width(h, half_width, footing),
                completed=done, stopped=msg, band_width=band, eps_max=emax,
                newton=list(qs.iterations), wall_s=wall,
                nonlocal_s=gmax(comm, sim.timers.get("nonlocal", 0.0)),
                n_particles=gsum(comm, len(p)))
