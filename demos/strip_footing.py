"""W5: a strip footing on soft clay under a repeated load: fixed against absorbing boundaries.

    python3 demos/strip_footing.py [--out DIR] [--quick]
    mpirun -n 2 python3 demos/strip_footing.py

BENCHMARKS.md W5 (seed 000 ch. 5): a plane-strain half model of a strip footing of width
B = 0.5 m (the loaded half-width B/2 = 0.25 m next to the symmetry axis x = 0) on a layer
D = 6 m wide and H = 4 m deep, the seed's dx = 0.0625 m (--quick: 0.25 m; --dx to change),
2 x 2 particles per cell, dt = 0.005 s. Soil: von Mises clay (fm.VonMises) E = 2 MPa,
nu = 0.41, rho = 1000 kg/m^3, c_u = 10 kPa softening linearly (H = -140 kPa) to c_res = 3 kPa;
c_p = 68.2 m/s. The softening is regularised (issue 19, fenicsmpm.materials.regularisation:
over-nonlocal eps_p, internal length --length, default 0.25 m; --length 0 for local
softening, with which the band localises into one cell at dx = 0.0625 m and the footing
fails in the first pulse: the run stops at t = 0.64-0.65 s when particles heave out of the top
of the mesh, 66-68 mm settled). The von Mises soil gets F-bar by default (Simulation
fbar="auto"; measured at dx = 0.0625 m with the default length: settlements after the three
pulses 11.1 / 16.6 / 18.7 mm on the fixed base against 10.1 / 15.1 / 16.8 mm without F-bar,
v_first 0.350 against 0.336 m/s, 2.24 against 2.16 Newton iterations per step).

Stage 1 (geostatic): quasi-static Newton, gravity g = 10 m/s^2 ramped over 50 steps and held
to step 60 (t = 0.3 s), bottom fixed, rollers on both sides.
Stage 2 (dynamic, sim.start_stage): implicit Newmark (beta = 1/4, gamma = 1/2), dt = 0.005 s,
keeping sigma_ini and removing gravity (seed 000 section 3.5: the internal force comes from
sigma - sigma_ini, the von Mises return sees the total stress), so the absorbing boundaries
carry only the dynamic stress (dashpots alone under the static stress would creep).
Load: three 0.2 s pulses p(t) = 40 kPa sin^2(pi (t - 0.3 s) / 0.2 s) for 0.3 s <= t <= 0.9 s
(the seed's Fig. 5.1b shape is not in its text; peak 40 kPa, 0.2 s each, back to back: the
seed's second pulse is "applied completely" at t = 0.7 s), as a force p(t) B/2 per unit
thickness shared by the top particles with x < B/2 (sim.add_particle_load: it follows the
settling material).
Bases, side by side (left side x = 0: rollers in all three):
  fixed         bottom fixed, right side rollers (as in stage 1),
  viscous       bottom and right side released and replaced by fm.Viscous dashpots
                (Lysmer-Kuhlemeyer, a = b = 1) on the mesh facets,
  viscoelastic  the same with fm.Viscoelastic (Deeks-Randolph springs k = G / (2 r_b),
                r_b = 4 m, the distance from the footing to the bottom).

Printed and returned per base:
  sigma_v_base    geostatic sigma_yy of the bottom particle row after stage 1 against
                  -rho g d (d their depth; the seed: 40 kPa at the base), worst relative error,
  u_static        geostatic settlement of the surface particle nearest x = 0 after stage 1
                  against the 1D closed form rho g (H y0 - y0^2 / 2) / M (M = E (1 - nu) /
                  ((1 + nu)(1 - 2 nu)) = 4.65 MPa, y0 its initial height),
  v_first         the peak downward velocity of the surface particle nearest x = 0 (under
                  the footing's centre) during the first pulse (t < 0.5 s), against
                  the 1D estimate p / (rho c_p) = 0.58 m/s (the seed measures 0.52 m/s),
  settlement      its downward displacement at the end of each pulse (t = 0.5, 0.7, 0.9 s),
  sigma_bottom    the largest |sigma_yy - sigma_yy,ini| (dynamic vertical stress) at the
                  particle nearest (0, dx/4) (bottom, below the footing): the fixed base
                  reflects the pulse and roughly doubles it,
  eps_p_max       the largest equivalent plastic strain (VonMises state column 0), and
                  the plastic zone depth below the surface (particles with eps_p > 0.01),
  newton          mean Newton iterations per dynamic step (Newmark rtol 1e-6; a step whose
                  Newton fails is retried as halves, up to 4 times: max_dt_cuts = 4).
A run whose Newton still fails (the softened soil under the footing has failed: the seed's
"the foundation reaches the failure point") stops there; its numbers are reported up to
that time with the message, and the settlement list ends at the last complete pulse.
Prandtl's bearing capacity (2 + pi) c_u = 51.4 kPa exceeds the 40 kPa pulses: failure here
comes from softening under repeated loading.

Writes to DIR (default results/strip_footing/):
    strip_footing.png   the final plastic strain as rasters (fenicsmpm.io.particle_raster: the
                        mean per square of 3 dx / 4), the three bases side by side, and the
                        histories of settlement and bottom dynamic stress
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
B, H, D = 0.5, 4.0, 6.0
E, NU, RHO = 2.0e6, 0.41, 1000.0
C_U, C_RES, H_SOFT = 10.0e3, 3.0e3, -140.0e3
G = 10.0
DT = 0.005
P_PEAK, T0, PULSE, N_PULSES = 40.0e3, 0.3, 0.2, 3
R_B = 4.0
STATIC_STEPS, RAMP_STEPS = 60, 50
PLASTIC = 0.01                  # plastic zone: eps_p above this
PLOT = ((0.0, D), (0.0, H + 0.1))     # the plastic strain rasters' rectangle


def pressure(t):
    """Footing pressure [Pa]: N_PULSES back-to-back sin^2 pulses from T0."""
    s = (t - T0) / PULSE
    return P_PEAK * math.sin(math.pi * s) ** 2 if 0.0 <= s <= N_PULSES else 0.0


def c_p():
    M = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))
    return math.sqrt(M / RHO)


def run_base(base, dx, t_end, length=None):
    nx, ny = int(round(D / dx)), int(round(H / dx))
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [D, H]], [nx, ny], dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    soil = fm.VonMises(E=E, nu=NU, density=RHO, c_u=C_U, c_res=C_RES, H=H_SOFT,
                       nonlocal_length=length)
    pts = fm.Particles.fill(grid, soil, per_cell=2)
    qs = fm.QuasiStatic(load_steps=RAMP_STEPS)
    sim = fm.Simulation(grid, pts, qs, dt=DT, gravity=(0.0, -G), max_dt_cuts=4)
    tol = 1e-6 * dx
    left = lambda x: np.abs(x[:, 0]) < tol
    right = lambda x: np.abs(x[:, 0] - D) < tol
    bottom = lambda x: np.abs(x[:, 1]) < tol
    sim.fix(left, [0])
    sim.fix(right, [0])
    sim.fix(bottom)
    top = sim.probe((0.0, H), ["displacement", "velocity", "position"])
    bot = sim.probe((0.0, 0.0), ["stress"])
    t0 = time.perf_counter()
    sim.run(steps=STATIC_STEPS)
    p = sim.particles
    # geostatic check on the bottom particle row
    y0 = p.x[:, 1]
    row = y0 < 0.5 * dx
    err = np.abs(p.stress[row, 1, 1] / (-RHO * G * (H - y0[row])) - 1.0)
    err_max = comm.allreduce(float(err.max()) if len(err) else 0.0, op=MPI.MAX)
    s_base = comm.allreduce(float(p.stress[row, 1, 1].min()) if np.any(row) else 0.0, op=MPI.MIN)
    static_newton = list(qs.iterations)
    # 1D closed form of the geostatic settlement at the probed particle's height y0 (rollers
    # on the sides, fixed base): u_y(y0) = -rho g (H y0 - y0^2 / 2) / M
    d0 = top.data()
    M = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))
    yp = float(d0["position_y"][0])
    u_static = float(-d0["displacement_y"][-1])
    u_static_exact = RHO * G * (H * yp - 0.5 * yp * yp) / M

    nm = fm.Newmark(rtol=1e-6)
    sim.start_stage(nm, dt=DT, gravity=(0.0, 0.0))       # keeps sigma_ini, u from here
    y_top = comm.allreduce(float(p.x[:, 1].max()) if len(p) else -np.inf, op=MPI.MAX)
    sim.add_particle_load(region=lambda x: (x[:, 1] > y_top - 0.5 * dx) & (x[:, 0] < B / 2),
                          value=lambda t: (0.0, -pressure(t) * B / 2))
    if base != "fixed":
        sim.release(lambda x: bottom(x) | right(x))
        law = fm.Viscous if base == "viscous" else (lambda w: fm.Viscoelastic(w, r_b=R_B))
        sim.add_boundary(law(lambda x: bottom(x) | right(x)))
    stopped = None
    try:
        sim.run(t_end=t_end)
    except (RuntimeError, FloatingPointError) as err:      # every rank raises the same
        stopped = str(err).splitlines()[0]
    wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)

    dt_top, dt_bot = top.data(), bot.data()
    tt = dt_top["t"]
    dyn = tt > T0 + 1e-9           # the record at T0 itself is the static state, before the reset
    uy = dt_top["displacement_y"]
    # stage 2 resets displacements at T0: uy after T0 is the settlement
    ends = [T0 + PULSE * (k + 1) for k in range(N_PULSES) if T0 + PULSE * (k + 1) <= sim.t + 1e-9]
    ends = ends or [sim.t]
    settle = [float(-np.interp(te, tt[dyn], uy[dyn])) for te in ends]
    first = dyn & (tt <= T0 + PULSE + 1e-9)
    v_first = float(-dt_top["velocity_y"][first].min())
    tb = dt_bot["t"]
    s0 = np.interp(T0, tb, dt_bot["stress_yy"])
    sig_bottom = float(np.max(np.abs(dt_bot["stress_yy"][tb >= T0] - s0)))
    eps = p.state[:, 0]
    eps_max = comm.allreduce(float(eps.max()) if len(p) else 0.0, op=MPI.MAX)
    x0 = p.x - p.u
    zone = eps > PLASTIC
    depth = comm.allreduce(float((H - x0[zone, 1]).max()) if np.any(zone) else 0.0, op=MPI.MAX)
    eps_r = particle_raster(comm, p.x, eps, PLOT,
                            raster_shape(PLOT, 0.75 * dx))
    res = dict(base=base, dx=dx, n_particles=p.n_global(), sigma_v_base=s_base,
               sigma_v_base_exact=-RHO * G * (H - 0.25 * dx), sigma_v_error=err_max,
               static_newton=static_newton, static_settlement=u_static,
               static_settlement_exact=u_static_exact,
               static_settlement_error=abs(u_static / u_static_exact - 1.0), v_first=v_first, settlement=settle,
               settlement_times=ends, sigma_bottom=sig_bottom, eps_p_max=eps_max,
               plastic_depth=depth, newton_mean=float(np.mean(nm.iterations)),
               newton_max=int(np.max(nm.iterations)), dynamic_steps=len(nm.iterations),
               t_reached=float(sim.t), stopped=stopped, wall_s=wall, hist=dict(t=tt, uy=uy, tb=tb, syy=dt_bot["stress_yy"] - s0))
    if comm.rank == 0:
        res["eps"] = eps_r
    return res


def plot(results, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    n = len(results)
    fig = plt.figure(figsize=(4.2 * n + 1.0, 6.5), constrained_layout=True)
    gs = fig.add_gridspec(2, n, height_ratios=(1.3, 1))
    vmax = max(max(r["eps_p_max"] for r in results), 1e-9)
    for k, r in enumerate(results):
        ax = fig.add_subplot(gs[0, k])
        sc = ax.imshow(r["eps"].T, origin="lower", extent=(*PLOT[0], *PLOT[1]), cmap="magma_r",
                       vmin=0.0, vmax=min(vmax, 1.0))
        ax.set_aspect("equal")
        ax.set_xlim(0, D)
        ax.set_ylim(0, H + 0.1)
        ax.set_title(f"{r['base']}: settlement {1e3 * r['settlement'][-1]:.0f} mm", fontsize=9)
        ax.set_xlabel("x [m]")
        if k == 0:
            ax.set_ylabel("y [m]")
    fig.colorbar(sc, ax=fig.axes[:n], label=r"plastic strain $\varepsilon_p$", shrink=0.8)
    ax1 = fig.add_subplot(gs[1, : max(1, n // 2 + n % 2)])
    ax2 = fig.add_subplot(gs[1, max(1, n // 2 + n % 2):]) if n > 1 else None
    for r in results:
        h = r["hist"]
        a, b = h["t"] > T0 + 1e-9, h["tb"] >= T0
        ax1.plot(h["t"][a], -1e3 * h["uy"][a], label=r["base"])
        if ax2 is not None:
            ax2.plot(h["tb"][b], h["syy"][b] / 1e3, label=r["base"])
    ax1.set_xlabel("t [s]")
    ax1.set_ylabel("settlement since t = 0.3 s [mm]")
    ax1.legend(fontsize=8)
    ax1.grid(alpha=0.3)
    if ax2 is not None:
        ax2.set_xlabel("t [s]")
        ax2.set_ylabel(r"dynamic $\sigma_{yy}$ at the bottom [kPa]")
        ax2.grid(alpha=0.3)
    fig.suptitle("Strip footing under three 40 kPa pulses (W5): fixed vs absorbing boundaries",
                 fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/strip_footing", help="output directory")
    parser.add_argument("--quick", action="store_true",
                        help="coarse grid (dx = 0.25 m), first pulse only, fixed and viscous")
    parser.add_argument("--dx", type=float, default=None, help="cell size (default 0.0625 m)")
    parser.add_argument("--length", type=float, default=0.25,
                        help="nonlocal internal length l [m] (0: local softening)")
    parser.add_argument("--bases", default=",".join(BASES), help="comma-separated bases")
    args = parser.parse_args(argv)
    if args.quick:
        dx, t_end, bases = 0.25, T0 + PULSE, ("fixed", "viscous")
    else:
        dx, t_end, bases = 0.0625, T0 + N_PULSES * PULSE, tuple(args.bases.split(","))
    dx = args.dx or dx
    if comm.rank == 0:
        os.makedirs(args.out, exist_ok=True)
    results = [run_base(b, dx, t_end, args.length or None) for b in bases]
    v_est = P_PEAK / (RHO * c_p())
    strip = lambda r: {k: v for k, v in r.items() if k not in ("eps", "hist")}
    metrics = dict(dx=dx, t_end=t_end, nonlocal_length=args.length or None, c_p=c_p(), v_estimate=v_est,
                   prandtl=(2.0 + math.pi) * C_U, runs={r["base"]: strip(r) for r in results})
    if comm.rank == 0:
        png = os.path.join(args.out, "strip_footing.png")
        plot(results, png)
        r0 = results[0]
        print(f"\nStrip footing (W5), dx = {dx:g} m, {r0['n_particles']} particles, dt = {DT} s, "
              f"to t = {t_end:g} s, {comm.size} rank(s); c_p = {c_p():.1f} m/s, "
              f"p/(rho c_p) = {v_est:.3f} m/s, (2 + pi) c_u = {metrics['prandtl'] / 1e3:.1f} kPa")
        print(f"geostatic settlement at the surface (x ~ 0): {1e3 * r0['static_settlement']:.3f} mm, "
              f"1D closed form {1e3 * r0['static_settlement_exact']:.3f} mm "
              f"({100 * r0['static_settlement_error']:.2f}%)")
        print(f"{'base':<13} {'sig_v base [kPa]':>16} {'err':>7} {'v_first [m/s]':>13} "
              f"{'settlement after each pulse [mm]':>33} {'sig_bot dyn [kPa]':>17} "
              f"{'eps_p max':>9} {'zone depth [m]':>14} {'Newton/step':>11} {'wall [s]':>8}")
        for r in results:
            st = ", ".join(f"{1e3 * s:.1f}" for s in r["settlement"])
            print(f"{r['base']:<13} {r['sigma_v_base'] / 1e3:16.2f} {100 * r['sigma_v_error']:6.2f}% "
                  f"{r['v_first']:13.3f} {st:>33} {r['sigma_bottom'] / 1e3:17.2f} "
                  f"{r['eps_p_max']:9.3f} {r['plastic_depth']:14.2f} {r['newton_mean']:11.2f} "
                  f"{r['wall_s']:8.1f}")
        for r in results:
            if r["stopped"]:
                print(f"{r['base']}: stopped at t = {r['t_reached']:.4g} s (settlements up to "
                      f"then): {r['stopped']}")
        print(f"\nplot: {png}")
        metrics["png"] = png
    return comm.bcast(metrics, root=0)


if __name__ == "__main__":
    main()
