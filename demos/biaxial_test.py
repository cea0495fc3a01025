"""Seed 004's biaxial test (Figure 3.3) in MPM: dense hypoplastic sand compressed in plane
strain under a constant confining pressure, against the mesh-free element test.

    python3 demos/biaxial_test.py [--out DIR] [--quick]
    mpirun -n 2 python3 demos/biaxial_test.py --quick

Set-up: a 1 m x 1 m sample of fm.Hypoplastic sand (seed 004 Table 3.1 in SI, as in
demos/pile_driving.py; rho 2600 kg/m^3, e_0 = 0.65) under sigma = -100 kPa I, in a
1.5 m x 1.25 m mesh of square cells (h = 0.25 m, quick too; --h), 2 x 2 particles per cell;
rollers on its base and left side; its top nodes pushed down by 10 % of its height over
t = 1 (sim.fix(top, [1], displacement=u(t))); the confining 100 kPa on its right side as a
follower pressure on the particle column there (sim.add_surface_pressure), which stays on the
sample as it dilates into the empty cells beyond x = 1 (a facet traction stays on the mesh).
fm.QuasiStatic(rtol=1e-6) in 100 steps (quick 50). shape="cpgimp": the default for
hypoplastic sand, the standard family (--shape auto), does not see the particles that
spread beyond their cells as the sample bulges: q -4.4 % at 5 % strain and +5.8 % at 10 %
(quick, 2026-12-06), where cpGIMP is within 0.3 % (the Mohr-Coulomb sample of
tests/test_surface_pressure.py: 5 % low, 0.06 %).

Reported (printed table, DIR/biaxial_test.json, DIR/biaxial_test.png): the deviatoric stress
q = sigma_xx - sigma_yy (volume mean of the particles away from the loaded column, x < 0.75 m)
against the axial strain, beside fenicsmpm.materials.element_test.biaxial (1000 steps), their
difference at 1, 2, 5 and 10 %, the peak, and the sample's volumetric strain (dense sand:
contraction, then dilation; ln(V / V0) of the particles against the element test's tr eps).

Measured (2026-12-06, h = 0.25 m, 64 particles; the element test 1000 steps): quick, serial
(50 steps, 11.8 s) and on 2 ranks (10.5 s), the same figures: q +0.30 / +0.06 / +0.11 / +0.25 % off the element
test at 1 / 2 / 5 / 10 % axial strain, peak 309.3 kPa at 2.8 % (element test 309.1 kPa);
full (100 steps, 16 s): +0.24 / +0.04 / +0.01 / +0.19 %, peak 309.1 kPa at 2.9 %; with
Newton's default rtol = 1e-8 the full run stopped in step 47 (|R|/|f| = 1.2e-8). The sample's
volumetric strain ln(V / V0) follows the element test's contraction and dilation within
0.1 % of strain (least -0.38 % against -0.47 %, +0.93 % against +0.89 % at the end: the
loaded particle column, less confined, is in the MPM figure).
"""
import argparse
import json
import os
import time

import numpy as np
from mpi4py import MPI
from dolfinx import mesh

import fenicsmpm as fm
from fenicsmpm.materials import element_test

comm = MPI.COMM_WORLD
S0 = 100e3                 # confining pressure [Pa] (seed Fig. 3.3: sigma0 = -100 kPa)
EPS = -0.10                # axial strain at t = 1
E_0 = 0.65                 # dense (seed Fig. 3.3)
# seed 004 Table 3.1 in SI (h_s = 5.8E6 kPa, p_t = 1.6 kPa), as demos/pile_driving.py
TABLE_3_1 = dict(phi_c=30.0, h_s=5.8e9, n=0.28, e_d0=0.53, e_c0=0.84, e_i0=1.0, alpha=0.13,
                 beta=1.0, m_R=10.0, m_T=2.0, R=5e-5, beta_r=0.3, chi=1.0, p_t=1600.0)
CHECK = (0.01, 0.02, 0.05, 0.10)
# Newton's tolerance |R| <= RTOL |f|: the hypoplastic update's adaptive sub-steps (its tol
# 1e-4) leave the residual a floor near 1e-8, Newton's default rtol, where it stalled (step 47
# of 100 at 1.2e-8, 2026-12-06)
RTOL = 1e-6


def sand():
    return fm.Hypoplastic(density=2600.0, e_0=E_0, **TABLE_3_1)


def build(h, steps, shape):
    """The Simulation (module docstring) and the sample's top locator."""
    grid = fm.Grid(mesh.create_rectangle(comm, [[0.0, 0.0], [1.5, 1.25]],
                                         [int(round(1.5 / h)), int(round(1.25 / h))],
                                         mesh.CellType.quadrilateral))
    p = fm.Particles.fill(grid, sand(), per_cell=2,
                          region=lambda x: (x[:, 0] < 1.0) & (x[:, 1] < 1.0))
    p.stress[:] = -S0 * np.eye(3)
    sim = fm.Simulation(grid, p, fm.QuasiStatic(rtol=RTOL), dt=1.0 / steps, shape=shape)
    top = lambda x: np.isclose(x[:, 1], 1.0)
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0), [1])
    sim.fix(lambda x: np.isclose(x[:, 0], 0.0), [0])
    sim.fix(top, [1], displacement=lambda t: EPS * t)
    sim.add_surface_pressure(lambda x: x[:, 0] > 1.0 - h / 2, (1.0, 0.0), S0)
    return sim


def plot(eps, q, ev, ref_eps, ref_q, ref_ev, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4.2))
    ax1.plot(100 * ref_eps, ref_q / 1e3, "k-", lw=1, label="element test")
    ax1.plot(100 * eps, q / 1e3, "C0o", ms=3, label="MPM (x < 0.75 m)")
    ax1.set_xlabel("axial strain [%]")
    ax1.set_ylabel(r"$q = \sigma_{xx} - \sigma_{yy}$ [kPa]")
    ax2.plot(100 * ref_eps, 100 * ref_ev, "k-", lw=1, label="element test")
    ax2.plot(100 * eps, 100 * ev, "C0o", ms=3, label="MPM (whole sample)")
    ax2.set_xlabel("axial strain [%]")
    ax2.set_ylabel(r"volumetric strain $\varepsilon_v$ [%] (dilation > 0)")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Drained biaxial test on dense hypoplastic sand (seed 004 Fig. 3.3), "
                 "sigma0 = 100 kPa, e0 = 0.65", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/biaxial_test", help="output directory")
    parser.add_argument("--quick", action="store_true", help="50 steps (about 15 s)")
    parser.add_argument("--h", type=float, default=0.25, help="cell size [m]")
    parser.add_argument("--shape", default="cpgimp", help="shape family (default cpgimp)")
    args = parser.parse_args(argv)
    steps = 50 if args.quick else 100
    if comm.rank == 0:
        os.makedirs(args.out, exist_ok=True)
    sim = build(args.h, steps, args.shape)
    p = sim.particles
    V0 = p.total(p.V)
    eps, q, ev = [0.0], [0.0], [0.0]

    def record(s):
        w = np.where(p.x[:, 0] < 0.75, p.V, 0.0)
        sxx, syy = (p.total(w * p.stress[:, k, k]) / p.total(w) for k in (0, 1))
        eps.append(-EPS * s.t)
        q.append(sxx - syy)
        ev.append(float(np.log(p.total(p.V) / V0)))          # ln J, as tr(sum D dt)
    sim.observe(record, every=1)
    t0 = time.perf_counter()
    sim.run(t_end=1.0 - 1e-9, progress=not args.quick)
    wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    eps, q, ev = np.array(eps), np.array(q), np.array(ev)
    ref = element_test.biaxial(sand(), S0, e0=E_0, axial_strain=EPS, n=1000)
    ref_eps = -ref["eps_a"]
    ref_q = ref["sigma"][:, 0, 0] - ref["sigma"][:, 1, 1]
    ref_ev = ref["eps_v"]
    rel = {f"{e:g}": float(np.interp(e, eps, q) / np.interp(e, ref_eps, ref_q) - 1.0)
           for e in CHECK}
    out = dict(shape=sim.shape, h=args.h, steps=sim.step_count, particles=p.n_global(),
               wall_s=wall, q_peak=float(q.max()), eps_at_peak=float(eps[np.argmax(q)]),
               q_peak_element=float(ref_q.max()), q_relative_difference=rel,
               volumetric_strain_end=float(ev[-1]), png=os.path.join(args.out, "biaxial_test.png"),
               json=os.path.join(args.out, "biaxial_test.json"))
    if comm.rank == 0:
        plot(eps, q, ev, ref_eps, ref_q, ref_ev, out["png"])
        with open(out["json"], "w") as f:
            json.dump(dict(out, curve=dict(eps=eps.tolist(), q=q.tolist(), eps_v=ev.tolist())),
                      f, indent=1)
        print(f"biaxial test, shape {sim.shape}, h = {args.h:g} m, {out['particles']} particles, "
              f"{sim.step_count} steps, {wall:.1f} s")
        print(f"{'axial strain':>14} {'q MPM [kPa]':>12} {'q element':>10} {'difference':>11}")
        for e in CHECK:
            print(f"{100 * e:13.0f}% {np.interp(e, eps, q) / 1e3:12.1f} "
                  f"{np.interp(e, ref_eps, ref_q) / 1e3:10.1f} {rel[f'{e:g}']:+11.2%}")
        print(f"peak q {out['q_peak'] / 1e3:.1f} kPa at {100 * out['eps_at_peak']:.1f} % "
              f"(element test {out['q_peak_element'] / 1e3:.1f} kPa); volumetric strain at the "
              f"end {100 * ev[-1]:+.2f} %; results in {args.out}/")
    return out


if __name__ == "__main__":
    main()
