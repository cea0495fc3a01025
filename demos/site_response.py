"""P1: site response of a 10 m soil column on a rigid base (BENCHMARKS.md P1, seed 003 §3).

    python3 demos/site_response.py [--out DIR] [--quick]
    mpirun -n 2 python3 demos/site_response.py

Column (built below with the public API: fm.Grid, fm.Particles.fill, fm.Simulation with
on_leave="periodic", sim.set_periodic, fm.rigid_base, sim.probe; the same scene as
fenicsmpm.problems.soil_column.soil_column, whose helpers analyse the records): H = 10 m, E = 1e4 kPa, nu = 0.33, unit weight
18.5 kN/m^3 (V_s = 44.65 m/s, f_n = (2n+1) V_s / (4H) = 1.116, 3.349, 5.581 Hz), one cell
wide with periodic sides, 2x2 particles per cell, element size 0.25 m (--quick: 0.5 m).
Input: the Gabor wavelet at f0 (soil_column.gabor: 0.1 m/s^2, gamma = 0.5, centred at
t = 1 s), baseline-corrected, on a rigid base (relative-frame body force; the absolute top
motion is relative + input). Gravity is switched on at t = 0 on the stress-free column, so
the vertical acceleration shows how each scheme treats the vertical (P-wave) noise.
Schemes: symplectic Euler (fm.Explicit(), MUSL, dt = "auto"), explicit generalized-alpha
(rho_b = 0.5, dt = "auto") and implicit Newmark (beta = 1/4, gamma = 1/2, dt = h / c_p).
Record: 20 s (--quick: 12 s).

Printed: the first three transfer-function peaks and their errors against f_n, the top/base
amplification at f0, the RMS vertical acceleration at the top, the Arias intensity of the
input and of the top motion, and wall times.
Writes to DIR (default results/site_response/):
    site_response_histories.png   top a_x, v_x, u_x and a_y for the three schemes
    site_response_transfer.png    |FFT(a_top)| / |FFT(a_base)| over 1 / |cos(2 pi f H / V_s)|
"""
import argparse
import os
import time

import numpy as np
from mpi4py import MPI

from dolfinx import mesh as dmesh

import fenicsmpm as fm
from fenicsmpm.problems import soil_column as sr


def build(integrator, h, t_end, comm=MPI.COMM_WORLD):
    """The column on a rigid base, gravity switched on at t = 0: (sim, info) as
    soil_column returns them (info: the probes and the motion, for sr.column_histories)."""
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [h, sr.H]], [1, int(round(sr.H / h))],
                                 dmesh.CellType.quadrilateral)       # one cell wide
    grid = fm.Grid(msh)
    soil = fm.LinearElastic(E=sr.E, nu=sr.NU, density=sr.RHO)
    pts = fm.Particles.fill(grid, soil, per_cell=2)
    dt = "auto" if integrator.explicit else h / soil.p_wave_speed    # implicit: Courant 1
    sim = fm.Simulation(grid, pts, integrator, dt=dt, on_leave="periodic", gravity=(0.0, -9.81))
    sim.set_periodic(0)                                  # the two sides move together
    motion = fm.InputMotion.from_callable(sr.gabor(), t_end, 1e-3)   # baseline-corrected
    base = fm.rigid_base(sim, lambda x: np.abs(x[:, 1]) < 1e-8 * sr.H, motion, component=0)
    probes = dict(top=sim.probe([0.5 * h, sr.H], ["velocity", "displacement"]),
                  base=sim.probe([0.5 * h, 0.0], ["velocity", "displacement"]))
    return sim, dict(probes=probes, motion=motion, incident=motion, base="rigid", bc=base,
                     V_s=sr.VS, f_n=sr.natural_frequencies(3), H=sr.H, h=h, dt=sim.dt)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/site_response")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    h, t_end = (0.5, 12.0) if args.quick else (0.25, 20.0)
    schemes = [("symplectic Euler (MUSL)", fm.Explicit()),
               ("explicit gen.-alpha rho_b=0.5", fm.ExplicitGeneralizedAlpha(0.5)),
               ("implicit Newmark", fm.Newmark())]
    runs, curves, rows = [], [], []
    for name, integ in schemes:
        sim, info = build(integ, h, t_end)
        t0 = time.perf_counter()
        sim.run(t_end=t_end, progress=False)
        wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
        hist = sr.column_histories(sim, info)
        peaks, err, (f, ratio) = sr.transfer_peaks(hist)
        runs.append(hist)
        curves.append((name, f, ratio))
        rows.append(dict(scheme=name, dt=sim.dt, peaks=peaks, errors=err,
                         amplification_f0=sr.amplification_at(hist, info["f_n"][0]),
                         vertical_rms=sr.noise_rms(hist["t"], hist["ay_top"]),
                         arias_in=sr.arias_intensity(hist["t"], hist["a_in"])[-1],
                         arias_top=sr.arias_intensity(hist["t"], hist["a_top"])[-1], wall=wall))
    if comm.rank == 0:
        os.makedirs(args.out, exist_ok=True)
        fn = sr.natural_frequencies(3)
        print(f"P1 site response, h = {h} m, {t_end} s; f_n = {np.round(fn, 3)} Hz")
        for r in rows:
            print(f"{r['scheme']:32s} dt={r['dt']:.3g}  peaks {np.round(r['peaks'], 3)} Hz, "
                  f"errors {np.round(100 * r['errors'], 2)} %, |H(f0)| = {r['amplification_f0']:.1f}, "
                  f"RMS a_y = {r['vertical_rms']:.3g} m/s^2, Arias in/top = {r['arias_in']:.3g}/"
                  f"{r['arias_top']:.3g} m/s, wall {r['wall']:.1f} s")
        labels = [r["scheme"] for r in rows]
        sr.plot_histories(runs, os.path.join(args.out, "site_response_histories.png"),
                          title=f"P1 column, h = {h} m, Gabor wavelet at f0 = {fn[0]:.3f} Hz",
                          labels=labels)
        sr.plot_transfer(curves, os.path.join(args.out, "site_response_transfer.png"),
                         title=f"P1 transfer function top/base, h = {h} m")
    return rows


if __name__ == "__main__":
    main()
