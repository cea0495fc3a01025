"""Robin playground: boundary laws written in a few lines of UFL on the W1 column's base.

    python3 demos/robin_playground.py [--out DIR] [--quick]
    mpirun -n 2 python3 demos/robin_playground.py

fm.Robin(traction, where) takes any traction(u, v, n) -> UFL vector of the boundary
displacement u, velocity v and outward normal n; fenicsmpm assembles it on the facets
where(x) selects (and, for implicit runs, derives its tangent with ufl.derivative). The
W1 column (fenicsmpm.problems.absorbing_column: H = 100 m, E = 20 MPa, nu = 0.25, rho = 1500 kg/m^3,
side rollers, Gaussian surface pulse of 10.07 kPa) stands on each of these bases:

  viscous         Lysmer-Kuhlemeyer:  t = -rho c_p v_n n - rho c_s v_s
  half-absorbing  the same with a = b = 0.5 (an impedance mismatch)
  over-damped     a = b = 2
  nonlinear       a dashpot stiffening with speed: c(v) = rho c_p (1 + |v|^2 / v_ref^2),
                  v_ref = 0.05 m/s (about the pulse's peak velocity)
  Kellezi         viscous plus springs k_n = rho c_p^2 / r_b, k_s = rho c_s^2 / r_b, r_b = H
and, as the reference for total reflection, the fixed base (Dirichlet, not a Robin law).

For a 1D pulse meeting a dashpot a rho c_p the reflected / incident stress ratio is
(a - 1) / (a + 1): -1/3 for a = 0.5 (the reflection is tensile, as from a free end), +1/3 for
a = 2 (compressive, as from a fixed end), 0 for a = 1, 1 for a fixed base. The measured
ratio (largest |sigma_yy| at mid-depth after t0 + H / c_p over the incident peak) is printed
against it; the reflected pulse has travelled 100 m further than the incident one, so the
scheme's dispersion lowers its peak (by ~15 % at dx = 0.5 m, ~5 % at 0.25 m): the ratio over
the fixed base's ratio removes that and is printed too.

Explicit MUSL, dt = "auto" (Courant 0.5); dx = 0.25 m (full) or 0.5 m (--quick), to 1.4 s
(the base's reflection has passed mid-depth by 1.31 s).
Writes DIR/robin_playground.png (default DIR results/robin_playground/): sigma_yy at
mid-depth per law, and the reflection ratios against the 1D theory.
"""
import argparse
import os

import numpy as np
import ufl
from mpi4py import MPI

import fenicsmpm as fm
import fenicsmpm.problems.absorbing_column as W1
from fenicsmpm.problems.absorbing_column import absorbing_column, histories, reflection_ratio

comm = MPI.COMM_WORLD

SOIL = fm.LinearElastic(E=W1.E, nu=W1.NU, density=W1.RHO)
RHO, CP, CS = SOIL.density, SOIL.p_wave_speed, SOIL.s_wave_speed
H = 100.0
V_REF = 0.05


def dashpot(a):
    """Lysmer-Kuhlemeyer dashpots scaled by a."""
    def law(u, v, n):
        vn = ufl.dot(v, n)
        return -a * RHO * CP * vn * n - a * RHO * CS * (v - vn * n)
    return law


def nonlinear_dashpot(u, v, n):
    return -RHO * CP * (1.0 + ufl.dot(v, v) / V_REF ** 2) * v


def kellezi(u, v, n):
    un = ufl.dot(u, n)
    return (dashpot(1.0)(u, v, n)
            - RHO * CP ** 2 / H * un * n - RHO * CS ** 2 / H * (u - un * n))


# name, base (a Robin law, or "fixed"), 1D theory for the reflection ratio |a - 1| / (a + 1)
# (None: no closed form)
LAWS = [
    ("viscous", dashpot(1.0), 0.0),
    ("half-absorbing (a = 0.5)", dashpot(0.5), 1.0 / 3.0),
    ("over-damped (a = 2)", dashpot(2.0), 1.0 / 3.0),
    ("fixed (reference)", "fixed", 1.0),
    ("nonlinear c(v)", nonlinear_dashpot, None),
    ("Kellezi spring + dashpot", kellezi, None),
]


def run_law(name, law, dx, t_end):
    sim, exact = absorbing_column(fm.Explicit("MUSL"), base=law, dx=dx, depths=(50.0,))
    sim.run(t_end=t_end)
    h = histories(exact["probes"][50.0], exact)          # collective
    return dict(name=name, h=h, reflection=reflection_ratio(h, exact), exact=exact)


def plot(runs, theory, path, dx):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(13, 4.8),
                                   gridspec_kw=dict(width_ratios=[1.6, 1.0]))
    for k, r in enumerate(runs):
        ax1.plot(r["h"]["t"], 1e-3 * r["h"]["stress"], lw=1.1, color=f"C{k}", label=r["name"])
    ex = runs[0]["exact"]
    ax1.axvline(W1.split_time(ex), color="k", lw=0.7, ls=":")
    ax1.text(W1.split_time(ex), 0.5, "  incident | reflected", fontsize=8, va="bottom")
    ax1.set_xlabel("time [s]")
    ax1.set_ylabel(r"$\sigma_{yy}$ at mid-depth [kPa]")
    ax1.set_title("stress at mid-depth (50 m)")
    ax1.grid(alpha=0.3)
    ax1.legend(fontsize=8, loc="lower right")
    x = np.arange(len(runs))
    ax2.bar(x, [100 * r["reflection"] for r in runs], 0.6,
            color=[f"C{k}" for k in range(len(runs))], label="measured")
    th = [np.nan if t is None else 100 * t for t in theory]
    ax2.plot(x, th, "k_", ms=30, mew=2, label="1D theory |a - 1| / (a + 1)")
    for xi, r in zip(x, runs):
        ax2.text(xi, 100 * r["reflection"] + 0.5, f"{100 * r['reflection']:.1f} %",
                 ha="center", fontsize=8)
    ax2.set_xticks(x)
    ax2.set_xticklabels([r["name"] for r in runs], rotation=20, ha="right", fontsize=8)
    ax2.set_ylabel("reflection ratio [%]")
    ax2.set_title("reflected / incident |stress| at mid-depth")
    ax2.legend(fontsize=8, loc="upper right")
    fig.suptitle(f"Robin laws in UFL on the W1 column base (dx = {dx} m, explicit MUSL, "
                 f"{comm.size} rank(s))", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/robin_playground", help="output directory")
    parser.add_argument("--quick", action="store_true", help="dx = 0.5 m (a few seconds)")
    args = parser.parse_args(argv)
    dx, t_end = (0.5, 1.4) if args.quick else (0.25, 1.4)
    if comm.rank == 0:
        os.makedirs(args.out, exist_ok=True)
    runs = [run_law(name, law, dx, t_end) for name, law, _ in LAWS]
    theory = [t for _, _, t in LAWS]
    fixed = next(r["reflection"] for r in runs if r["name"].startswith("fixed"))
    png = os.path.join(args.out, "robin_playground.png")
    if comm.rank == 0:
        plot(runs, theory, png, dx)
        print(f"\nRobin laws on the W1 column base, dx = {dx} m, explicit MUSL, to {t_end} s, "
              f"{comm.size} rank(s)")
        print(f"{'law':<26} {'reflection':>10} {'/ fixed':>8} {'1D theory':>10}")
        for r, t in zip(runs, theory):
            print(f"{r['name']:<26} {100 * r['reflection']:9.2f}% "
                  f"{100 * r['reflection'] / fixed:7.2f}% "
                  f"{'-' if t is None else f'{100 * t:.2f}%':>10}")
        print(f"\nplot: {png}")
    return dict(png=png, dx=dx, reflection={r["name"]: r["reflection"] for r in runs},
                over_fixed={r["name"]: r["reflection"] / fixed for r in runs},
                theory={name: t for name, _, t in LAWS})


if __name__ == "__main__":
    main()
