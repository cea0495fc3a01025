"""A softening Mohr-Coulomb slope that fails and runs out (issue 19: is the run-out
mesh-objective?).

Plane strain, half-open geometry: a slope H = 10 m high at 45 degrees, a crest plateau 5 m
long against a smooth back wall (roller on x = 0), toe at x = X_TOE = 15 m, on a rough base
(sim.add_friction, mu = 0.4); the mesh spans 0 <= x <= 50 m, 0 <= y <= H + 2 h, square cells
h = H / cells, 2 x 2 particles per cell, K0 start (nu / (1 - nu)), g = 9.81 m/s^2, the
library's explicit defaults (fm.Explicit(), dt='auto').
Soil: rho = 2000 kg/m^3, E = 20 MPa, nu = 0.3, psi = 0, strain softening from the peak
phi = 20 deg, c = 5 kPa to the residual phi = 10 deg, c = 1 kPa at rate eta = 10
(MohrCoulomb, seed 003 exponential law).  The peak strength holds the slope only just (it
creeps a few metres), the residual one lets it flow far: what it does in between is set by
the softening, so without a length scale it depends on h.

The run-out is the distance from the toe to the farthest particle centre once the slope is
at rest (granular_collapse.run_to_rest, T = sqrt(H / g))."""
import numpy as np

from ..collective import gmax, gmax_of

H, CREST, X_TOE, LENGTH = 10.0, 5.0, 15.0, 50.0
G = 9.81
SOIL = dict(E=20e6, nu=0.3, density=2000.0, phi=20.0, c=5e3, psi=0.0, phi_res=10.0,
            c_res=1e3, eta=10.0)
MU_BASE = 0.4


def surface(x):
    """Height of the initial ground surface above positions x (n, 2): plateau, 45 degree
    face, nothing beyond the toe."""
    return np.clip(H - (x[:, 0] - CREST), 0.0, H)


def soil(length=None, softening=True, residual=False):
    """The slope's MohrCoulomb: softening (nonlocal_length `length`, None: local), or
    perfectly plastic at the peak (softening=False) or at the residual (residual=True)
    strength."""
    import fenicsmpm as fm
    kw = dict(SOIL)
    if residual:
        kw.update(phi=kw["phi_res"], c=kw["c_res"])
    if residual or not softening:
        kw.update(phi_res=None, c_res=None, eta=0.0)
    return fm.MohrCoulomb(**kw, nonlocal_length=length)


def slope(cells=16, material=None, comm=None, **sim_options):
    """The scene: a Simulation. material: default soil(); sim_options go to fm.Simulation
    (default: the library's explicit defaults)."""
    from dolfinx import mesh
    from mpi4py import MPI
    import fenicsmpm as fm
    from fenicsmpm.materials.initial_stress import k0_stress
    comm = MPI.COMM_WORLD if comm is None else comm
    h = H / cells
    nx, ny = int(round(LENGTH / h)), cells + 2
    msh = mesh.create_rectangle(comm, [[0.0, 0.0], [nx * h, ny * h]], [nx, ny],
                                mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    pts = fm.Particles.fill(grid, material or soil(), per_cell=2,
                            region=lambda x: x[:, 1] < surface(x))
    k0_stress(pts, gravity=G, surface=surface)
    opts = dict(dt="auto")
    opts.update(sim_options)
    sim = fm.Simulation(grid, pts, fm.Explicit(), gravity=(0.0, -G), **opts)
    sim.fix(lambda x: np.abs(x[:, 0]) < 1e-9 * h, [0])
    sim.add_friction(lambda x: np.abs(x[:, 1]) < 1e-9 * h, mu=MU_BASE, normal=(0.0, -1.0))
    return sim


def runout(cells=16, material=None, t_max=15.0, chunk=0.25, comm=None, **sim_options):
    """Run slope(cells, material) to rest.  Returns a dict (the same on every rank): runout
    [m] (farthest particle centre - X_TOE), t_rest / T (nan if not at rest by t_max T),
    steps, dt, particles, wall_s and nonlocal_s (the largest over the ranks), finished and
    the error message of a stopped run."""
    import time
    from mpi4py import MPI
    from .granular_collapse import run_to_rest
    comm = MPI.COMM_WORLD if comm is None else comm
    sim = slope(cells, material, comm, **sim_options)
    p = sim.particles
    t0 = time.perf_counter()
    hist, error, t_rest = run_to_rest(sim, np.sqrt(H / G), t_max, chunk, X_TOE, H)
    wall = gmax(comm, time.perf_counter() - t0)
    front = gmax_of(comm, p.x[:, 0])
    return dict(cells=cells, h=H / cells, runout=front - X_TOE, t_rest=t_rest,
                t_end=sim.t / np.sqrt(H / G), steps=sim.step_count, dt=sim.dt,
                particles=p.n_global(), wall_s=wall,
                nonlocal_s=gmax(comm, sim.timers.get("nonlocal", 0.0)),
                finished=error is None, error=error)
