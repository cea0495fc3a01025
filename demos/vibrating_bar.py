"""V1: the axially vibrating elastic bar (BENCHMARKS.md V1), explicit and implicit.

    python3 demos/vibrating_bar.py [--out DIR] [--quick]
    mpirun -n 2 python3 demos/vibrating_bar.py

A bar fixed at x = 0 and free at x = L starts with v = v0 sin(pi x / 2L) and vibrates in its
first mode: v(x, t) = v0 cos(w t) sin(pi x / 2L). It is run for 5 periods with explicit MUSL
(cfl 0.2) and with implicit Newmark (5x the explicit critical step). A probe records the
velocity of the particle nearest the free end; the period is measured from its zero
crossings and the total energy (kinetic + strain) is compared with its initial value.

Writes to DIR (default results/vibrating_bar/):
    vibrating_bar.png                  velocity at the probe and E / E0 vs time
    probe_explicit.csv, probe_implicit.csv
    explicit/particles.pvd, explicit/grid.xdmf   (open in ParaView)
"""
import argparse
import os

import numpy as np
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.problems.elastic import vibrating_bar

comm = MPI.COMM_WORLD


def total_energy(sim):
    e = sim.energy()                      # collective: every rank must call it
    return e["kinetic"] + e["strain"]


def measured_period(t, v):
    """Period from the zero crossings of v(t), located by linear interpolation."""
    i = np.flatnonzero(np.sign(v[:-1]) * np.sign(v[1:]) < 0)
    tc = t[i] - v[i] * (t[i + 1] - t[i]) / (v[i + 1] - v[i])
    return 2.0 * (tc[-1] - tc[0]) / (len(tc) - 1)


def run(name, integrator, out, n_cells, periods, output_every=None):
    sim, exact = vibrating_bar(integrator, n_cells=n_cells)
    L, h = 1.0, exact["h"]
    csv = os.path.join(out, f"probe_{name}.csv")
    probe = sim.probe((L, h / 2), ["velocity", "position"], path=csv)
    output = fm.Output(os.path.join(out, name), every=output_every) if output_every else None

    # Advance in chunks (one per output frame) and sample the energy after each chunk.
    chunk = output_every or 1
    t, E = [sim.t], [total_energy(sim)]
    t_end = periods * exact["period"]
    while sim.t < t_end - 0.5 * sim.dt:
        sim.run(steps=chunk, output=output)
        t.append(sim.t)
        E.append(total_energy(sim))

    d = probe.data()                      # collective; the same arrays on every rank
    x0 = d["position_x"][0]               # the probe particle's initial position
    T = measured_period(d["t"], d["velocity_x"])
    E = np.array(E)
    return dict(name=name, dt=sim.dt, steps=sim.step_count, period=T, exact_period=exact["period"],
                period_error=(T - exact["period"]) / exact["period"],
                energy_drift=(E[-1] - E[0]) / E[0],
                max_energy_error=float(np.max(np.abs(E - E[0])) / E[0]),
                t=d["t"], v=d["velocity_x"], v_exact=lambda s: exact["velocity"](x0, s),
                energy_t=np.array(t), energy=E / E[0], probe_x=x0, probe_csv=csv,
                output=output.pvd if output else None)


def plot(runs, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    s = np.linspace(0.0, runs[0]["t"][-1], 1000)
    ax1.plot(s, runs[0]["v_exact"](s), "k-", lw=1, label="exact")
    for r, style in zip(runs, ["C0-", "C1o"]):
        ax1.plot(r["t"], r["v"], style, ms=3, lw=1.2, label=f"{r['name']} (dt = {r['dt']:.3g} s)")
        ax2.plot(r["energy_t"], r["energy"], style, ms=3, lw=1.2, label=r["name"])
    ax1.set_ylabel(f"velocity at x = {runs[0]['probe_x']:.4g} m  [m/s]")
    ax1.set_title("Vibrating bar (V1): explicit MUSL vs implicit Newmark")
    ax1.legend(loc="upper right", fontsize=8)
    ax2.axhline(1.0, color="k", lw=0.8)
    ax2.set_xlabel("time [s]")
    ax2.set_ylabel("(kinetic + strain) / E0")
    ax2.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/vibrating_bar", help="output directory")
    parser.add_argument("--quick", action="store_true", help="coarse and short (a few seconds)")
    args = parser.parse_args(argv)
    n_cells, periods, every = (20, 1, 100) if args.quick else (20, 5, 20)
    if comm.rank == 0:
        os.makedirs(args.out, exist_ok=True)

    runs = [run("explicit", fm.Explicit("MUSL"), args.out, n_cells, periods, output_every=every),
            run("implicit", fm.Newmark(), args.out, n_cells, periods)]

    png = os.path.join(args.out, "vibrating_bar.png")
    if comm.rank == 0:
        plot(runs, png)
        print(f"\nVibrating bar, {n_cells} cells, {periods} period(s), {comm.size} rank(s); energy "
              f"sampled every {every} explicit steps and every implicit step")
        print(f"{'integrator':<10} {'dt [s]':>9} {'steps':>6} {'period [s]':>11} {'exact [s]':>10} "
              f"{'period err':>11} {'energy drift':>13} {'max |E-E0|/E0':>14}")
        for r in runs:
            print(f"{r['name']:<10} {r['dt']:9.3g} {r['steps']:6d} {r['period']:11.5f} "
                  f"{r['exact_period']:10.5f} {100 * r['period_error']:+10.3f}% "
                  f"{100 * r['energy_drift']:+12.3f}% {100 * r['max_energy_error']:13.3f}%")
        print(f"\nplot:      {png}")
        print(f"probes:    {runs[0]['probe_csv']}, {runs[1]['probe_csv']}")
        print(f"ParaView:  {runs[0]['output']} (particles), "
              f"{os.path.join(args.out, 'explicit', 'grid.xdmf')} (grid)")
    keys = ("dt", "steps", "period", "exact_period", "period_error", "energy_drift",
            "max_energy_error", "probe_csv")
    return dict(png=png, **{r["name"]: {k: r[k] for k in keys} for r in runs})


if __name__ == "__main__":
    main()
