"""L4: failure of a Mohr-Coulomb slope, with strength reduction (seed 002 section 5.2).

    python3 demos/slope_failure.py [--out DIR] [--quick]
    mpirun -n 2 python3 demos/slope_failure.py

BENCHMARKS.md L4: rho = 2000 kg/m^3, E = 40 MPa, nu = 0.42, psi = 0, 3 x 3 particles per
cell, a 50 x 27 grid of square cells (--quick: 20 x 11), plane strain, g = 9.81 m/s^2.
The seed's Fig. 5.6 gives the slope's shape but no dimensions in its text; this demo's slope
(chosen so that the 50 x 27 grid holds it as in the seed's Fig. 5.7): a 200 m x 108 m domain,
a base layer 40 m thick, on it a slope 60 m high at 1V:1.5H (33.7 deg) facing left, toe at
x = 50 m, crest at x = 140 m, plateau to x = 200 m. Rollers on the sides (u_x = 0) and the
base (u_y = 0), as in the seed.

Strength reduction: for a factor F, the soil is fm.MohrCoulomb(phi = 18 deg, c = 5 kPa)
.reduced(F): tan(phi) / F and c / F (F < 1 strengthens it). Each run is explicit MUSL from a
stress-free state with gravity ramped in over T_ramp (Simulation(gravity_ramp=2 T_ramp),
seed 002 eq 4.13, full gravity from t = T_ramp on), then held to t_end = T_ramp + T_hold.

Failure criterion (stated): the slope fails at F when its crest keeps moving under full
gravity: the displacement of the crest particle (the particle nearest (x_crest, top)) during
the hold, |u(t_end) - u(T_ramp)|, exceeds U_FAIL = 0.5 m. A stable slope only vibrates
elastically about its settled state during the hold (the ramp leaves it settled by ~1.4 m,
elastically: E = 40 MPa under 100 m of soil), a failing one slides on by metres. The
mass-weighted mean speed v = sum |v_p| m_p / sum m_p (seed 002 eq 5.12) is reported and
plotted alongside; it is not the criterion, because a failed slope can come to rest again
and the elastic vibration left by the ramp keeps a stable slope's mean speed at a few cm/s.

Procedure: F = 1 (the unreduced phi = 18 deg, c = 5 kPa slope) is run and its state reported;
then the factor of safety F_s (the F at which the slope just fails) is bracketed by
bisection: on [F_LO, 1] if the unreduced slope fails (F_LO = 0.25, --quick 0.5; checked
stable first), on [1, F_HI = 2] otherwise, down to a bracket width of 0.05 (--quick: 0.25,
that is one bisection step).

Reference: Bishop's simplified limit equilibrium over circular slip surfaces
(fenicsmpm.problems.slope_stability.bishop) gives F = 0.598 for this slope. Measured
(serial, 50 x 27 cells): the defaults (cpGIMP for Mohr-Coulomb since 2026-12-06) stable
at 0.625 (crest motion in the hold 0.19 m), fail at 0.672 (4.6 m), 95.6 s wall; the standard
family (--shape mpm, the default before) stable at F = 0.531, fails at 0.578
(docs/measured.md).

Printed and returned:
  unreduced       failed or not at F = 1, its final mean speed and crest displacement,
  bracket         (F_stable, F_failed) with F_stable < F_s <= F_failed, and every run's
                  (F, failed, mean speed over the last quarter of the hold, crest |u|).

Writes to DIR (default results/slope_failure/):
    slope_failure.png   the unreduced slope's final state: a raster of the mean plastic
                        deviatoric strain (MohrCoulomb state column 0) per square of h / 2
                        (fenicsmpm.io.particle_raster), and the mean-speed histories of
                        every run
"""
import argparse
import math
import os
import time

import numpy as np
from mpi4py import MPI
from dolfinx import mesh as dmesh

import fenicsmpm as fm
from fenicsmpm.problems.slope_stability import bishop
from fenicsmpm.io import particle_raster

comm = MPI.COMM_WORLD
RHO, E, NU, PSI = 2000.0, 40.0e6, 0.42, 0.0
PHI, C = 18.0, 5.0e3
G = 9.81
L, HEIGHT = 200.0, 108.0          # domain [m]
BASE, SLOPE_H, RUN = 40.0, 60.0, 90.0
X_TOE = 50.0
X_CREST = X_TOE + RUN
U_FAIL = 0.5                      # [m] failure: crest displacement during the hold above this
F_LO, F_HI = 0.25, 2.0


def surface(x):
    """Height of the ground surface at x."""
    return BASE + SLOPE_H * np.clip((x - X_TOE) / RUN, 0.0, 1.0)


def build(factor, cells, dt_cfl=0.5, t_ramp=8.0, fbar=False, shape="auto"):
    """The slope at strength-reduction factor `factor` on a grid of `cells` = (nx, ny)."""
    nx, ny = cells
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [L, HEIGHT]], [nx, ny],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    soil = fm.MohrCoulomb(E=E, nu=NU, density=RHO, phi=PHI, c=C, psi=PSI).reduced(factor)
    pts = fm.Particles.fill(grid, soil, per_cell=3, region=lambda x: x[:, 1] < surface(x[:, 0]))
    sim = fm.Simulation(grid, pts, fm.Explicit("MUSL"), dt="auto", cfl=dt_cfl,
                        gravity=(0.0, -G), gravity_ramp=2.0 * t_ramp, fbar=fbar,
                        shape=shape)
    tol = 1e-6 * L
    sim.fix(lambda x: (np.abs(x[:, 0]) < tol) | (np.abs(x[:, 0] - L) < tol), [0])
    sim.fix(lambda x: np.abs(x[:, 1]) < tol, [1])
    return sim, soil


def run_factor(factor, cells, t_ramp, t_hold, keep=False, fbar=False, shape="auto"):
    """One strength-reduction run. Returns a dict (same on every rank)."""
    sim, soil = build(factor, cells, t_ramp=t_ramp, fbar=fbar, shape=shape)
    crest = sim.probe((X_CREST, BASE + SLOPE_H), ["displacement"])
    hist = [(0.0, 0.0)]
    sim.observe(lambda s: hist.append((s.t, s.particles.mean_speed())), every=5)
    t0 = time.perf_counter()
    sim.run(t_end=t_ramp + t_hold)
    wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    t, v = np.array(hist).T
    tail = t >= t_ramp + 0.75 * t_hold
    v_tail = float(v[tail].mean())
    d = crest.data()
    ux, uy = d["displacement_x"], d["displacement_y"]
    k = int(np.argmin(np.abs(d["t"] - t_ramp)))
    u_crest = float(np.hypot(ux[-1], uy[-1]))
    u_hold = float(np.hypot(ux[-1] - ux[k], uy[-1] - uy[k]))
    out = dict(factor=float(factor), phi=soil.phi, c=soil.c, failed=bool(u_hold > U_FAIL),
               crest_u_hold=u_hold,
               mean_speed_tail=v_tail, mean_speed_final=float(v[-1]), crest_u=u_crest,
               steps=sim.step_count, dt=sim.dt, n_particles=sim.particles.n_global(),
               wall_s=wall, t=t, v=v)
    if keep:       # the plastic strain raster (rank 0; None elsewhere): squares of h / 2
        p = sim.particles
        out["eps"] = particle_raster(comm, p.x, p.state[:, 0], ((0.0, L), (0.0, HEIGHT)),
                                     (2 * cells[0], 2 * cells[1]))
    return out


def plot(base, runs, bracket, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 8), gridspec_kw=dict(height_ratios=(3, 2)))
    eps = base["eps"]
    sc = ax1.imshow(eps.T, origin="lower", extent=(0.0, L, 0.0, HEIGHT), cmap="viridis",
                    vmin=0.0, vmax=max(np.nanpercentile(eps, 98), 1e-12))
    xs = np.linspace(0.0, L, 200)
    ax1.plot(xs, surface(xs), "k--", lw=0.8, label="initial surface")
    ax1.set_aspect("equal")
    ax1.set_xlim(0, L)
    ax1.set_ylim(0, HEIGHT)
    ax1.set_xlabel("x [m]")
    ax1.set_ylabel("y [m]")
    ax1.legend(loc="upper left", fontsize=8)
    fig.colorbar(sc, ax=ax1, label=r"plastic deviatoric strain $\varepsilon_d^p$", shrink=0.7)
    ax1.set_title(f"phi = {PHI:g} deg, c = {C / 1e3:g} kPa (F = 1) at t = {base['t'][-1]:.1f} s: "
                  f"{'failed' if base['failed'] else 'stable'}, crest |u| = {base['crest_u']:.2f} m",
                  fontsize=10)
    for r in sorted(runs, key=lambda r: r["factor"]):
        ax2.semilogy(r["t"], np.maximum(r["v"], 1e-6), "-" if r["failed"] else "--",
                     label=f"F = {r['factor']:.3f} ({'fails' if r['failed'] else 'stable'})")
    ax2.set_xlabel("t [s]")
    ax2.set_ylabel("mean speed [m/s]")
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=7, ncol=2)
    ax2.set_title(f"strength reduction: stable at F = {bracket[0]:.3f}, fails at F = {bracket[1]:.3f}",
                  fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/slope_failure", help="output directory")
    parser.add_argument("--quick", action="store_true", help="coarse grid, wide bracket")
    parser.add_argument("--fbar", action="store_true", help="Simulation(fbar=True) (F-bar)")
    parser.add_argument("--shape", default="auto", help="Simulation shape family (default "
                        "'auto': cpGIMP for Mohr-Coulomb on this grid)")
    args = parser.parse_args(argv)
    if args.quick:
        cells, t_ramp, t_hold, f_lo, tol = (20, 11), 6.0, 6.0, 0.5, 0.25
    else:
        cells, t_ramp, t_hold, f_lo, tol = (50, 27), 8.0, 8.0, F_LO, 0.05
    if comm.rank == 0:
        os.makedirs(args.out, exist_ok=True)
    t0 = time.perf_counter()
    base = run_factor(1.0, cells, t_ramp, t_hold, keep=True, fbar=args.fbar, shape=args.shape)
    runs = [base]
    if base["failed"]:                   # F_s < 1: bracket it in [f_lo, 1]
        lo_run = run_factor(f_lo, cells, t_ramp, t_hold, fbar=args.fbar, shape=args.shape)
        runs.append(lo_run)
        lo, hi, ok = f_lo, 1.0, not lo_run["failed"]
    else:                                # F_s > 1: bracket it in [1, F_HI]
        hi_run = run_factor(F_HI, cells, t_ramp, t_hold, fbar=args.fbar, shape=args.shape)
        runs.append(hi_run)
        lo, hi, ok = 1.0, F_HI, hi_run["failed"]
    while ok and hi - lo > tol + 1e-12:
        mid = 0.5 * (lo + hi)
        r = run_factor(mid, cells, t_ramp, t_hold, fbar=args.fbar, shape=args.shape)
        runs.append(r)
        if r["failed"]:
            hi = mid
        else:
            lo = mid
    wall = time.perf_counter() - t0
    strip = lambda r: {k: v for k, v in r.items() if k not in ("t", "v", "eps")}
    metrics = dict(cells=list(cells), t_ramp=t_ramp, t_hold=t_hold, u_fail=U_FAIL,
                   bracket=(lo, hi) if ok else None, bracket_valid=bool(ok),
                   unreduced=strip(base), runs=[strip(r) for r in runs],
                   factor_of_safety=0.5 * (lo + hi) if ok else float("nan"), wall_s=wall)
    if comm.rank == 0:
        bishop_factor = bishop(surface, RHO * G, C, PHI, (0.0, L))["factor"]
        metrics["bishop_factor"] = bishop_factor
        png = os.path.join(args.out, "slope_failure.png")
        plot(base, runs, (lo, hi), png)
        print(f"\nSlope failure (L4), {cells[0]} x {cells[1]} cells, {base['n_particles']} particles, "
              f"dt = {base['dt']:.4g} s, ramp {t_ramp:g} s + hold {t_hold:g} s, {comm.size} rank(s), "
              f"{wall:.1f} s wall")
        print(f"failure criterion: crest displacement during the hold > {U_FAIL} m")
        print(f"{'F':>7} {'phi [deg]':>10} {'c [kPa]':>8} {'mean speed [m/s]':>17} "
              f"{'crest |u| [m]':>14} {'during hold [m]':>16}  result")
        for r in sorted(runs, key=lambda r: r["factor"]):
            print(f"{r['factor']:7.4f} {r['phi']:10.3f} {r['c'] / 1e3:8.3f} {r['mean_speed_tail']:17.4f} "
                  f"{r['crest_u']:14.3f} {r['crest_u_hold']:16.3f}  {'FAILS' if r['failed'] else 'stable'}")
        print(f"\nunreduced slope (phi = {PHI:g} deg, c = {C / 1e3:g} kPa): "
              f"{'FAILS' if base['failed'] else 'stable'} (mean speed {base['mean_speed_tail']:.3f} m/s, "
              f"crest |u| = {base['crest_u']:.2f} m)")
        if ok:
            print(f"factor of safety: stable at F = {lo:.4f}, fails at F = {hi:.4f} "
                  f"(F_s ~ {0.5 * (lo + hi):.3f})")
        else:
            print(f"no bracket: both ends of the interval {'fail' if base['failed'] else 'are stable'}")
        print(f"reference: Bishop's simplified method (circular slip surfaces, "
              f"fenicsmpm.problems.slope_stability): F = {bishop_factor:.3f}")
        print(f"\nplot: {png}")
        metrics["png"] = png
    return comm.bcast(metrics, root=0)


if __name__ == "__main__":
    main()
