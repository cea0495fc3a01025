"""Rough bases and rigid contact that hold a body at rest (issue 17; boundaries.friction,
contact.multi_velocity): an elastic block 1 m x 0.5 m (E = 10 MPa, nu = 0.3, rho = 2000) on
a frictional base, on an incline (gravity rotated, or the mesh itself rotated with the base
normal from its facets), or on a rigid body.

Known answers: the static settlement of the centroid on a smooth base (plane strain, free
sides) rho g H^2 (1 - nu^2) / (3 E) = 0.1488 mm (STATIC); on a 30 deg incline a block sticks
when mu >= tan 30 deg and otherwise slides with a = g (sin theta - mu cos theta)."""
import numpy as np

G, RHO, E, NU, H = 9.81, 2000.0, 10e6, 0.3, 0.5
STATIC = RHO * G * H ** 2 * (1 - NU ** 2) / (3 * E)


def incline_answer(theta, mu, t):
    """Displacement along the incline at time t of a block released from rest (0: sticks)."""
    th = np.radians(theta)
    return 0.5 * max(G * (np.sin(th) - mu * np.cos(th)), 0.0) * t ** 2


def _geostatic(p, sel, depth, th, R):
    """The equilibrium stress of the block on an incline of angle th, in the base frame
    rotated to the mesh by R: sigma_yy = -rho g cos th d, sigma_xx = K0 sigma_yy,
    sigma_xy = rho g sin th d (d the depth below the block's top)."""
    s = np.zeros((len(depth), 2, 2))
    s[:, 1, 1] = -RHO * G * np.cos(th) * depth
    s[:, 0, 0] = NU / (1 - NU) * s[:, 1, 1]
    s[:, 0, 1] = s[:, 1, 0] = RHO * G * np.sin(th) * depth
    p.stress[sel, :2, :2] = R @ s @ R.T
    p.stress[sel, 2, 2] = s[:, 0, 0]


def block_on_base(scheme="MUSL", mu=0.5, theta=0.0, geostatic=False, ramp=None, cfl=0.5, h=0.05,
                  inclined_mesh=False, contact=False, shape="mpm", transfer=None, comm=None):
    """The block on a frictional base `sim.add_friction` inclined by theta: gravity rotated,
    or with inclined_mesh the mesh rotated and the base normal taken from its facets; with
    `contact` the block is two bodies side by side (fm.ExplicitContact, mu 0.5 between them);
    `transfer` is fm.Explicit's (None: FLIP, "apic").
    Returns (sim, base boundary, history list of (t, along, normal) mass-weighted
    displacement, appended every 5 steps)."""
    from dolfinx import mesh
    from mpi4py import MPI
    import fenicsmpm as fm
    comm = MPI.COMM_WORLD if comm is None else comm
    th = np.radians(theta)
    msh = mesh.create_rectangle(comm, [[0, 0], [3.0, 1.0]], [round(3 / h), round(1 / h)],
                                mesh.CellType.quadrilateral)
    rot = np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]])   # base frame -> mesh
    if inclined_mesh:
        msh.geometry.x[:, :2] = msh.geometry.x[:, :2] @ rot.T
    grid = fm.Grid(msh)
    frame = (lambda x: x @ rot) if inclined_mesh else (lambda x: x)        # mesh -> base frame
    p = fm.Particles.fill(grid, fm.LinearElastic(E=E, nu=NU, density=RHO), per_cell=2,
                          region=lambda x: (np.abs(frame(x)[:, 0] - 1.0) < 0.5) & (frame(x)[:, 1] < H))
    if geostatic:
        _geostatic(p, slice(None), H - frame(p.x)[:, 1], th, rot if inclined_mesh else np.eye(2))
    gravity = (0.0, -G) if inclined_mesh else (G * np.sin(th), -G * np.cos(th))
    integrator = fm.Explicit(scheme, transfer=transfer)
    if contact:
        fm.set_body(p, 1, region=lambda x: frame(x)[:, 0] > 1.0)
        integrator = fm.ExplicitContact(scheme, mu=0.5)
    sim = fm.Simulation(grid, p, integrator, dt="auto", cfl=cfl, gravity=gravity, gravity_ramp=ramp,
                        shape=shape)
    if inclined_mesh:
        base = sim.add_friction(lambda x: np.abs(frame(x)[:, 1]) < 1e-9, mu)
    else:
        base = sim.add_friction(lambda x: np.isclose(x[:, 1], 0.0), mu, normal=(0.0, -1.0))
    return sim, base, _history(sim, frame, lambda: slice(None))


def block_on_rigid_body(mu, theta=30.0, h=0.05, algorithm="multi-velocity", comm=None, shape="auto"):
    """The block (body 0, geostatic) on a rigid body (body 1, held at rest, its face on the
    grid line y = 0.25, prescribed outward normal (0, 1)), gravity rotated by theta, through
    fm.ExplicitContact (multi-velocity, or penalty with polylines on both faces), with the
    shape family `shape`.
    Returns (sim, history as in block_on_base)."""
    from dolfinx import mesh
    from mpi4py import MPI
    import fenicsmpm as fm
    comm = MPI.COMM_WORLD if comm is None else comm
    th, y0 = np.radians(theta), 0.25
    msh = mesh.create_rectangle(comm, [[0, 0], [3.0, 1.0]], [round(3 / h), round(1 / h)],
                                mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, fm.LinearElastic(E=E, nu=NU, density=RHO), per_cell=2,
                          region=lambda x: ((np.abs(x[:, 0] - 1.0) < 0.5) & (x[:, 1] < y0 + H))
                          | (x[:, 1] < y0))
    blk = fm.set_body(p, 1, region=lambda x: x[:, 1] < y0) == 0
    _geostatic(p, blk, y0 + H - p.x[blk, 1], th, np.eye(2))
    if algorithm == "penalty":
        from ..contact.penalty import line, rectangle
        M = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))
        integ = fm.ExplicitContact("MUSL", mu=mu, rigid={1: (0.0, 0.0)}, algorithm="penalty",
                                   penalty=dict(k_n=M / h))
        integ.add_polyline(0, rectangle((0.5, y0), (1.5, y0 + H), h / 2), closed=True)
        integ.add_polyline(1, line((3.0, y0), (0.0, y0), round(6.0 / h)))
    else:
        integ = fm.ExplicitContact("MUSL", mu=mu, rigid={1: (0.0, 0.0)}, normal={1: (0.0, 1.0)})
    sim = fm.Simulation(grid, p, integ, dt="auto", gravity=(G * np.sin(th), -G * np.cos(th)), shape=shape)
    return sim, _history(sim, lambda x: x, lambda: p.body == 0)


def _history(sim, frame, select):
    """Observe the mass-weighted displacement (along, normal to the base) of the selected
    particles every 5 steps; returns the list it fills with (t, along, normal)."""
    p = sim.particles
    sel = select()
    m0 = p.total(p.mass[sel])
    c0 = np.array([p.total(p.mass[sel] * frame(p.x[sel])[:, k]) for k in range(2)]) / m0
    hist = []

    def record(s):
        q = select()
        hist.append([s.t] + [p.total(p.mass[q] * frame(p.x[q])[:, k]) / m0 - c0[k] for k in range(2)])

    sim.observe(record, every=5)
    return hist
