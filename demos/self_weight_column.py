"""V2 (small strain): an elastic column settling under its own weight, quasi-static.

    python3 demos/self_weight_column.py [--out DIR] [--quick]
    mpirun -n 2 python3 demos/self_weight_column.py

A column of height H = 10 m, one cell wide, rollers on the sides and the base, with gravity
ramped over 10 quasi-static load steps (Newton + PETSc KSP). Exact (linear elasticity):
    sigma_yy(y) = -rho g (H - y),   u_y(y) = -rho g (H y - y^2 / 2) / M,
so the top settles rho g H^2 / (2 M). Particles are compared at their initial height y0.

Writes to DIR (default results/self_weight_column/):
    self_weight_column.png     sigma_yy(y0) and u_y(y0): the mean of each particle row
                               (fenicsmpm.io.particle_profile) vs exact
    probe_top.csv              displacement and stress of the top particle per load step
    output/particles.pvd       particles (VTU) and output/grid.xdmf, for ParaView
"""
import argparse
import os

import numpy as np
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.io import particle_profile
from fenicsmpm.problems.elastic import self_weight_column

comm = MPI.COMM_WORLD
H = 10.0          # column height (the builder's default)


def total(a):
    """Sum over all particles of all ranks."""
    return comm.allreduce(float(np.sum(a)))


def plot(y0, syy, uy, exact, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    y = np.linspace(0.0, H, 200)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 5), sharey=True)
    ax1.plot(exact["stress_yy"](y) / 1e3, y, "k-", lw=1, label="exact")
    ax1.plot(syy / 1e3, y0, "C0o", ms=4, label="particle rows")
    ax1.set_xlabel(r"$\sigma_{yy}$ [kPa]")
    ax1.set_ylabel("initial height y0 [m]")
    ax2.plot(exact["displacement_y"](y) * 1e3, y, "k-", lw=1, label="exact")
    ax2.plot(uy * 1e3, y0, "C0o", ms=4, label="particle rows")
    ax2.set_xlabel(r"$u_y$ [mm]")
    for ax, where in ((ax1, "upper left"), (ax2, "lower left")):
        ax.grid(alpha=0.3)
        ax.legend(loc=where, fontsize=8)
    fig.suptitle("Elastic column under self-weight (V2, small strain, quasi-static)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/self_weight_column", help="output directory")
    parser.add_argument("--quick", action="store_true", help="coarse mesh (a few seconds)")
    args = parser.parse_args(argv)
    n_cells, load_steps = (10, 10) if args.quick else (40, 10)
    if comm.rank == 0:
        os.makedirs(args.out, exist_ok=True)

    integrator = fm.QuasiStatic(load_steps=load_steps)
    sim, exact = self_weight_column(integrator, n_cells=n_cells, height=H)
    h = exact["h"]
    csv = os.path.join(args.out, "probe_top.csv")
    sim.probe((h / 2, H), ["displacement", "stress"], path=csv)
    sim.run(steps=load_steps, output=fm.Output(os.path.join(args.out, "output"), every=1))

    p = sim.particles
    y0, syy, uy, V0 = (p.x - p.u)[:, 1], p.stress[:, 1, 1], p.u[:, 1], p.V0
    # Q1 elements give a constant stress per cell row, exact at the row centre. Mid-depth
    # y = H/2 is a node, so interpolate linearly between the particle rows either side.
    below = comm.allreduce(float(y0[y0 <= H / 2].max()) if np.any(y0 <= H / 2) else -np.inf,
                           op=MPI.MAX)
    above = comm.allreduce(float(y0[y0 > H / 2].min()) if np.any(y0 > H / 2) else np.inf,
                           op=MPI.MIN)
    s_rows = [total(syy[y0 == r]) / total(y0 == r) for r in (below, above)]
    s_mid, s_mid_exact = np.interp(H / 2, [below, above], s_rows), exact["stress_yy"](H / 2)
    # u_y is linear within the top cell: extrapolate its particles to the top, y = H (the
    # least-squares line through them, from sums over the ranks).
    top = y0 > H - h
    n_top = total(top)
    y_mean, u_mean = total(y0[top]) / n_top, total(uy[top]) / n_top
    slope = total((y0[top] - y_mean) * (uy[top] - u_mean)) / total((y0[top] - y_mean) ** 2)
    settlement = -(u_mean + slope * (H - y_mean))
    # AMPLE's stress error norm (BENCHMARKS.md V2): sum |s_p - s(Y_p)| V0_p / (rho g H V0)
    norm = total(np.abs(syy - exact["stress_yy"](y0)) * V0) / (-exact["stress_yy"](0.0) * total(V0))
    # the plot: the mean of each particle row (per_cell = 2 rows per cell, bins centred on them)
    n_rows = 2 * n_cells
    rows = [particle_profile(comm, y0, f, (0.0, H), n_rows) for f in (syy, uy)]
    metrics = None
    if comm.rank == 0:
        metrics = dict(stress_mid=s_mid, stress_mid_exact=s_mid_exact,
                       stress_error=abs(s_mid - s_mid_exact) / abs(s_mid_exact),
                       settlement=settlement, settlement_exact=exact["top_settlement"],
                       settlement_error=abs(settlement / exact["top_settlement"] - 1.0),
                       stress_error_norm=norm, newton_iterations=list(integrator.iterations))
        png = os.path.join(args.out, "self_weight_column.png")
        plot((np.arange(n_rows) + 0.5) * H / n_rows, *rows, exact, png)
        m = metrics
        print(f"\nSelf-weight column, {n_cells} cells, {load_steps} load steps, {comm.size} rank(s); "
              f"Newton iterations per step: {m['newton_iterations']}")
        print(f"{'quantity':<28} {'numerical':>12} {'exact':>12} {'error':>9}")
        print(f"{'sigma_yy at y = H/2 [Pa]':<28} {s_mid:12.2f} {s_mid_exact:12.2f} "
              f"{100 * m['stress_error']:8.3f}%")
        print(f"{'top settlement [m]':<28} {settlement:12.6f} {exact['top_settlement']:12.6f} "
              f"{100 * m['settlement_error']:8.3f}%")
        print(f"{'stress error norm (AMPLE)':<28} {norm:12.3e}")
        print(f"\nplot:      {png}\nprobe:     {csv}\n"
              f"ParaView:  {os.path.join(args.out, 'output', 'particles.pvd')} (particles), "
              f"{os.path.join(args.out, 'output', 'grid.xdmf')} (grid)")
        metrics.update(png=png, probe_csv=csv)
    return comm.bcast(metrics, root=0)


if __name__ == "__main__":
    main()
