"""L3: collapse of a Mohr-Coulomb soil column on a frictional base (seed 002 section 5.1).

    python3 demos/column_collapse.py [--out DIR] [--quick]
    mpirun -n 2 python3 demos/column_collapse.py

BENCHMARKS.md L3: Mohr-Coulomb soil E = 20 MPa, nu = 0.42, rho = 1000 kg/m^3, c = 1 kPa,
phi = 42 deg, psi = 0 (fm.MohrCoulomb, no softening), plane strain, g = 9.8 m/s^2, 3 x 3
particles per cell, explicit MUSL (FLIP), dt = 1 ms. The seed's figure gives the column's
shape but not its size in the text; here it is W = 4 m wide and H = 8 m tall, on cells of
h = 0.4 m (10 x 20 cells of material, 1800 particles: the seed's count). --quick: h = 0.8 m
(450 particles), dt = 2 ms.

Initial state: K0 = nu / (1 - nu) = 0.724 (fenicsmpm.materials.initial_stress.k0_stress below the top of
the column): sigma_yy = -rho g d, sigma_xx = sigma_zz = K0 sigma_yy, no shear. Gravity acts in
full from t = 0 and the sides are free, so the column collapses plastically.
Base: a rigid frictional boundary (sim.add_friction, Coulomb mu = 0.6, stick/slip) on the
grid nodes of y = 0; the mesh extends far enough on both sides that the deposit stays on it.

The run goes on until the motion stops: in chunks of 0.1 s, after the mean speed (below) has
peaked, until the runout grows by less than STOP_RUNOUT = 1 mm in a chunk, or t_max = 4 s
(--quick: t_max = 2 s). The seed: "the time of the collapse is t = 2.5 s". The mean speed
falls to 0.003 m/s (0.1 % of the 2.73 m/s peak, at h = 0.4 m, with the defaults since
2026-12-06: cpGIMP, run-out 5.22 m, stopped at 2.6 s; 0.022 m/s with the standard family and
Mohr-Coulomb's separation gap before) once the runout has stopped; with pure FLIP (before
fm.Explicit's plastic default flip = 0.99) the deposit kept 0.14 m/s of particle-velocity
noise at the rough base.
Printed and returned:
  runout         the final spread of the deposit, (max x_p - min x_p - W) / 2, from the
                 particle centres (the advance of each toe beyond the initial column edge,
                 averaged over the two sides); runout_left / runout_right each side;
  height         final height of the deposit (max y_p, particle centres);
  mean speed     the mass-weighted mean speed sum |v_p| m_p / sum m_p (seed 002 eq 5.12)
                 every 10 steps (its history is in mean_speed.csv); the peak and the final
                 value;
  t_stop         the end of the first 0.1 s chunk after the peak in which the runout grew
                 by less than 1 mm (nan if not by t_max);
  mass           total particle mass at the start and the end (conserved exactly);
  min det F      smallest Jacobian over all particles and the run (> 0: no inversion;
                 the guards would stop the run otherwise).

Writes to DIR (default results/column_collapse/):
    column_collapse.png   the final deposit: a raster of the mean accumulated plastic
                          deviatoric strain (MohrCoulomb state column 0) per square of about 3h / 4
                          (fenicsmpm.io.particle_raster, reduced over the ranks), with the
                          initial outline, and the mean-speed history
    mean_speed.csv        t, mean speed
"""
import argparse
import os
import time

import numpy as np
from mpi4py import MPI
from dolfinx import mesh as dmesh

import fenicsmpm as fm
from fenicsmpm.io import particle_raster, raster_shape
from fenicsmpm.materials.initial_stress import k0_stress

comm = MPI.COMM_WORLD
E, NU, RHO = 20.0e6, 0.42, 1000.0
PHI, C, PSI = 42.0, 1.0e3, 0.0
MU = 0.6
G = 9.8
W, H = 4.0, 8.0            # column width and height [m]
HALF_SPAN = 14.0           # the mesh spans -HALF_SPAN < x < HALF_SPAN
STOP_RUNOUT = 1e-3         # [m] motion stopped: runout growth within a 0.1 s chunk
EVERY = 10                 # mean speed sampled every EVERY steps


def build(h, dt, fbar=False, shape="auto"):
    """The L3 scene: (sim, soil). Symmetric full column centred on x = 0."""
    nx = int(round(2 * HALF_SPAN / h))
    ny = int(round((H + 2 * h) / h))
    msh = dmesh.create_rectangle(comm, [[-HALF_SPAN, 0.0], [HALF_SPAN, ny * h]], [nx, ny],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    soil = fm.MohrCoulomb(E=E, nu=NU, density=RHO, phi=PHI, c=C, psi=PSI)
    pts = fm.Particles.fill(grid, soil, per_cell=3,
                            region=lambda x: (np.abs(x[:, 0]) < W / 2) & (x[:, 1] < H))
    k0_stress(pts, gravity=G, surface=lambda x: np.full(len(x), H))   # K0 = nu / (1 - nu)
    sim = fm.Simulation(grid, pts, fm.Explicit("MUSL"), dt=dt, gravity=(0.0, -G), fbar=fbar,
                        shape=shape)
    sim.add_friction(lambda x: np.abs(x[:, 1]) < 1e-9 * h, mu=MU, normal=(0.0, -1.0))
    return sim, soil


def plot(eps, bounds, lim, t, s, runout, path):
    """eps: the plastic-strain raster over bounds (NaN where empty), shown within lim."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 7), gridspec_kw=dict(height_ratios=(2, 1)))
    sc = ax1.imshow(eps.T, origin="lower", extent=(*bounds[0], *bounds[1]), cmap="viridis",
                    vmin=0.0, vmax=max(np.nanpercentile(eps, 95), 1e-12))
    ax1.plot([-W / 2, -W / 2, W / 2, W / 2], [0, H, H, 0], "k--", lw=0.8, label="initial column")
    ax1.set_xlim(*lim[0])
    ax1.set_ylim(*lim[1])
    ax1.set_aspect("equal")
    ax1.set_xlabel("x [m]")
    ax1.set_ylabel("y [m]")
    ax1.legend(loc="upper right", fontsize=8)
    fig.colorbar(sc, ax=ax1, label=r"plastic deviatoric strain $\varepsilon_d^p$", shrink=0.8)
    ax1.set_title(f"Column collapse (L3) at t = {t[-1]:.2f} s: runout {runout:.2f} m", fontsize=10)
    ax2.plot(t, s, "C0-")
    ax2.set_xlabel("t [s]")
    ax2.set_ylabel("mean speed [m/s]")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/column_collapse", help="output directory")
    parser.add_argument("--quick", action="store_true", help="coarse grid (a few seconds)")
    parser.add_argument("--fbar", action="store_true", help="Simulation(fbar=True) (F-bar)")
    parser.add_argument("--shape", default="auto", help="Simulation shape family (default "
                        "'auto': cpGIMP for Mohr-Coulomb on this grid)")
    args = parser.parse_args(argv)
    h, dt, t_max = (0.8, 2e-3, 2.0) if args.quick else (0.4, 1e-3, 4.0)
    if comm.rank == 0:
        os.makedirs(args.out, exist_ok=True)

    sim, soil = build(h, dt, fbar=args.fbar, shape=args.shape)
    p = sim.particles
    mass0 = comm.allreduce(float(np.sum(p.mass)))
    n0 = p.n_global()
    hist = [(0.0, p.mean_speed())]
    det_min = [np.inf]

    def observe(s):
        hist.append((s.t, s.particles.mean_speed()))
        d = np.linalg.det(s.particles.F[:, :2, :2]) if len(s.particles) else np.array([np.inf])
        det_min[0] = min(det_min[0], comm.allreduce(float(d.min()), op=MPI.MIN))

    sim.observe(observe, every=EVERY)
    t0 = time.perf_counter()
    def extent():
        lo = comm.allreduce(float(p.x[:, 0].min()) if len(p) else np.inf, op=MPI.MIN)
        hi = comm.allreduce(float(p.x[:, 0].max()) if len(p) else -np.inf, op=MPI.MAX)
        return lo, hi

    t_stop = float("nan")
    spread = np.diff(extent())[0]
    while sim.t < t_max - 1e-9:
        sim.run(t_end=min(sim.t + 0.1, t_max))
        new = np.diff(extent())[0]
        s_now = [v for _, v in hist]
        if np.argmax(s_now) < len(s_now) - 1 and 0.5 * (new - spread) < STOP_RUNOUT:
            t_stop = sim.t
            break
        spread = new
    wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)

    mass1 = comm.allreduce(float(np.sum(p.mass)))
    t, s = np.array(hist).T
    k = int(np.argmax(s))
    lo, hi = extent()
    top = comm.allreduce(float(p.x[:, 1].max()) if len(p) else -np.inf, op=MPI.MAX)
    runout_r, runout_l = hi - W / 2, -lo - W / 2
    finite = comm.allreduce(bool(np.all(np.isfinite(p.x)) and np.all(np.isfinite(p.stress))),
                            op=MPI.LAND)
    eps_max = comm.allreduce(float(p.state[:, 0].max()) if len(p) else -np.inf, op=MPI.MAX)
    bounds = ((-HALF_SPAN, HALF_SPAN), (0.0, H + 2 * h))          # the mesh; squares of ~3h/4
    eps = particle_raster(comm, p.x, p.state[:, 0], bounds,
                          raster_shape(bounds, 0.75 * h))
    metrics = dict(h=h, dt=dt, t_end=float(sim.t), steps=sim.step_count, n_particles=n0,
                   n_particles_final=p.n_global(), mass_initial=mass0, mass_final=mass1,
                   runout=0.5 * (runout_l + runout_r), runout_left=runout_l,
                   runout_right=runout_r, height=top, peak_mean_speed=float(s[k]),
                   t_peak=float(t[k]), final_mean_speed=float(s[-1]), t_stop=t_stop,
                   min_det_F=float(det_min[0]), finite=finite, wall_s=wall,
                   mean_speed=dict(t=t.tolist(), v=s.tolist()))
    if comm.rank == 0:
        png = os.path.join(args.out, "column_collapse.png")
        csv = os.path.join(args.out, "mean_speed.csv")
        np.savetxt(csv, np.column_stack([t, s]), delimiter=",", header="t,mean_speed",
                   comments="")
        plot(eps, bounds, ((lo - h, hi + h), (0.0, max(top, H) + h / 2)), t, s,
             metrics["runout"], png)
        m = metrics
        print(f"\nColumn collapse (L3), W x H = {W:g} x {H:g} m, h = {h:g} m, {n0} particles, "
              f"dt = {dt:g} s, {m['steps']} explicit MUSL steps, {comm.size} rank(s), "
              f"{wall:.1f} s wall")
        print(f"{'quantity':<34} {'value':>12}")
        for name, key, fmt in (("runout (mean of both sides) [m]", "runout", ".3f"),
                               ("runout left / right [m]", None, None),
                               ("final height [m]", "height", ".3f"),
                               ("peak mean speed [m/s]", "peak_mean_speed", ".4f"),
                               ("  at t [s]", "t_peak", ".3f"),
                               ("final mean speed [m/s]", "final_mean_speed", ".4f"),
                               ("t_stop (runout stopped) [s]", "t_stop", ".3f"),
                               ("total mass start [kg/m]", "mass_initial", ".6f"),
                               ("total mass end [kg/m]", "mass_final", ".6f"),
                               ("min det F", "min_det_F", ".4f"),
                               ("max plastic dev. strain", None, None)):
            if key is not None:
                print(f"{name:<34} {m[key]:12{fmt}}")
            elif name.startswith("runout"):
                print(f"{name:<34} {runout_l:6.3f} / {runout_r:.3f}")
            else:
                print(f"{name:<34} {eps_max:12.4f}")
        print("mean speed history [t s: m/s]: " + ", ".join(
            f"{ti:.2f}: {si:.3f}" for ti, si in zip(t[::max(1, len(t) // 10)], s[::max(1, len(t) // 10)])))
        print(f"\nplot:        {png}\nmean speed:  {csv}")
        metrics.update(png=png, csv=csv, max_plastic_strain=eps_max)
    return comm.bcast(metrics, root=0)


if __name__ == "__main__":
    main()
