"""W1: a Gaussian pulse down a 100 m soil column on a fixed, a viscous and a viscoelastic base.

    python3 demos/column_pulse.py [--out DIR] [--quick]
    mpirun -n 2 python3 demos/column_pulse.py

BENCHMARKS.md W1 (seed 000 section 4.2.1): H = 100 m, E = 20 MPa, nu = 0.25,
rho = 1500 kg/m^3, side rollers, a surface pressure p(t) = 0.375 / (a sqrt(pi))
exp(-((t - t0) / a)^2) kPa (t0 = 0.05 s, a = 0.021 s: peak 10.07 kPa, impulse 0.375 kPa s).
Bases: fixed (all components), viscous (Lysmer-Kuhlemeyer dashpots, a = b = 1) and
viscoelastic (the dashpots plus Deeks-Randolph springs k = G / (2 r_b), r_b = H), all three
on the mesh boundary (fm.Viscous / fm.Viscoelastic as Robin forms on the base facets).
Explicit MUSL, dt = "auto" (Courant 0.5). Full: dx = 0.25 m, 1 m wide (4 cells, 2x2
particles per cell: 6400 particles), to 2.5 s. --quick: dx = 0.5 m, one cell wide, to 1.6 s.

Exact 1D answers (dashed in the figure): the incident pulse sigma = -p(t - y / c_p) at depth
y, v = sigma / (rho c_p); a fixed base reflects it with the same sign, the free top with the
opposite sign (images); a viscous base absorbs it and leaves the column displaced by
I / (rho c_p) = 1.976 mm. No closed form is drawn for the viscoelastic base (it returns
towards zero with the relaxation time rho c_p / k_n ~ 4.7 s).

Printed and returned: the reflection ratio at mid-depth (largest |sigma_yy| after
t0 + H / c_p over the incident peak), the viscous base's final offset error, the incident
peaks, the arrival error, and the top particle's peak stress (the thesis reports the top
particle ~25 % low when the load is applied through the shape functions).

Writes to DIR (default results/column_pulse/):
    column_pulse.png      sigma_yy, v_y and u_y histories at depths 0, 25, 50, 75, 100 m
                          (rows) for the three bases (columns)
    histories_<base>.csv  the same numbers (t, then stress/velocity/displacement per depth)
"""
import argparse
import os
import time

import numpy as np
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.problems.absorbing_column import absorbing_column, histories, summary

comm = MPI.COMM_WORLD
BASES = ("fixed", "viscous", "viscoelastic")
DEPTHS = (0.0, 25.0, 50.0, 75.0, 100.0)


def exact_history(base, depth, t, exact):
    """1D image solution (stress [Pa], velocity [m/s], displacement [m]) at `depth`, or None
    for the viscoelastic base."""
    if base not in ("fixed", "viscous"):
        return None
    c, rho, H = exact["c_p"], exact["density"], exact["height"]
    p = np.vectorize(exact["load"])
    # (delay, sign of the stress, direction: +1 down-going, -1 up-going)
    waves = [(depth / c, 1.0, 1.0)]
    if base == "fixed":
        waves += [((2 * H - depth) / c, 1.0, -1.0), ((2 * H + depth) / c, -1.0, 1.0),
                  ((4 * H - depth) / c, -1.0, -1.0), ((4 * H + depth) / c, 1.0, 1.0)]
    sigma = sum(-s * p(t - d) for d, s, _ in waves)
    v = sum(-s * g * p(t - d) for d, s, g in waves) / (rho * c)
    u = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    return sigma, v, u


def run_base(base, dx, width, t_end):
    sim, exact = absorbing_column(fm.Explicit("MUSL"), base=base, dx=dx, width=width,
                                  depths=DEPTHS)
    comm.barrier()
    t0 = time.perf_counter()
    sim.run(t_end=t_end)
    wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    hist = {d: histories(pr, exact) for d, pr in exact["probes"].items()}   # collective
    s = summary(sim, exact)
    top = hist[0.0]
    s.update(base=base, wall_s=wall, steps=sim.step_count, dt=sim.dt,
             n_particles=sim.particles.n_global(),
             top_peak_stress=float(np.max(np.abs(top["stress"][top["t"] < 0.2]))))
    return dict(summary=s, hist=hist, exact=exact)


def write_csv(path, hist):
    t = hist[DEPTHS[0]]["t"]
    cols, head = [t], ["t"]
    for d, h in hist.items():
        for f in ("stress", "velocity", "displacement"):
            cols.append(h[f])
            head.append(f"{f}_{d:g}m")
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=",".join(head), comments="")


def plot(runs, path, dx):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [("stress", r"$\sigma_{yy}$ [kPa]", 1e-3), ("velocity", r"$v_y$ [m/s]", 1.0),
            ("displacement", r"$u_y$ [mm]", 1e3)]
    fig, axes = plt.subplots(3, len(runs), figsize=(4.6 * len(runs), 9.0), sharex=True,
                             sharey="row", squeeze=False)
    colors = plt.cm.viridis(np.linspace(0.0, 0.9, len(DEPTHS)))
    for j, r in enumerate(runs):
        s = r["summary"]
        for i, (field, label, scale) in enumerate(rows):
            ax = axes[i, j]
            for d, col in zip(DEPTHS, colors):
                h = r["hist"][d]
                ax.plot(h["t"], scale * h[field], color=col, lw=1.1,
                        label=f"{h['depth']:.1f} m" if i == 0 else None)
                ex = exact_history(s["base"], h["depth"], h["t"], r["exact"])
                if ex is not None:
                    k = [f for f, _, _ in rows].index(field)
                    ax.plot(h["t"], scale * ex[k], color=col, lw=0.7, ls="--")
            ax.grid(alpha=0.3)
            if j == 0:
                ax.set_ylabel(label)
            if i == 2:
                ax.set_xlabel("time [s]")
        title = f"{s['base']} base: reflection {100 * s['reflection']:.1f} %"
        if s["base"] == "viscous":
            title += f"\noffset {1e3 * s['base_displacement']:.3f} mm " \
                     f"(exact {-1e3 * r['exact']['final_offset']:.3f})"
        elif s["base"] == "viscoelastic":
            title += f"\n(Deeks-Randolph, r_b = {r['exact']['spring_length']:g} m)"
        axes[0, j].set_title(title, fontsize=10)
    axes[0, 0].legend(title="depth", fontsize=8, loc="upper left")
    fig.suptitle(f"W1 column, dx = {dx} m, explicit MUSL (Courant 0.5), {comm.size} rank(s); "
                 f"dashed: exact 1D", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/column_pulse", help="output directory")
    parser.add_argument("--quick", action="store_true",
                        help="dx = 0.5 m, one cell wide, to 1.6 s (a few seconds)")
    args = parser.parse_args(argv)
    dx, width, t_end = (0.5, 0.5, 1.6) if args.quick else (0.25, 1.0, 2.5)
    if comm.rank == 0:
        os.makedirs(args.out, exist_ok=True)
    runs = [run_base(b, dx, width, t_end) for b in BASES]

    png = os.path.join(args.out, "column_pulse.png")
    csvs = {r["summary"]["base"]: os.path.join(args.out, f"histories_{r['summary']['base']}.csv")
            for r in runs}
    if comm.rank == 0:
        for r in runs:
            write_csv(csvs[r["summary"]["base"]], r["hist"])
        plot(runs, png, dx)
        ex = runs[0]["exact"]
        print(f"\nW1 column: H = {ex['height']:g} m, dx = {dx} m, width {width} m, "
              f"{runs[0]['summary']['n_particles']} particles, explicit MUSL dt = "
              f"{runs[0]['summary']['dt']:.3g} s, to {t_end} s, {comm.size} rank(s)")
        print(f"c_p = {ex['c_p']:.2f} m/s; exact peak stress {ex['peak_stress'] / 1e3:.2f} kPa, "
              f"peak velocity {ex['peak_velocity']:.4f} m/s, offset {1e3 * ex['final_offset']:.3f}"
              f" mm")
        print(f"{'base':<13} {'reflection':>10} {'peak σ [kPa]':>12} {'peak v [m/s]':>12} "
              f"{'arrival err':>11} {'top σ [kPa]':>11} {'u_base [mm]':>11} {'wall [s]':>8}")
        for r in runs:
            s = r["summary"]
            print(f"{s['base']:<13} {100 * s['reflection']:9.2f}% "
                  f"{s['incident_peak_stress'] / 1e3:12.3f} {s['incident_peak_velocity']:12.4f} "
                  f"{100 * s['arrival_error']:+10.2f}% {s['top_peak_stress'] / 1e3:11.3f} "
                  f"{1e3 * s['base_displacement']:11.4f} {s['wall_s']:8.2f}")
        sv = runs[1]["summary"]
        print(f"viscous base: final offset {1e3 * sv['base_displacement']:.4f} mm vs exact "
              f"{-1e3 * ex['final_offset']:.4f} mm (error {100 * sv['offset_error']:+.2f} %)")
        print(f"top particle peak stress: {runs[1]['summary']['top_peak_stress'] / 1e3:.2f} kPa "
              f"({100 * (runs[1]['summary']['top_peak_stress'] / ex['peak_stress'] - 1):+.1f} % "
              f"of the applied peak; the thesis reports ~-25 %)")
        print(f"\nplot: {png}\ncsv:  {', '.join(csvs.values())}")
    keys = ("reflection", "offset_error", "base_displacement", "incident_peak_stress",
            "incident_peak_velocity", "peak_stress_error", "peak_velocity_error",
            "arrival_error", "top_peak_stress", "wall_s", "steps", "dt")
    out = dict(png=png, csv=csvs, dx=dx, t_end=t_end,
               reflection={r["summary"]["base"]: r["summary"]["reflection"] for r in runs},
               offset_error=runs[1]["summary"]["offset_error"])
    out.update({r["summary"]["base"]: {k: r["summary"][k] for k in keys} for r in runs})
    return out


if __name__ == "__main__":
    main()
