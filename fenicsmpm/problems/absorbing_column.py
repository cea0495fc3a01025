"""W1 (BENCHMARKS.md section W): a soil column hit by a Gaussian surface pulse, standing on a
fixed, viscous (Lysmer-Kuhlemeyer) or viscoelastic (Kelvin-Voigt) base. Shared by the tests,
the demos and the `absorbing` benchmark case.

    sim, exact = absorbing_column(fm.Explicit("MUSL"), base="viscous")
    sim.run(t_end=1.4)
    h = histories(exact["probes"][50.0], exact)       # collective
    R = reflection_ratio(h, exact)

Column: height H (default 100 m), width `width` (default one cell), E = 20 MPa, nu = 0.25,
rho = 1500 kg/m^3, plane strain, `per_cell` x `per_cell` particles in every cell of a
structured quadrilateral mesh [0, width] x [0, H] (no empty cells: the displacements are
millimetres). Load on the top facets: a pressure p(t) = 0.375 / (a sqrt(pi))
exp(-((t - t0) / a)^2) kPa, t0 = 0.05 s, a = 0.021 s (peak 10.07 kPa, impulse
I = 0.375 kPa s). Sides: rollers (the x components of the side nodes fixed), so the column is
1D (uniaxial strain) and the pulse travels at c_p = sqrt(M / rho) = 126.5 m/s.

Base (the facets at y = 0):
  "fixed"         all displacement components fixed (total reflection),
  "viscous"       fm.Viscous: t = -rho c_p v_n n - rho c_s v_s (a = b = 1),
  "viscoelastic"  fm.Viscoelastic: the viscous dashpots plus springs; `spring` picks the law
                  ("deeks-randolph": k_n = k_s = G / (2 r_b), r_b defaults to H, the distance
                  from the loaded surface to the base; "kellezi": k_n = rho c_p^2 / r_b,
                  k_s = rho c_s^2 / r_b; "virtual-layer": k = rho c^2 / delta),
  a callable      a user Robin law traction(u, v, n) -> UFL vector, put on the base facets as
                  fm.Robin(base, where=exact["base_where"]).

Inclined column (`angle`, degrees, counter-clockwise): the mesh coordinates of the
create_rectangle mesh are rotated about the origin before the Grid is built (so the grid is
not axis-aligned and uses the bounding-box-tree location path); the load, the base, the
probes and the histories are all rotated with it. The library's `fix` only fixes Cartesian
components, so rollers on inclined sides cannot be expressed with it: an inclined column is
built WITHOUT side rollers (rollers=False, the default for angle != 0; rollers=True with
angle != 0 raises ValueError). Without rollers the sides are free, the column is a
plane-strain bar (the lateral Poisson expansion is free) and the pulse travels at
c_bar = sqrt(E / ((1 - nu^2) rho)) = 119.3 m/s instead of c_p, so the dashpots tuned to
c_p reflect a little ((c_p - c_bar) / (c_p + c_bar) ~ 3 % for a long wave). The inclined
check therefore compares a rotated roller-free column with the axis-aligned roller-free
column (rollers=False, angle=0): same physics, only the orientation differs.

Probes: one per depth in `depths` that lies in the column (measured from the loaded surface,
default 0, 25, 50, 75, 100 m), at the particle nearest to the column's centre line at that depth, recording stress,
velocity, displacement and position. `histories(probe, exact)` turns a probe's record into
column-axis components (collective: call it on every rank after the run).

Exact answers (SI units, Pa, m, s; 1D wave theory):
  c_p, arrival(depth) = t0 + depth / c_p (the time the pulse peak passes),
  peak_stress = 0.375e3 / (a sqrt(pi)) Pa (compressive), peak_velocity = p_max / (rho c_p),
  final_offset = I / (rho c_p) (the viscous base: the whole column ends displaced by this
  much, towards the base), impulse I, load(t) (the pressure p(t) in Pa)."""
import math

import numpy as np
from mpi4py import MPI
from dolfinx import mesh as dmesh

from ..boundaries import Robin, Viscoelastic, Viscous
from ..grid import Grid
from ..materials import LinearElastic
from ..particles import Particles
from ..simulation import Simulation

E, NU, RHO = 20.0e6, 0.25, 1500.0
T0, A = 0.05, 0.021                     # pulse centre and width [s]
IMPULSE = 375.0                         # Pa s (0.375 kPa s)
PEAK = IMPULSE / (A * math.sqrt(math.pi))    # 10.07 kPa
BASES = ("fixed", "viscous", "viscoelastic")
DEPTHS = (0.0, 25.0, 50.0, 75.0, 100.0)


def gaussian_pulse(t):
    """The W1 surface pressure p(t) in Pa (compression positive)."""
    return PEAK * math.exp(-((t - T0) / A) ** 2)


def absorbing_column(integrator, base="viscous", dx=0.5, height=100.0, width=None, per_cell=2,
                     dt=None, spring="deeks-randolph", r_b=None, angle=0.0, delta=None,
                     rollers=None, depths=DEPTHS, load=None, cfl=0.5, comm=MPI.COMM_WORLD,
                     partitioner=None, shape="auto"):
    """W1: the column described in the module docstring. Returns (sim, exact).

    dt: None -> "auto" (cfl * dx / c_p) for explicit integrators, 0.005 s (W1) for implicit
    ones; or a number. load: the surface pressure p(t) in Pa (default the W1 pulse).
    exact["probes"] maps each depth to its Probe. partitioner: an optional dolfinx cell
    partitioner for the mesh (e.g. fm.partition.strips(1, ny, axis=1) for reproducible runs).
    shape: the Simulation's shape family."""
    if width is None:
        width = dx
    for name, val in (("dx", dx), ("height", height), ("width", width)):
        if not (isinstance(val, (int, float)) and math.isfinite(val) and val > 0):
            raise ValueError(f"absorbing_column: '{name}' must be > 0, got {val!r}")
    ny, nx = int(round(height / dx)), int(round(width / dx))
    if ny < 2 or nx < 1 or not (math.isclose(ny * dx, height) and math.isclose(nx * dx, width)):
        raise ValueError(f"absorbing_column: 'height' and 'width' must be multiples of dx = {dx}"
                         f" (got {height}, {width})")
    if not (isinstance(base, str) and base in BASES) and not callable(base):
        raise ValueError(f"absorbing_column: 'base' must be one of {BASES} or a Robin law "
                         f"traction(u, v, n), got {base!r}")
    if rollers is None:
        rollers = angle == 0.0
    if rollers and angle != 0.0:
        raise ValueError("absorbing_column: side rollers on an inclined column are not "
                         "expressible with fix() (Cartesian components only); use rollers=False")
    load = gaussian_pulse if load is None else load

    extra = {} if partitioner is None else {"partitioner": partitioner}
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [width, height]], [nx, ny],
                                 dmesh.CellType.quadrilateral, **extra)
    th = math.radians(angle)
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    if angle != 0.0:
        gx = msh.geometry.x
        gx[:, :2] = gx[:, :2] @ R.T
    ex, axis = R[:, 0].copy(), R[:, 1].copy()         # column-local x and y (axis) directions
    tol = 1e-8 * height

    def local(x):
        return x @ ex, x @ axis

    def base_where(x):
        return np.abs(local(x)[1]) < tol

    def top_where(x):
        return np.abs(local(x)[1] - height) < tol

    def sides_where(x):
        s = local(x)[0]
        return (np.abs(s) < tol) | (np.abs(s - width) < tol)

    grid = Grid(msh)
    mat = LinearElastic(E=E, nu=NU, density=RHO)
    pts = Particles.fill(grid, mat, per_cell=per_cell)
    cp, cs = mat.p_wave_speed, mat.s_wave_speed
    if dt is None:
        dt = "auto" if integrator.explicit else 0.005
    sim = Simulation(grid, pts, integrator, dt=dt, cfl=cfl, shape=shape)
    sim.add_traction(top_where, lambda t: -load(t) * axis)
    if rollers:
        sim.fix(sides_where, [0])
    law = None
    if base == "fixed":
        sim.fix(base_where)
    elif base == "viscous":
        law = Viscous(base_where)
    elif base == "viscoelastic":
        if r_b is None and spring != "virtual-layer":
            r_b = height
        law = Viscoelastic(base_where, r_b=r_b, delta=delta, spring=spring)
    else:
        law = Robin(base, base_where)
    if law is not None:
        sim.add_boundary(law)

    probes = {}
    for d in (d for d in depths if d <= height):
        point = R @ np.array([0.5 * width, height - d])
        probes[float(d)] = sim.probe(point, ["stress", "velocity", "displacement", "position"])
    exact = dict(
        c_p=cp, c_s=cs, M=mat.constrained_modulus, G=mat.shear_modulus, density=RHO,
        c_bar=math.sqrt(E / ((1 - NU ** 2) * RHO)),
        arrival=lambda depth: T0 + depth / cp,
        peak_stress=PEAK, peak_velocity=PEAK / (RHO * cp),
        final_offset=IMPULSE / (RHO * cp), impulse=IMPULSE, load=load, t0=T0, a=A,
        height=height, width=width, dx=dx, dt=sim.dt, courant=cp * sim.dt / dx, angle=angle,
        rollers=bool(rollers), base=base if isinstance(base, str) else "user",
        axis=axis, rotation=R, base_where=base_where, top_where=top_where,
        sides_where=sides_where, law=law, probes=probes, material=mat)
    if isinstance(law, Viscoelastic):
        exact.update(spring=law.spring, spring_length=law.length, k_n=law.k_n, k_s=law.k_s)
    return sim, exact


def histories(probe, exact):
    """A probe's record in column-axis components (collective). Returns a dict of arrays:
    t, stress (axial normal stress e.sigma.e, compression negative), velocity and
    displacement (along the axis, positive away from the base), and the probe particle's
    depth below the loaded surface (from its initial position)."""
    d = probe.data()
    e = exact["axis"]
    sxx, syy, sxy = d["stress_xx"], d["stress_yy"], d["stress_xy"]
    x0 = np.array([d["position_x"][0], d["position_y"][0]])
    return dict(
        t=d["t"],
        stress=e[0] ** 2 * sxx + 2 * e[0] * e[1] * sxy + e[1] ** 2 * syy,
        velocity=e[0] * d["velocity_x"] + e[1] * d["velocity_y"],
        displacement=e[0] * d["displacement_x"] + e[1] * d["displacement_y"],
        depth=exact["height"] - float(x0 @ e))


def split_time(exact):
    """t0 + H / c_p: the time the incident peak reaches the base. At a probe at depth y the
    incident pulse passes at t0 + y / c_p and the base's reflection arrives at
    t0 + (2H - y) / c_p, so this instant separates the two at every depth (the trailing
    dispersive ripple of the incident pulse has died down to < 0.1 % of the peak by then at
    dx = 0.5 m; at arrival + 4a it is still ~4 %)."""
    return exact["t0"] + exact["height"] / exact["c_p"]


def _incident_window(h, exact):
    return h["t"] <= split_time(exact)


def incident_peak(h, exact):
    """Largest |axial stress| while the incident pulse passes the probe (t <= split_time)."""
    return float(np.max(np.abs(h["stress"][_incident_window(h, exact)])))


def reflection_ratio(h, exact, t_end=None):
    """Reflection ratio: the largest |axial stress| after the incident pulse has passed the
    probe (split_time < t <= t_end, default the end of the record), over the measured
    incident peak at the same probe. Meaningful for probes away from the base."""
    late = ~_incident_window(h, exact)
    if t_end is not None:
        late &= h["t"] <= t_end
    if not np.any(late):
        raise ValueError("reflection_ratio: the record ends before the incident pulse has passed")
    return float(np.max(np.abs(h["stress"][late]))) / incident_peak(h, exact)


def arrival_time(h, exact, field="stress"):
    """Time of the incident peak of |field| at the probe (parabola through the top three
    samples)."""
    w = np.flatnonzero(_incident_window(h, exact))
    y = np.abs(h[field][w])
    k = int(np.argmax(y))
    t = h["t"][w]
    if 0 < k < len(y) - 1:
        y0, y1, y2 = y[k - 1], y[k], y[k + 1]
        den = y0 - 2 * y1 + y2
        if den != 0:
            return float(t[k] + 0.5 * (y0 - y2) / den * (t[k + 1] - t[k]))
    return float(t[k])


def incident_peak_velocity(h, exact):
    """Largest |axial velocity| while the incident pulse passes the probe."""
    return float(np.max(np.abs(h["velocity"][_incident_window(h, exact)])))


def summary(sim, exact, depth=50.0, base_depth=None):
    """The W1 numbers of a finished run (collective): reflection ratio and incident peaks at
    `depth`, arrival time error, and the final base displacement (the deepest probe) with
    its error against -I / (rho c_p) (meaningful for the viscous base)."""
    probes = exact["probes"]
    h = histories(probes[float(depth)], exact)
    hb = histories(probes[max(probes) if base_depth is None else float(base_depth)], exact)
    arr = arrival_time(h, exact)
    t_exact = exact["arrival"](h["depth"])
    u_end = float(hb["displacement"][-1])
    return dict(
        reflection=reflection_ratio(h, exact),
        incident_peak_stress=incident_peak(h, exact),
        peak_stress_error=incident_peak(h, exact) / exact["peak_stress"] - 1.0,
        incident_peak_velocity=incident_peak_velocity(h, exact),
        peak_velocity_error=incident_peak_velocity(h, exact) / exact["peak_velocity"] - 1.0,
        arrival=arr, arrival_exact=t_exact, arrival_error=(arr - t_exact) / t_exact,
        probe_depth=h["depth"], base_displacement=u_end,
        offset_error=(-u_end - exact["final_offset"]) / exact["final_offset"])
