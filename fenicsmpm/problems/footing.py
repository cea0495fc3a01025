"""Prandtl's smooth rigid strip footing on weightless Tresca soil (issue 21; seed 000 ch. 5,
BENCHMARKS W5's collapse-load check): the limit pressure is (2 + pi) c_u (Prandtl 1920).

Half model (symmetry line x = 0): soil `width` x `depth` (default 5 m x 3 m) of
fm.VonMises(E = 10 MPa, nu, rho = 1800, c_u = 10 kPa) without weight; a rigid footing of
half-width B/2 = 0.5 m and height 2 h (a body of particles, fm.ExplicitContact with
`rigid={1: v(t)}`, frictionless contact mu = 0: a smooth footing) stands on the surface and is
pushed down at `speed_factor` c_s, reached smoothly (3 s^2 - 2 s^3) over the time of a
quarter cell. Rollers on x = 0 and x = width, the base fixed; the mesh has 3 empty cell rows
(or `room` metres of them) above the surface. The footing pressure is q = F_y / (B/2), F the contact force on the footing
(integrator.body_contact_force).  `soil=` replaces the Tresca soil, e.g. a weightless
fm.MohrCoulomb (limit pressure c N_c, Prandtl-Reissner: limit_pressure)."""
import math

import numpy as np

B2 = 0.5          # footing half-width [m]
C_U = 10e3        # undrained strength [Pa]
PRANDTL = 2.0 + np.pi


def tresca_soil(nu=0.49):
    """Prandtl's soil: fm.VonMises(E = 10 MPa, nu, rho = 1800 kg/m^3, c_u = C_U), used
    weightless (module docstring)."""
    from ..materials import VonMises
    return VonMises(E=10e6, nu=nu, density=1800.0, c_u=C_U)


def limit_pressure(soil):
    """The limit pressure of a smooth strip footing on weightless soil: (2 + pi) c_u for
    fm.VonMises (Prandtl 1920), c N_c for fm.MohrCoulomb with N_c = (N_q - 1) cot phi,
    N_q = exp(pi tan phi) tan^2(45 deg + phi/2) (Reissner 1924; the classical solution,
    associated flow psi = phi), (2 + pi) c at phi = 0."""
    if hasattr(soil, "c_u"):
        return PRANDTL * soil.c_u
    if not hasattr(soil, "phi"):
        raise ValueError(f"limit_pressure: 'soil' must be a VonMises or MohrCoulomb material, "
                         f"got {type(soil).__name__}")
    phi = math.radians(soil.phi)
    if phi == 0.0:
        return PRANDTL * soil.c
    n_q = math.exp(math.pi * math.tan(phi)) * math.tan(0.25 * math.pi + 0.5 * phi) ** 2
    return soil.c * (n_q - 1.0) / math.tan(phi)


def strip_footing(h=0.1, nu=0.49, width=5.0, depth=3.0, speed_factor=2e-3, scheme="MUSL",
                  shape="auto", fbar=None, mu=0.0, soil=None, room=None, comm=None,
                  algorithm="multi-velocity", interface="auto", half=True):
    """The scene: (sim, pressure, settlement): pressure() -> q / limit_pressure(soil) of the
    last step (from the global contact force; the same on every rank), settlement(t) the
    footing's prescribed settlement [m]. fbar: the Simulation option (None: the library
    default); mu: the footing-soil friction coefficient (0: smooth; a rough footing, e.g.
    mu = 10, has the same Prandtl limit on weightless Tresca soil); soil: the soil material
    (None: the Tresca soil above with Poisson's ratio nu); room: the height [m] of empty
    cells above the surface, for the heave (None: 3 h); algorithm: fm.ExplicitContact's
    ("penalty": node-to-segment with k_n = rho c_p^2 / h of the soil, the soil surface and
    the footing's outline as polylines, vertices h/2 apart); interface: fm.ExplicitContact's
    ("paired": one constraint per node pair across the footing's base; "coverage": edge nodes
    held in proportion to the footing's coverage of them); half: the half model (the symmetry
    line x = 0 a roller), or with half=False the whole footing, B wide, in the middle of a
    soil body 2 width wide (no symmetry line)."""
    from dolfinx import mesh
    from mpi4py import MPI
    import fenicsmpm as fm
    if room is not None and not room > 0.0:
        raise ValueError(f"strip_footing: 'room' must be > 0 (metres of empty cells), got {room!r}")
    comm = MPI.COMM_WORLD if comm is None else comm
    span = width if half else 2.0 * width
    mid = 0.0 if half else width
    nx = int(round(span / h))
    ny = int(round(depth / h)) + (3 if room is None else int(math.ceil(room / h - 1e-9)))
    msh = mesh.create_rectangle(comm, [[0.0, 0.0], [span, ny * h]], [nx, ny],
                                mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    soil = tresca_soil(nu) if soil is None else soil
    q_limit = limit_pressure(soil)
    pts = fm.Particles.fill(grid, soil, per_cell=2, region=lambda x: x[:, 1] < depth)
    pts = pts + fm.Particles.fill(grid, fm.LinearElastic(E=10e6, nu=0.3, density=1800.0),
                                  per_cell=2, region=lambda x: (np.abs(x[:, 0] - mid) < B2)
                                  & (x[:, 1] > depth)
                                  & (x[:, 1] < depth + 2 * h))
    speed = speed_factor * soil.s_wave_speed
    ramp = 0.25 * h / speed

    def velocity(t):
        s = min(t / ramp, 1.0)
        return (0.0, -speed * (3 * s * s - 2 * s ** 3))

    def settlement(t):
        s = min(t / ramp, 1.0)
        return speed * (ramp * (s ** 3 - 0.5 * s ** 4) + max(t - ramp, 0.0))

    kw = {} if fbar is None else dict(fbar=fbar)
    if algorithm == "penalty":
        if not half:
            raise ValueError("strip_footing: algorithm='penalty' needs the half model (half=True)")
        from ..contact.penalty import line, rectangle
        integ = fm.ExplicitContact(scheme, mu=mu, rigid={1: velocity}, algorithm="penalty",
                                   penalty=dict(k_n=soil.density * soil.p_wave_speed ** 2 / h))
        integ.add_polyline(0, line((width, depth), (0.0, depth), 2 * nx))
        integ.add_polyline(1, rectangle((0.0, depth), (B2, depth + 2 * h), 0.5 * h), closed=True)
    else:
        integ = fm.ExplicitContact(scheme, mu=mu, rigid={1: velocity}, algorithm=algorithm,
                                   interface=interface)
    sim = fm.Simulation(grid, pts, integ, dt="auto", shape=shape, **kw)
    sim.fix(lambda x: np.isclose(x[:, 0], 0.0) | np.isclose(x[:, 0], span), [0])
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0))

    def pressure():
        return np.asarray(integ.body_contact_force)[1][1] / (B2 if half else 2.0 * B2) / q_limit
    return sim, pressure, settlement


def contact_load_shares(h=0.1, t_from=0.5, t_end=0.8, comm=None, **scene):
    """Where the footing's load goes: strip_footing(h, **scene) pushed to t_end; the soil's
    vertical nodal contact force (integrator.contact_force) averaged over the steps after
    t_from, as shares of its global total.  Returns (x, share, q): this rank's owned nodes
    that carry load (coordinates, share) and the mean q / limit over those steps (collective)."""
    from mpi4py import MPI
    comm = MPI.COMM_WORLD if comm is None else comm
    sim, pressure, _ = strip_footing(h=h, comm=comm, **scene)
    g = sim.grid
    f, q = np.zeros(g.n_nodes), []

    def record(s):
        if s.t > t_from:
            f[:] += s.integrator.contact_force[:, 0, 1]
            q.append(pressure())
    sim.observe(record, every=1)
    sim.run(t_end=t_end, progress=False)
    own = f[: g.n_owned_nodes]
    total = comm.allreduce(float(own.sum()))
    keep = np.abs(own) > 1e-9 * abs(total)
    return g.node_x[: g.n_owned_nodes][keep], own[keep] / total, float(np.mean(q))
