"""C1: a cylinder on an incline (BENCHMARKS.md C1, seed 004 §2.6.9), contact between bodies.

    python3 demos/cylinder_incline.py [--out DIR] [--quick]
    mpirun -n 2 python3 demos/cylinder_incline.py

A neo-Hookean cylinder (R = 1.6 m, K = 6 MPa, G = 3 MPa, rho = 1000 kg/m^3) rests on a
deformable plane 0.8 m thick and 10x stiffer; the incline is tilted through gravity
(g = 10 m/s^2 at theta from the plane's normal). Two cases:
    rolling   theta = 45 deg, mu = 0.495:  x(t) = (5 sqrt 2 / 3) t^2   (rolls without slip)
    slipping  theta = 60 deg, mu = 2/7:    x(t) = (5/2)(sqrt 3 - 2/7) t^2
The centre displacement (mass-weighted mean of the cylinder's particles) is plotted against
the rigid-cylinder x(t) for:
    multi-velocity        fm.ExplicitContact (seed 004 eqs 2.34-2.39, with the gap check),
    multi-velocity-nogap  the same without the gap check (the seed's plain algorithm),
    penalty               fm.ExplicitContact(algorithm="penalty"): node-to-segment penalty
                          contact between the cylinder's circle and the plane's top edge
                          (seed 004 eqs 2.40-2.53; polylines of 0.1 m segments),
    single-field          fm.Explicit: one velocity field, the cylinder is glued to the plane.
Scene: fenicsmpm.bench.contact.incline; grid h = 0.4 m (the benchmark's), and also
h = 0.2 m unless --quick.

Writes to DIR (default results/cylinder_incline/):
    cylinder_incline.png      centre displacement vs time, both cases, every algorithm
    cylinder_incline.csv      t and x(t) of every run
"""
import argparse
import os

import numpy as np
from mpi4py import MPI

from fenicsmpm.bench.contact import ALGORITHMS, CASES, exact_x, incline

comm = MPI.COMM_WORLD


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/cylinder_incline", help="output directory")
    parser.add_argument("--quick", action="store_true", help="h = 0.4 m only (seconds)")
    args = parser.parse_args()
    cells = (0.4,) if args.quick else (0.4, 0.2)
    runs = {}
    for case, (theta, mu) in CASES.items():
        for alg in ALGORITHMS:
            for h in cells:
                r = incline(theta, mu, alg, h=h, t_end=1.0)
                runs[(case, alg, h)] = r
                if comm.rank == 0:
                    print(f"{case:8s} {alg:21s} h = {h:g}: x(1 s) = {r['x_end']:.4f} m, exact "
                          f"{r['x_exact']:.4f} m, error {r['error']:+.2%}, wall {r['wall_s']:.1f} s",
                          flush=True)
    if comm.rank != 0:
        return
    os.makedirs(args.out, exist_ok=True)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    colors = {"multi-velocity": "tab:blue", "multi-velocity-nogap": "tab:green",
              "penalty": "tab:purple", "single-field": "tab:red"}
    styles = {0.4: "-", 0.2: "--"}
    cols, data = [], []
    for ax, (case, (theta, mu)) in zip(axes, CASES.items()):
        t = np.linspace(0.0, 1.0, 101)
        ax.plot(t, exact_x(theta, mu, t), "k:", lw=2, label="rigid cylinder (exact)")
        for alg in ALGORITHMS:
            for h in cells:
                r = runs[(case, alg, h)]
                ax.plot(r["t"], r["x"], styles[h], color=colors[alg],
                        label=f"{alg}, h = {h:g} m ({r['error']:+.1%})")
                cols += [f"{case}_{alg}_h{h:g}_t", f"{case}_{alg}_h{h:g}_x"]
                data += [r["t"], r["x"]]
        ax.set_title(f"{case}: theta = {theta:g} deg, mu = {mu:.3g}")
        ax.set_xlabel("t [s]")
        ax.set_ylabel("centre displacement along the incline [m]")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, "cylinder_incline.png"), dpi=120)
    n = max(len(a) for a in data)
    table = np.full((n, len(data)), np.nan)
    for j, a in enumerate(data):
        table[: len(a), j] = a
    np.savetxt(os.path.join(args.out, "cylinder_incline.csv"), table, delimiter=",",
               header=",".join(cols), comments="")
    print(f"wrote {os.path.join(args.out, 'cylinder_incline.png')}")


if __name__ == "__main__":
    main()
