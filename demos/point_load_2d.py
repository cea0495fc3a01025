"""W4: a 2D plane-strain half model under a line load, with a fixed box, a viscous and a
viscoelastic far-field boundary.

    python3 demos/point_load_2d.py [--out DIR] [--quick]
    mpirun -n 2 python3 demos/point_load_2d.py

BENCHMARKS.md W4 (seed 000 section 4.3): a 4 m x 4 m symmetric half model, dx = 0.05 m
(--quick: 0.2 m), 2x2 particles per cell, E = 20 MPa, nu = 0.25, unit weight 15 kN/m^3
(rho = 15e3 / 9.81 = 1529 kg/m^3), implicit Newmark (beta = 1/4, gamma = 1/2) with
dt = 0.01 s, run to 1.0 s.

Load: a line load P(t) = 300 kN/m * sin^2(pi t / 0.5 s) for 0 <= t <= 0.5 s (zero after;
peak at t = 0.25 s, impulse 75 kN s/m), shared equally by the top-row particles within
b = 0.2 m of the symmetry axis (2 particles in --quick, 8 at dx = 0.05 m; equivalent to a
pressure P / b, 1.5 MPa at the peak) and passed to the grid through their shape functions
(`sim.add_particle_load`; the thesis also applies its point load "to the top 2 material points"
of an element). It is not a facet traction (fm's sim.add_traction) because those act on
fixed mesh facets: at dx = 0.05 m the loaded particles sink out of the top cell row by
t ~ 0.15 s, the loaded nodes lose their mass, the load is dropped, particles invert and
Newton stops at t = 0.17 s. The same physical strip b is used in both modes, so their
numbers are comparable. The thesis's pulse shape is not given in its text (only "peaking
at t = 0.25 s", displacements already at 0.15 s, the load over by 1.0 s) and it loads one
element (b = dx = 0.05 m): the displacement right under a line load depends on the loaded
width (logarithmically), so our numbers are not expected to match the thesis's closely.

Boundaries: the left side x = 0 has rollers (symmetry) in every case.
  fixed         bottom fully fixed, right side rollers (as in the thesis's fixed model); the
                mesh is the 4 m x 4 m material,
  viscous       fm.Viscous (Lysmer-Kuhlemeyer, a = b = 1),
  viscoelastic  fm.Viscoelastic (the dashpots plus Deeks-Randolph springs
                k_n = k_s = G / (2 r_b), r_b = 4 m: the distance from the load to the
                bottom and to the right side),
the absorbing laws as particle layers (fm.ParticleLayer, like the thesis's method 4 for W4,
with the run's shape functions: cpGIMP by default) on the bottom particle row (normal (0, -1)) and
the right particle column (normal (1, 0); the corner particle belongs to the right layer
only), on a mesh extending 0.2 m below and right of the material. Mesh-boundary dashpots
(fm.Viscous on the facets of a mesh ending at the material) cannot run this case: a viscous
far field lets the whole model sink (0.07 m at 1.0 s) and the bottom particles leave the
mesh (at t = 0.27 s in --quick, 0.16 s at dx = 0.05 m).

Gravity is not applied. The material is linear elastic, so a geostatic stage followed by a
dynamic stage with sigma_ini (sim.start_stage(..., gravity=(0, 0))) gives the same dynamic
response (superposition; only the Jaumann rotation terms of order |sigma_ini| * rotation
differ), and the thesis's displacements are measured from the geostatic state. All stresses
reported are therefore dynamic stress increments.

Printed and returned per boundary:
  u_max_025      largest |u| over all particles at t = 0.25 s (the thesis: viscous 0.13 m,
                 viscoelastic 0.11 m, fixed 0.09 m),
  u_load_025     vertical displacement of the loaded surface particle at x ~ 0 at 0.25 s,
  u_load_100     the same at t = 1.0 s ("permanent"; the thesis: viscous ~0.06 m left,
                 viscoelastic back to ~0),
  sigma_bottom   the largest |sigma_yy| over the time history of the particle nearest
                 (0, 0.25 m) (below the load, near the bottom boundary; not the lowest row:
                 in the absorbing runs the layer particles sink into the empty cells below
                 the material, where a particle alone in its cell carries ~no stress), and
                 sigma_bottom_row the largest over its whole row of particles;
                 bottom_ratio = fixed / absorbing of sigma_bottom (the thesis: ~3),
  energy_balance (kinetic + strain - work of the load - work of the far field) at 1.0 s
                 over the largest work of the load (sim.monitor_energy's balance_error): the
                 energy the discretisation lost.
                 At dx = 0.05 m with the default cpGIMP: fixed -0.57 %, viscous -0.62 %,
                 viscoelastic +1.28 %; with the standard family (--shape mpm) -9.8 / -5.6 /
                 -4.5 %, lost where particles cross cells. Wall time (2026-12-05, one
                 process): 10.8 / 12.7 / 12.1 s with cpGIMP, 8.7 / 9.6 / 9.8 s standard.

Writes to DIR (default results/point_load_2d/):
    point_load_2d.png   |u| at 0.25 s and 1.0 s (rows) for the three boundaries (columns,
                        deformation x 5) as rasters (fenicsmpm.io.particle_raster: the mean
                        |u| per square of 3 dx / 4 at the magnified deformed positions), and
                        the histories of u_y under the load and of sigma_yy at the bottom
                        below the load
    histories.csv       t, u_y under the load and sigma_yy at the bottom, per boundary
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

comm = MPI.COMM_WORLD
BASES = ("fixed", "viscous", "viscoelastic")
L = 4.0                       # domain size [m]
E, NU = 20.0e6, 0.25
RHO = 15.0e3 / 9.81           # unit weight 15 kN/m^3
P_PEAK = 300.0e3              # line load [N/m]
T_LOAD = 0.5                  # sin^2 pulse duration [s] (peak at T_LOAD / 2)
WIDTH = 0.2                   # loaded strip next to the symmetry axis [m]
DT = 0.01
MARGIN = 0.2                  # mesh beyond the material for absorbing runs [m]
BOTTOM_Y = 0.25               # "bottom boundary" stress: the particle row nearest this height
R_B = 4.0                     # Deeks-Randolph r_b: load to bottom / right side
SNAPSHOTS = (0.25, 1.0)
MAG = 5.0                     # deformation magnification of the |u| snapshots
PLOT = ((0.0, L + 0.6), (-0.6, L + 0.1))      # the snapshot rasters' rectangle (x >= 0: rollers)
THESIS = dict(u_max_025=dict(fixed=0.09, viscous=0.13, viscoelastic=0.11),
              u_load_100=dict(viscous=0.06, viscoelastic=0.0), bottom_ratio=3.0)


def line_load(t):
    """P(t) [N/m]: 300 kN/m * sin^2(pi t / T_LOAD) on 0 <= t <= T_LOAD."""
    return P_PEAK * math.sin(math.pi * t / T_LOAD) ** 2 if 0.0 <= t <= T_LOAD else 0.0


def build(base, dx, shape="auto"):
    """The W4 scene for one boundary type (shape: the Simulation's shape family). Returns
    (sim, info)."""
    n = int(round(L / dx))
    # absorbing runs: the mesh extends MARGIN beyond the material at the bottom and on the
    # right, so the material can drift out of [0, L]^2 (a viscous far field lets it) without
    # leaving the mesh; the law then acts on a layer of particles, not on mesh facets
    m = 0 if base == "fixed" else int(math.ceil(MARGIN / dx - 1e-9))
    msh = dmesh.create_rectangle(comm, [[0.0, -m * dx], [L + m * dx, L]], [n + m, n + m],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=E, nu=NU, density=RHO)
    pts = fm.Particles.fill(grid, mat, per_cell=2,
                            region=lambda x: (x[:, 0] < L) & (x[:, 1] > 0.0))
    sim = fm.Simulation(grid, pts, fm.Newmark(), dt=DT, shape=shape)
    tol = 1e-6 * dx
    left = lambda x: np.abs(x[:, 0]) < tol
    right = lambda x: np.abs(x[:, 0] - L) < tol
    bottom = lambda x: np.abs(x[:, 1]) < tol
    sim.fix(left, [0])
    # the load follows the material: shared by the top particles near the axis (a facet
    # traction is lost once they sink out of the top cell row)
    n_loaded = sim.add_particle_load(region=lambda x: (x[:, 1] > L - 0.5 * dx) & (x[:, 0] < WIDTH),
                                     value=lambda t: (0.0, -line_load(t)))
    if base == "fixed":
        sim.fix(bottom)
        sim.fix(right, [0])
    else:
        law = (lambda: fm.Viscous()) if base == "viscous" else (lambda: fm.Viscoelastic(r_b=R_B))
        # the outermost particle row / column (particles sit at dx/4 from the cell edges);
        # the corner particle is in the right-side layer only (a particle carries one layer)
        sim.add_boundary(fm.ParticleLayer(law(), normal=(0.0, -1.0),
                                          region=lambda x: (x[:, 1] < 0.5 * dx) & (x[:, 0] < L - 0.5 * dx)))
        sim.add_boundary(fm.ParticleLayer(law(), region=lambda x: x[:, 0] > L - 0.5 * dx,
                                          normal=(1.0, 0.0)))
    # probes by initial position: the surface particle under the load, the bottom particle
    # below it
    top = sim.probe((0.0, L), ["displacement"])
    bot = sim.probe((0.0, BOTTOM_Y), ["stress"])
    p = sim.particles
    info = dict(top=top, bottom=bot, snapshots={}, row_peak=[0.0], n_loaded=n_loaded)
    # the particle row nearest BOTTOM_Y (the same particles in every run)
    y = p.x[:, 1]
    near = np.min(np.abs(y - BOTTOM_Y)) if len(p) else np.inf
    near = comm.allreduce(near, op=MPI.MIN)
    bottom_row = np.abs(np.abs(y - BOTTOM_Y) - near) < 1e-9 * L
    # every rank holds the ids of this one particle row (they may migrate): bounded by the
    # row, not by the particle count
    ids = np.concatenate(comm.allgather(p.id[bottom_row]))
    raster = raster_shape(PLOT, 0.75 * dx)

    def observe(s):
        q = s.particles
        sel = np.isin(q.id, ids)
        loc = float(np.max(np.abs(q.stress[sel, 1, 1]))) if np.any(sel) else 0.0
        info["row_peak"][0] = max(info["row_peak"][0], comm.allreduce(loc, op=MPI.MAX))
        for ts in SNAPSHOTS:
            if abs(s.t - ts) < 0.5 * s.dt and ts not in info["snapshots"]:
                um = np.linalg.norm(q.u, axis=1)
                umax = comm.allreduce(float(np.max(um)) if len(q) else 0.0, op=MPI.MAX)
                info[f"umax_{ts}"] = umax
                info["snapshots"][ts] = (particle_raster(comm, q.x - q.u + MAG * q.u, um, PLOT,
                                                         raster), umax)

    sim.observe(observe)
    return sim, info


def run_base(base, dx, t_end, shape="auto"):
    sim, info = build(base, dx, shape)
    energy = sim.monitor_energy(every=10, tolerance=0.05)
    comm.barrier()
    t0 = time.perf_counter()
    sim.run(t_end=t_end)
    wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    top, bot = info["top"].data(), info["bottom"].data()          # collective
    t = top["t"]

    def at(ts):
        return float(np.interp(ts, t, top["displacement_y"]))

    s = dict(base=base, wall_s=wall, steps=sim.step_count, n_particles=sim.particles.n_global(),
             newton_iterations=float(np.mean(sim.integrator.iterations)),
             u_max_025=info["umax_0.25"], u_load_025=at(0.25), u_load_100=at(1.0),
             u_load_peak=float(np.min(top["displacement_y"])),
             sigma_bottom=float(np.max(np.abs(bot["stress_yy"]))),
             sigma_bottom_row=info["row_peak"][0], loaded_particles=info["n_loaded"],
             shape=sim.shape, energy_balance=energy[-1]["balance_error"])
    hist = dict(t=t, u_load=top["displacement_y"], sigma_bottom=bot["stress_yy"])
    sim.integrator.system.destroy()
    return dict(summary=s, hist=hist, snapshots=info["snapshots"])


def write_csv(path, runs):
    t = runs[0]["hist"]["t"]
    cols, head = [t], ["t"]
    for r in runs:
        b = r["summary"]["base"]
        cols += [r["hist"]["u_load"], r["hist"]["sigma_bottom"]]
        head += [f"u_y_load_{b}", f"sigma_yy_bottom_{b}"]
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=",".join(head), comments="")


def plot(runs, path, dx):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    nb = len(runs)
    fig, axes = plt.subplots(3, nb, figsize=(4.3 * nb, 12.0), squeeze=False, layout="constrained")
    for i, ts in enumerate(SNAPSHOTS):
        vmax = max(r["snapshots"][ts][1] for r in runs)
        for j, r in enumerate(runs):
            ax = axes[i, j]
            um, umax = r["snapshots"][ts]
            sc = ax.imshow(um.T, origin="lower", extent=(*PLOT[0], *PLOT[1]), cmap="viridis",
                           vmin=0.0, vmax=vmax)
            ax.set_aspect("equal")
            ax.set_xlim(-0.1, L + 0.6)
            ax.set_ylim(-0.6, L + 0.1)
            s = r["summary"]
            ax.set_title(f"{s['base']}, t = {ts:g} s: max |u| = {umax:.4f} m", fontsize=9)
            ax.plot([0, L, L], [0, 0, L], "k:", lw=0.6)
        fig.colorbar(sc, ax=axes[i, :].tolist(), label=f"|u| [m] at t = {ts:g} s", shrink=0.9)
    colors = {"fixed": "0.3", "viscous": "C0", "viscoelastic": "C1"}
    ax1, ax2 = axes[2, 0], axes[2, 1]
    for r in runs:
        b, h = r["summary"]["base"], r["hist"]
        ax1.plot(h["t"], h["u_load"], color=colors[b], label=b)
        ax2.plot(h["t"], 1e-3 * h["sigma_bottom"], color=colors[b], label=b)
    tt = np.linspace(0, runs[0]["hist"]["t"][-1], 201)
    ax3 = axes[2, 2] if nb > 2 else ax1.twinx()
    ax3.plot(tt, [1e-3 * line_load(x) for x in tt], "k")
    ax3.set_ylabel("line load P(t) [kN/m]")
    ax3.set_xlabel("time [s]")
    ax3.set_title(f"sin$^2$ pulse on the top particles in x < {WIDTH:g} m", fontsize=9)
    ax1.set_ylabel("u_y under the load [m]")
    ax2.set_ylabel(r"$\sigma_{yy}$ at the bottom below the load [kPa]")
    for ax in (ax1, ax2, ax3):
        ax.grid(alpha=0.3)
        ax.set_xlabel("time [s]")
    ax1.legend(fontsize=8)
    ax2.legend(fontsize=8)
    fig.suptitle(f"W4 line load on a 4 m x 4 m half model, dx = {dx} m, Newmark dt = {DT} s, "
                 f"{comm.size} rank(s); deformation x {MAG:g}", fontsize=11)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/point_load_2d", help="output directory")
    parser.add_argument("--quick", action="store_true", help="dx = 0.2 m (a few seconds)")
    parser.add_argument("--shape", default="auto", help="Simulation shape family (default \"auto\": cpGIMP here; \"mpm\" for the standard family)")
    args = parser.parse_args(argv)
    dx, t_end = (0.2 if args.quick else 0.05), 1.0
    if comm.rank == 0:
        os.makedirs(args.out, exist_ok=True)
    runs = [run_base(b, dx, t_end, args.shape) for b in BASES]
    sums = {r["summary"]["base"]: r["summary"] for r in runs}
    absorbing = ("viscous", "viscoelastic")
    ratio = {b: sums["fixed"]["sigma_bottom"] / sums[b]["sigma_bottom"] for b in absorbing}
    ratio_row = {b: sums["fixed"]["sigma_bottom_row"] / sums[b]["sigma_bottom_row"]
                 for b in absorbing}
    png = os.path.join(args.out, "point_load_2d.png")
    csv = os.path.join(args.out, "histories.csv")
    if comm.rank == 0:
        write_csv(csv, runs)
        plot(runs, png, dx)
        print(f"\nW4 line load: 4 m x 4 m, dx = {dx} m, {sums['fixed']['n_particles']} particles, "
              f"Newmark dt = {DT} s to {t_end} s, {comm.size} rank(s)")
        print(f"load: {P_PEAK / 1e3:g} kN/m * sin^2(pi t / {T_LOAD:g}) on the "
              f"{sums['fixed']['loaded_particles']} top particles within {WIDTH:g} m of the axis "
              f"(pressure {P_PEAK / WIDTH / 1e3:g} kPa at the peak); gravity not applied; "
              f"absorbing laws as particle layers")
        print(f"{'boundary':<13} {'max|u| 0.25s':>12} {'thesis':>7} {'u_y load 0.25':>13} "
              f"{'u_y load 1.0':>12} {'thesis':>7} {'σyy bottom [kPa]':>16} {'row [kPa]':>9} "
              f"{'balance':>7} {'Newton':>6} {'wall [s]':>8}")
        for b in BASES:
            s = sums[b]
            th = THESIS["u_load_100"].get(b)
            print(f"{b:<13} {s['u_max_025']:12.4f} {THESIS['u_max_025'][b]:7.2f} "
                  f"{s['u_load_025']:13.4f} {s['u_load_100']:12.4f} "
                  f"{'-' if th is None else f'{th:.2f}':>7} {s['sigma_bottom'] / 1e3:16.2f} "
                  f"{s['sigma_bottom_row'] / 1e3:9.2f} {s['energy_balance']:+7.2%} "
                  f"{s['newton_iterations']:6.2f} "
                  f"{s['wall_s']:8.2f}")
        print("bottom-stress ratio fixed / absorbing (below the load; whole bottom row): "
              + ", ".join(f"{b} {ratio[b]:.2f}; {ratio_row[b]:.2f}" for b in absorbing)
              + f" (thesis ~{THESIS['bottom_ratio']:g})")
        print(f"balance: (kinetic + strain - work of the load - work of the far field) at "
              f"{t_end} s over the largest work of the load; shape={sums['fixed']['shape']!r}")
        print(f"\nplot: {png}\ncsv:  {csv}")
    out = dict(png=png, csv=csv, dx=dx, t_end=t_end, load_width=WIDTH, bottom_ratio=ratio,
               bottom_row_ratio=ratio_row, thesis=THESIS)
    out.update(sums)
    return out


if __name__ == "__main__":
    main()
