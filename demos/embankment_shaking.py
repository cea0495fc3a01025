"""A 35 deg Mohr-Coulomb embankment with softening on a 10 m elastic foundation with periodic
sides, shaken at the base (issue 8): crest runout against time.

    python3 demos/embankment_shaking.py [--out DIR] [--quick] [--amplitude A_G] [--face X]
    mpirun -n 2 python3 demos/embankment_shaking.py

Geometry (plane strain, structured quadrilaterals of size h; default h = 0.5 m, --quick 1 m):
  the mesh spans 0 < x < L = 40 m (periodic: sim.set_periodic(0), on_leave="periodic") and
  0 < y < D + H_E + 1 m;
  foundation: 0 < y < D = 10 m over the whole period, fm.LinearElastic(E = 60 MPa,
  nu = 0.3, rho = 2000 kg/m^3): V_s = 107 m/s, f_0 = V_s / 4D = 2.7 Hz;
  embankment: H_E = 5 m high, crest B = 4 m wide, both slopes at 35 deg (base width
  B + 2 H_E / tan 35 = 18.3 m), centred at x' = 0 in the periodic coordinate
  x' = x + X_FACE wrapped to [-L/2, L/2). The model is a row of embankments 40 m apart, so
  where the mesh's periodic face lies is a free choice: it is put at x' = X_FACE = 6 m, through
  the right slope at mid-height (the slope's surface is at y = 12.4 m there), where the
  shaking moves the soil most. The tie then carries the sliding embankment itself, not only
  the level foundation, and soil slides out through the right face of the mesh and re-enters
  through the left one. Plots, probes and CSVs use x' (crest centre at x' = 0).
  Soil: fm.MohrCoulomb(E = 20 MPa, nu = 0.3, rho = 2000 kg/m^3, phi = 37 deg, c = 10 kPa,
  psi = 0, tension cut-off 0, phi_res = 28 deg, c_res = 1 kPa, eta = 20): exponential
  softening of phi and c with the plastic deviatoric strain. Infinite-slope factor of safety
  at the 5 m depth, tan phi / tan 35 + c / (rho g H_E cos^2 35 tan 35): 1.29 with the peak
  and 0.78 with the residual strength, so the slope stands under gravity but, once the
  shaking has softened it, goes on moving for a while after the shaking ends.
  2 x 2 particles per cell (same density in both soils, so the K0 overburden is exact).
Initial state: fenicsmpm.materials.initial_stress.k0_stress below the embankment/ground surface
  (K0 = nu / (1 - nu) = 0.43), gravity g = 9.81 m/s^2 in full from t = 0.
Stages (one explicit run, fm.Explicit("MUSL"), dt = "auto", cfl 0.5; --scheme ga:
  fm.ExplicitGeneralizedAlpha(rho_b = 0.8), which matches MUSL at --quick (crest settlement
  0.573 vs 0.534 m, re-run 2026-12-02) but at h = 0.5 m stopped at t = 3.6 s with a particle flung to
  y = -2.8e19 m near the left toe: its USL-type update divides by small nodal masses):
  0 < t < T_S (1 s; --quick 0.5 s): static, no input (the K0 state settles under gravity);
  T_S < t < T_S + N / f: base shaking, rigid base (fm.rigid_base: base nodes fixed, relative
  frame body force -m a_g(t)), horizontal acceleration
      a_g(t) = A w(tau) sin(2 pi f tau),  tau = t - T_S,  A = 0.3 g (--amplitude), f = 2 Hz,
  N = 4 cycles (--quick 3), w a cosine taper over the first and last half cycle,
  baseline-corrected (fm.InputMotion, order 1, the record starts at T_S so a_g = 0 before);
  then free vibration for 2.5 s (--quick 1 s).
Reported (rank 0 prints a table; returned as a dict): crest displacement (relative to the
  base; that is the permanent deformation) against time: the crest centre (settlement) and
  the two crest shoulders (x' = -/+ B/2: outward horizontal runout and settlement), its value
  at the end of the static stage and at the end of the run; the mass (exact: particles are
  only wrapped, never removed); particles wrapped through the periodic face (largest number
  at any sample, and how many ended on the other side); the state check on wrapped particles
  (x = x0 + u - / + L); max plastic deviatoric strain; min det F.
Writes to DIR (default results/embankment_shaking/):
    embankment_shaking.png  the final eps_d^p as a raster (mean per square of 3h/4,
                            fenicsmpm.io.particle_raster; initial outline dashed), crest
                            displacement histories and the input acceleration
    crest_runout.csv        t, a_g, crest centre u_x u_y, left and right shoulder u_x u_y
"""
import argparse
import math
import os
import time

import numpy as np
from mpi4py import MPI
from dolfinx import mesh as dmesh

import fenicsmpm as fm
from fenicsmpm.io import particle_raster, raster_shape
from fenicsmpm.materials.initial_stress import k0_stress

comm = MPI.COMM_WORLD
G = 9.81
L, D, H_E, B, SLOPE = 40.0, 10.0, 5.0, 4.0, 35.0
RHO = 2000.0
FOUNDATION = dict(E=60.0e6, nu=0.3, density=RHO)
SOIL = dict(E=20.0e6, nu=0.3, density=RHO, phi=37.0, c=10.0e3, psi=0.0, tension_cutoff=0.0,
            phi_res=28.0, c_res=1.0e3, eta=20.0)
FREQ = 2.0
RHO_B = 0.8
X_FACE = 6.0               # x' of the periodic face (mesh x = 0 and x = L); --face
EVERY = 5                  # wrap count sampled every EVERY steps


def xwrap(x):
    """x' in [-L/2, L/2) of a mesh coordinate x: the periodic coordinate centred on the crest."""
    return np.mod(np.asarray(x) + X_FACE + 0.5 * L, L) - 0.5 * L


def to_mesh(xp):
    """The mesh coordinate x in [0, L) of x'."""
    return np.mod(np.asarray(xp) - X_FACE, L)


def surface(xp):
    """Ground / embankment surface height over x' (the embankment centred on x' = 0)."""
    run = H_E / math.tan(math.radians(SLOPE))
    d = np.abs(xp)
    return D + np.clip(H_E - (d - B / 2) * H_E / run, 0.0, H_E)


def input_motion(amplitude, t_s, cycles, t_end):
    """The tapered sine a_g(t) (module docstring) as an fm.InputMotion starting at t_s."""
    t = t_s + np.arange(int(round((t_end - t_s) / 1e-3)) + 1) * 1e-3
    tau = t - t_s
    T = cycles / FREQ
    ramp = 0.5 / FREQ
    w = np.ones_like(tau)
    w[tau < ramp] = 0.5 * (1 - np.cos(np.pi * tau[tau < ramp] / ramp))
    tail = tau > T - ramp
    w[tail] = 0.5 * (1 - np.cos(np.pi * np.clip(T - tau[tail], 0, None) / ramp))
    a = amplitude * G * w * np.sin(2 * np.pi * FREQ * tau)
    a[tau > T] = 0.0
    return fm.InputMotion(t, a, kind="acceleration", baseline=1)


def integrator(scheme):
    return fm.Explicit("MUSL") if scheme == "musl" else fm.ExplicitGeneralizedAlpha(RHO_B)


def build(h, motion, scheme="musl"):
    ny = int(round((D + H_E + 1.0) / h))
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [L, ny * h]], [int(round(L / h)), ny],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    found = fm.LinearElastic(**FOUNDATION)
    soil = fm.MohrCoulomb(**SOIL)
    p_f = fm.Particles.fill(grid, found, per_cell=2, region=lambda x: x[:, 1] < D)
    p_e = fm.Particles.fill(grid, soil, per_cell=2,
                            region=lambda x: (x[:, 1] > D) & (x[:, 1] < surface(xwrap(x[:, 0]))))
    pts = p_f + p_e
    k0_stress(pts, gravity=G, surface=lambda x: surface(xwrap(x[:, 0])))
    sim = fm.Simulation(grid, pts, integrator(scheme), dt="auto", cfl=0.5,
                        gravity=(0.0, -G), on_leave="periodic")
    sim.set_periodic(0)
    fm.rigid_base(sim, lambda x: np.abs(x[:, 1]) < 1e-9, motion, component=0)
    pts.add_field("x0", (2,))[:] = pts.x              # to check wrapped particles' state
    top = D + H_E - h / 4
    probes = dict(centre=sim.probe((to_mesh(h / 4), top), ["displacement"]),
                  left=sim.probe((to_mesh(-B / 2 + h / 4), top), ["displacement"]),
                  right=sim.probe((to_mesh(B / 2 - h / 4), top), ["displacement"]))
    return sim, soil, probes


def wrapped(p):
    """Per local particle: 0 if x = x0 + u, +1/-1 if x = x0 + u -/+ L (re-entered on the
    left / right), and the largest mismatch to the nearest of these."""
    off = p.x[:, 0] - p.x0[:, 0] - p.u[:, 0]
    k = np.round(off / L)
    err = np.abs(off - k * L)
    err = np.maximum(err, np.abs(p.x[:, 1] - p.x0[:, 1] - p.u[:, 1]))
    return k, (float(err.max()) if len(err) else 0.0)


def plot(eps, eps_emb, bounds, rows, t_s, t_shake, metrics, path):
    """eps: the eps_d^p raster over bounds (x', y); eps_emb: the same of the embankment soil
    alone (its 98th percentile sets the colour scale)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(3, 1, figsize=(10, 10), gridspec_kw=dict(height_ratios=(2.2, 1.3, 0.7)))
    ax = axes[0]
    vmax = max(np.nanpercentile(eps_emb, 98) if np.any(np.isfinite(eps_emb)) else 0.0, 1e-6)
    sc = ax.imshow(eps.T, origin="lower", extent=(*bounds[0], *bounds[1]), cmap="viridis",
                   vmin=0.0, vmax=vmax)
    xs = np.linspace(-L / 2, L / 2, 801)
    ax.plot(xs, surface(xs), "k--", lw=0.8, label="initial surface")
    ax.axhline(D, color="0.5", lw=0.5)
    ax.set_aspect("equal")
    ax.set_xlim(-L / 2, L / 2)
    ax.set_xlabel("x' [m] (periodic, crest at 0)")
    ax.set_ylabel("y [m]")
    ax.legend(loc="upper right", fontsize=8)
    fig.colorbar(sc, ax=ax, label=r"plastic deviatoric strain $\varepsilon_d^p$", shrink=0.7)
    ax.set_title(f"Embankment on periodic foundation, t = {rows[-1, 0]:.2f} s: shoulder runout "
                 f"{metrics['runout_final']:.3f} m, crest settlement {metrics['settlement_final']:.3f} m",
                 fontsize=10)
    t = rows[:, 0]
    ax = axes[1]
    ax.plot(t, rows[:, 2], "k-", label="crest centre $u_x$")
    ax.plot(t, -rows[:, 3], "k--", label="crest centre settlement $-u_y$")
    ax.plot(t, -rows[:, 4], "C0-", label="left shoulder outward $-u_x$")
    ax.plot(t, rows[:, 6], "C3-", label="right shoulder outward $u_x$")
    ax.plot(t, -rows[:, 5], "C0:", label="left shoulder $-u_y$")
    ax.plot(t, -rows[:, 7], "C3:", label="right shoulder $-u_y$")
    for ti in (t_s, t_shake):
        ax.axvline(ti, color="0.6", lw=0.6)
    ax.set_ylabel("crest displacement [m]")
    ax.legend(fontsize=7, ncol=3)
    ax.grid(alpha=0.3)
    axes[2].plot(t, rows[:, 1] / G, "C2-")
    axes[2].set_ylabel("$a_g$ [g]")
    axes[2].set_xlabel("t [s]")
    axes[2].grid(alpha=0.3)
    for a in axes[1:]:
        a.set_xlim(t[0], t[-1])
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/embankment_shaking", help="output directory")
    parser.add_argument("--quick", action="store_true", help="coarse grid, short record")
    parser.add_argument("--amplitude", type=float, default=0.3,
                        help="peak base acceleration in g (0: no shaking, the reference run)")
    parser.add_argument("--face", type=float, default=6.0,
                        help="x' of the periodic face (default 6: through the right slope; "
                             "20: through the level foundation, midway between embankments)")
    parser.add_argument("--scheme", choices=("ga", "musl"), default="musl",
                        help="explicit generalized-alpha (rho_b = 0.8) or MUSL")
    parser.add_argument("--cell", type=float, default=None, help="cell size h [m] (override)")
    args = parser.parse_args(argv)
    global X_FACE
    X_FACE = args.face
    h, t_s, cycles, t_free = (1.0, 0.5, 3, 1.0) if args.quick else (0.5, 1.0, 4, 2.5)
    h = args.cell or h
    t_shake = t_s + cycles / FREQ
    t_end = t_shake + t_free
    if comm.rank == 0:
        os.makedirs(args.out, exist_ok=True)
    motion = input_motion(args.amplitude, t_s, cycles, t_end)
    sim, soil, probes = build(h, motion, args.scheme)
    p = sim.particles
    mass0 = comm.allreduce(float(np.sum(p.mass)))
    n0 = p.n_global()
    n_emb = comm.allreduce(int(np.count_nonzero(p.material_id == 1)))
    stats = dict(max_wrapped=0, det_min=np.inf, state_err=0.0)

    def observe(s):
        k, err = wrapped(s.particles)
        stats["max_wrapped"] = max(stats["max_wrapped"],
                                   comm.allreduce(int(np.count_nonzero(k))))
        stats["state_err"] = max(stats["state_err"], comm.allreduce(err, op=MPI.MAX))
        d = np.linalg.det(s.particles.F[:, :2, :2]) if len(s.particles) else np.array([np.inf])
        stats["det_min"] = min(stats["det_min"], comm.allreduce(float(d.min()), op=MPI.MIN))

    sim.observe(observe, every=EVERY)
    t0 = time.perf_counter()
    sim.run(t_end=t_s, progress=False)
    eps_static = comm.allreduce(float(p.state[p.material_id == 1, 0].max())
                                if np.any(p.material_id == 1) else 0.0, op=MPI.MAX)
    sim.run(t_end=t_end, progress=False)
    wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    observe(sim)

    data = {k: pr.data() for k, pr in probes.items()}
    t = np.concatenate([[0.0], data["centre"]["t"]])

    def series(name, comp):
        return np.concatenate([[0.0], data[name][f"displacement_{comp}"]])

    rows = np.column_stack([t, motion.acceleration(t)] +
                           [series(n, c) for n in ("centre", "left", "right") for c in "xy"])
    k_end, _ = wrapped(p)
    n_crossed = comm.allreduce(int(np.count_nonzero(k_end)))
    inside = comm.allreduce(bool(np.all((p.x[:, 0] >= 0.0) & (p.x[:, 0] <= L))), op=MPI.LAND)
    mass1 = comm.allreduce(float(np.sum(p.mass)))
    finite = comm.allreduce(bool(np.all(np.isfinite(p.x)) and np.all(np.isfinite(p.stress))
                                 and np.all(np.isfinite(p.v))), op=MPI.LAND)
    i_s = int(np.searchsorted(t, t_s - 1e-9))

    def crest(i):
        c = rows[i]
        return dict(centre_ux=c[2], centre_uy=c[3], left_ux=c[4], left_uy=c[5],
                    right_ux=c[6], right_uy=c[7],
                    runout=0.5 * (c[6] - c[4]), settlement=-c[3],
                    magnitude=float(np.max(np.hypot(c[2::2], c[3::2]))))

    static, final = crest(i_s), crest(len(t) - 1)
    mag = np.max(np.hypot(rows[:, 2::2], rows[:, 3::2]), axis=1)
    bounds = ((-L / 2, L / 2), (0.0, D + H_E + 1.0))
    shape = raster_shape(bounds, 0.75 * h)
    xp = np.column_stack([xwrap(p.x[:, 0]), p.x[:, 1]])
    emb = p.material_id == 1
    eps_r = particle_raster(comm, xp, p.state[:, 0], bounds, shape)
    eps_emb = particle_raster(comm, xp[emb], p.state[emb, 0], bounds, shape)
    eps_loc = p.state[p.material_id == 1, 0]
    eps_f = p.state[p.material_id == 0, 0] if p.state.shape[1] else np.zeros(0)
    metrics = dict(h=h, face=X_FACE, scheme=args.scheme, dt=sim.dt, steps=sim.step_count, t_static=t_s, t_shake_end=t_shake,
                   t_end=float(sim.t), amplitude_g=args.amplitude, frequency=FREQ, cycles=cycles,
                   n_particles=n0, n_particles_final=p.n_global(), n_embankment=n_emb,
                   mass_initial=mass0, mass_final=mass1, finite=finite, min_det_F=stats["det_min"],
                   max_wrapped=stats["max_wrapped"], n_crossed_final=n_crossed,
                   wrap_state_error=stats["state_err"], all_inside=inside,
                   static=static, final=final,
                   runout_final=final["runout"], settlement_final=final["settlement"],
                   crest_max_static=float(mag[: i_s + 1].max()),
                   crest_max=float(mag.max()),
                   max_plastic_strain=comm.allreduce(float(eps_loc.max()) if len(eps_loc) else 0.0,
                                                     op=MPI.MAX),
                   max_plastic_strain_static=eps_static,
                   max_plastic_strain_foundation=comm.allreduce(
                       float(np.abs(eps_f).max()) if len(eps_f) else 0.0, op=MPI.MAX),
                   wall_s=wall,
                   history=dict(t=rows[:, 0].tolist(), centre_ux=rows[:, 2].tolist(),
                                centre_uy=rows[:, 3].tolist(), left_ux=rows[:, 4].tolist(),
                                left_uy=rows[:, 5].tolist(), right_ux=rows[:, 6].tolist(),
                                right_uy=rows[:, 7].tolist()))
    if comm.rank == 0:
        png = os.path.join(args.out, "embankment_shaking.png")
        csv = os.path.join(args.out, "crest_runout.csv")
        np.savetxt(csv, rows, delimiter=",", comments="",
                   header="t,a_g,centre_ux,centre_uy,left_ux,left_uy,right_ux,right_uy")
        plot(eps_r, eps_emb, bounds, rows, t_s, t_shake, metrics, png)
        m = metrics
        print(f"\nEmbankment shaking: L = {L:g} m periodic, foundation {D:g} m, embankment "
              f"H = {H_E:g} m, crest {B:g} m, {SLOPE:g} deg slopes; h = {h:g} m, {n0} particles "
              f"({n_emb} embankment), dt = {sim.dt:.4g} s, {m['steps']} "
              f"{'MUSL' if args.scheme == 'musl' else f'explicit gen.-alpha (rho_b = {RHO_B})'} steps, {comm.size} rank(s), {wall:.1f} s wall")
        print(f"input: {args.amplitude:g} g x sin(2 pi {FREQ:g} Hz tau), {cycles} cycles from "
              f"t = {t_s:g} s (tapered), free until t = {t_end:g} s; periodic face at "
              f"x' = {X_FACE:g} m")
        print(f"{'crest displacement [m]':<30} {'t = ' + format(t_s, 'g') + ' s (static)':>20} "
              f"{'t = ' + format(t_end, 'g') + ' s':>14}")
        for name, key in (("centre u_x", "centre_ux"), ("centre u_y", "centre_uy"),
                          ("left shoulder u_x", "left_ux"), ("left shoulder u_y", "left_uy"),
                          ("right shoulder u_x", "right_ux"), ("right shoulder u_y", "right_uy"),
                          ("shoulder runout (outward)", "runout"),
                          ("crest settlement", "settlement")):
            print(f"{name:<30} {static[key]:20.4f} {final[key]:14.4f}")
        step = max(1, len(t) // 12)
        print("crest history [t s: runout / settlement m]: " + ", ".join(
            f"{ti:.2f}: {0.5 * (r[6] - r[4]):.3f}/{-r[3]:.3f}" for ti, r in zip(t[::step], rows[::step])))
        print(f"max |crest displacement| static / whole run [m]: {m['crest_max_static']:.4f} / "
              f"{m['crest_max']:.4f}")
        print(f"mass start / end [kg/m]: {mass0:.6f} / {mass1:.6f}; particles {n0} -> "
              f"{m['n_particles_final']}")
        print(f"periodic wrap: up to {m['max_wrapped']} particle(s) on the other side at once, "
              f"{n_crossed} at the end; state check |x - (x0 + u -/+ L)| <= "
              f"{m['wrap_state_error']:.2e} m")
        print(f"max plastic dev. strain: embankment {m['max_plastic_strain_static']:.4f} (static), "
              f"{m['max_plastic_strain']:.4f} (end), foundation "
              f"{m['max_plastic_strain_foundation']:.1e}; min det F {m['min_det_F']:.4f}")
        print(f"\nplot:  {png}\ncsv:   {csv}")
        metrics.update(png=png, csv=csv)
    return comm.bcast(metrics, root=0)


if __name__ == "__main__":
    main()
