"""Collapse of a dry granular column on a rough base (issue 21; Lube et al. 2005, J. Fluid
Mech. 530, 'Collapses of two-dimensional granular columns').

Half model: a column L0 wide and H0 = a L0 tall (aspect ratio a) against a smooth back wall
(roller on x = 0), Mohr-Coulomb c = 0, phi = 30 deg, psi = 0, rho = 1500 kg/m^3, E = 10 MPa,
nu = 0.3, K0 = nu / (1 - nu) start, rough base (sim.add_friction, mu = tan 30 deg), gravity
g = 9.81 m/s^2, h = min(L0, H0) / cells, 2 x 2 particles per cell, the library's defaults
(fm.Explicit(), dt='auto').

Lube et al.'s law for the run-out (L_inf - L0) / L0 and the final height H_inf / L0
(their fig. 7 and eq. 3.1-3.2; plane collapses):
    (L_inf - L0) / L0 = 1.2 a          (a < 2.3),   1.9 a^(2/3)   (a > 2.3)
    H_inf / L0        = a              (a < 1.15),  a^(2/5)       (a > 1.15)."""
import numpy as np

from ..collective import gmax_of

PHI = 30.0
G = 9.81


def lube_runout(a):
    """(L_inf - L0) / L0 of Lube et al. (2005) for aspect ratio a."""
    return 1.2 * a if a < 2.3 else 1.9 * a ** (2.0 / 3.0)


def lube_height(a):
    """H_inf / L0 of Lube et al. (2005) for aspect ratio a."""
    return a if a < 1.15 else a ** 0.4


def granular_column(a, L0=1.0, cells=16, per_cell=2, integrator=None, comm=None,
                    separation=None, **sim_options):
    """The scene: (sim, L0, H0). The mesh spans 0 <= x <= L0 (1 + 2 lube_runout(a)) + 4 h and
    0 <= y <= H0 + 2 h. integrator: default fm.Explicit(); separation: the soil's
    fm.MohrCoulomb(separation=...) (None: the material's default); sim_options go to
    fm.Simulation (default: the library's)."""
    from dolfinx import mesh
    from mpi4py import MPI
    import fenicsmpm as fm
    from fenicsmpm.materials.initial_stress import k0_stress
    comm = MPI.COMM_WORLD if comm is None else comm
    H0 = a * L0
    h = min(L0, H0) / cells
    nx = int(np.ceil(L0 * (1.0 + 2.0 * lube_runout(a)) / h)) + 4
    ny = int(np.ceil(H0 / h)) + 2
    msh = mesh.create_rectangle(comm, [[0.0, 0.0], [nx * h, ny * h]], [nx, ny],
                                mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    soil = fm.MohrCoulomb(E=10e6, nu=0.3, density=1500.0, phi=PHI, c=0.0, psi=0.0,
                          **({} if separation is None else dict(separation=separation)))
    pts = fm.Particles.fill(grid, soil, per_cell=per_cell,
                            region=lambda x: (x[:, 0] < L0) & (x[:, 1] < H0))
    k0_stress(pts, gravity=G, surface=lambda x: np.full(len(x), H0))
    opts = dict(dt="auto")
    opts.update(sim_options)
    sim = fm.Simulation(grid, pts, integrator or fm.Explicit(), gravity=(0.0, -G), **opts)
    sim.fix(lambda x: np.abs(x[:, 0]) < 1e-9 * h, [0])
    sim.add_friction(lambda x: np.abs(x[:, 1]) < 1e-9 * h, mu=np.tan(np.radians(PHI)),
                     normal=(0.0, -1.0))
    return sim, L0, H0


def run_to_rest(sim, T, t_max, chunk, front, scale):
    """Run sim in chunks of `chunk` T until the front (the largest particle x) has stopped:
    after the peak of the mean speed, a chunk in which the front advanced by less than
    0.5 % of `scale` and the mean speed is below 5 % of its peak; at most t_max T.  `front`:
    the initial front.  Returns (history [(t / T, mean speed)], the error message of a
    stopped run or None, t_rest / T or nan).  Collective."""
    p, comm = sim.particles, sim.comm
    hist, error, t_rest = [(0.0, 0.0)], None, float("nan")
    try:
        while sim.t < t_max * T - 1e-9:
            sim.run(t_end=min(sim.t + chunk * T, t_max * T), progress=False)
            hist.append((sim.t / T, p.mean_speed()))
            new = gmax_of(comm, p.x[:, 0])
            speeds = [s for _, s in hist]
            if (np.argmax(speeds) < len(speeds) - 1 and new - front < 5e-3 * scale
                    and speeds[-1] < 0.05 * max(speeds)):
                t_rest = sim.t / T
                break
            front = new
    except (RuntimeError, FloatingPointError) as err:
        error = str(err)
    return hist, error, t_rest


def collapse(a, cells=16, t_max=8.0, chunk=0.25, comm=None, **scene):
    """Run granular_column(a, cells, **scene) to rest (run_to_rest, T = sqrt(H0 / g), front
    scale L0).
    Returns a dict (the same on every rank): runout = (L_inf - L0) / L0 from the farthest
    particle centre, height = H_inf / L0 (the highest particle centre), their errors against
    lube_runout / lube_height, t_rest / T (nan if not at rest by t_max T), the mean-speed
    history (t / T, sum |v_p| m_p / sum m_p), steps, particles, finished (no error) and the
    error message if the run stopped."""
    from mpi4py import MPI
    comm = MPI.COMM_WORLD if comm is None else comm
    sim, L0, H0 = granular_column(a, cells=cells, comm=comm, **scene)
    p = sim.particles
    T = np.sqrt(H0 / G)

    hist, error, t_rest = run_to_rest(sim, T, t_max, chunk, L0, L0)
    runout = (gmax_of(comm, p.x[:, 0]) - L0) / L0
    height = gmax_of(comm, p.x[:, 1]) / L0
    t, s = np.array(hist).T
    return dict(a=a, cells=cells, shape=sim.shape, dt=sim.dt, runout=runout, height=height,
                runout_error=runout / lube_runout(a) - 1.0,
                height_error=height / lube_height(a) - 1.0, t_rest=t_rest, t_end=sim.t / T,
                steps=sim.step_count, particles=p.n_global(), finished=error is None,
                error=error, mean_speed=dict(t=t.tolist(), v=s.tolist()))
