"""Pile driving (seed 004 ch. 4): an elastic pile hammered into hypoplastic sand, axisymmetric.

    python3 demos/pile_driving.py [--out DIR] [--quick] [--h H] [--grade H_FAR] [--blows N]
                                  [--gap G] [--start ramp|geostatic] [--t-gravity T]
                                  [--period P] [--shape FAMILY]
                                  [--contact multi-velocity|penalty]
    mpirun -n 2 python3 demos/pile_driving.py --quick

Set-up (seed 004 §4.2): a soil body of radius 5 m and depth 10 m in the meridian plane (r, z)
of an axisymmetric grid (fm.Grid(mesh, axisymmetric=True)), dense hypoplastic sand
(fm.Hypoplastic: von Wolffersdorff 1996 with intergranular strain, seed eqs 3.1-3.23 as
corrected in fenicsmpm.materials.hypoplastic; Table 4.1 in SI: phi_c 30 deg, h_s 5.8e9 Pa,
n 0.28, e_d0/e_c0/e_i0 0.53/0.84/1.0, alpha 0.13, beta 1, m_R 10, m_T 2, R 5e-5, beta_r 0.3,
chi 1, p_t 1.6 kPa), rho 2600 kg/m^3, e_0 = 0.65; an elastic pile 5 m long, radius 0.15 m,
with a hemispherical (rounded) tip standing on the surface (E 100 MPa, nu 0.28, rho 2500);
g = 10; pile-soil Coulomb friction mu = 0.2 by multi-velocity contact (fm.ExplicitContact,
seed eqs 2.34-2.39; default: the plain detection of the seed, gap=None; --gap 0 the library's
gap check), or with --contact penalty the seed's node-to-segment penalty contact (eqs
2.40-2.53, fm.ExplicitContact(algorithm="penalty"); contact.penalty) between two polylines:
the pile's outline (pile_outline: round the tip, up the shaft, across the head) and the
sand's surface, both on the faces of their particle domains, vertices a particle spacing
apart, k_n = M / h with M the larger constrained modulus (penalty_stiffness: the sand's at
p_max); the surface line follows the sand as the tip pushes it down, so the shaft meets
the stretched segment next to it. Bottom fixed, outer side r = 5 m on
rollers, the axis fixed radially by the grid. Stage 1: gravity ramped over 2 s (seed 002 eq
4.13, Simulation(gravity_ramp=4): g reaches its value at T/2), or with --start geostatic the
K0 state (1 - sin phi_c) and e_0 (fenicsmpm.materials.hypoplastic.geostatic) with gravity on
from t = 0 and only the pile settling. Stage 2: hammer blows, q = 1000 kPa on the pile head
for 0.1 s every 0.5 s (seed Fig 4.2), a particle load on the top row of pile particles (one
load per radial column, q (r_o^2 - r_i^2)/2 per radian). Explicit MUSL, 2 x 2 particles per
cell, dt = 0.5 h / c_p with c_p of the soil at p_max = 300 kPa (seed eq 3.30).

Reported (printed table, DIR/pile_driving.json, DIR/pile_driving.png): pile-head settlement
after gravity (seed: 0.25 m, frictional contact), sigma_zz of the base particles after gravity
against rho g (H - z) (seed: -170 kPa, the end of its Fig 4.5 colour scale; rho g H =
-260 kPa at the base), the penetration per
blow (head settlement between blows; seed Fig 4.8: 2.2 m in 20 blows, ~0.11 m a blow), the
peak vertical contact force of each blow, times 2 pi (split into "tip" = contact nodes below
the tip particle + h/2 and "shaft" = the others: at h >= 0.15 m the pile is at most one cell
wide, so the split is rough), and the void ratio near the tip after the blows (seed Fig 4.7:
down to 0.35; note that e_d(p) >= 0.42 up to p = 10 MPa, so e = 0.35 lies outside the
model's admissible range at any stress the pile produces). The PNG shows the void ratio
near the pile as a raster (fenicsmpm.io.particle_raster: the soil's mean e per square of 1.5
particle spacings, the pile's squares in black).

Measured (serial, 2026-12-01, load average 2-6 on 2 cores):
  python3 demos/pile_driving.py   (h = 0.15 m, 8911 particles, K0 start, 0.2 s settling,
  2 blows, plain detection; 11489 steps, 4.4 min CPU, 12.8 min wall on the loaded machine)
                                                here            seed 004
    pile-head settlement after settling         0.029 m         0.25 m (after the 2 s ramp)
    sigma_zz at the base (rho g (H - z) -259.0) -258.2 kPa      -170 kPa
    penetration, blow 1 / blow 2                0.676 / 0.399 m ~0.11 m a blow (2.2 m / 20)
    peak resistance, blow 1 (tip / shaft)       87.0 kN (86.9 / 0.0)
    peak resistance, blow 2 (tip / shaft)       113.4 kN (71.2 / 42.2); hammer: 70.7 kN
    void ratio near the tip after the blows     min 0.503       0.35 (Fig 4.7)
    particles with e < e_d(p) / e > e_i(p)      1 / 28 (surface particles pulled apart)
  python3 demos/pile_driving.py --start ramp --h 0.3   (gravity ramped over 2 s, 145 s wall):
    pile-head settlement after gravity 0.071 m (seed 0.25 m), far-field surface settlement
    0.060 m, base sigma_zz -260.7 kPa against rho g (H - z) = -258.1 kPa (seed -170 kPa); the
    blows then do not drive the pile (-0.02, -0.06 m: at h = 0.3 m the pile is half a cell
    wide and the plain detection locks it). With --gap 0 the pile sinks 0.61 m during the ramp
    and 0.52, 0.41, 0.44, 0.40 m in 4 blows (270 s wall). The ramp at h = 0.15 m (19k steps,
    ~15 min CPU) was not run.
  python3 demos/pile_driving.py --quick   (the test: h = 0.3 m, gap 0, 2 blows every 0.25 s;
    13 s serial, 2026-12-02): base sigma_zz +0.8 % off rho g (H - z), penetration 0.627 /
    0.400 m, peak resistance 134.6 / 111.8 kN, void ratio near the tip down to 0.603. Since
    dt="auto" follows the state (Simulation.follow_state_dt) the step shrinks to 0.5-0.9 of
    its initial value while the sand under the tip is compressed beyond p_max; before, with
    the initial dt above the state's critical step, the same run gave 0.90 / 0.53 m and 60 /
    121 kN. The other runs in this docstring (2026-12-01) were made with the initial dt and
    were not re-run.
Convergence in h (first blow, K0 start, 0.2 s settling; --h H --per-cell P --blows 1):
                       h = 0.6 m (P 4)   h = 0.3 m (P 2)   h = 0.15 m (P 2)
    plain (default)    -0.108 m          -0.005 m          0.676 m
    --gap 0            5.25 m (no contact) 1.137 m         2.180 m
Re-run 2026-12-06 (`--h H --blows 1 [--shape cpgimp]`, serial): standard family (the
default for hypoplastic sand) -0.006 / 0.662 m at h = 0.3 / 0.15 m (18 / 114 s wall), cpGIMP
-0.014 / 0.815 m (19 / 141 s); --quick 0.627 / 0.400 m standard, 0.562 / 0.350 m cpGIMP
(21 / 20 s).
Since 2026-12-07 the contact takes the rollers of the axis out of its normals
(contact.multi_velocity, "Rollers out of the normals"; before, the axis nodes' normal was
diagonal and the roller kept part of the correction): `--h 0.3 / 0.15 --blows 1` -0.050 /
0.624 m (17 / 110 s; pile-head settlement after the settling 0.009 / 0.019 m, first-blow peak
resistance 126.6 / 102.7 kN), --quick 0.391 / 0.082 m, 201.9 / 127.9 kN, settlement after
gravity 0.050 m, base sigma_zz -259.9 kPa against -258.1, void ratio near the tip down to
0.569 (28 s wall beside another run); `--h 0.075 --blows 1` 0.888 m (36,307 particles,
18,093 steps, 912 s wall beside another run; peak resistance 297.6 kN): the first-blow
penetration grows under refinement (-0.050 / 0.624 / 0.888 m at h = 0.3 / 0.15 / 0.075 m).
NOT converged: the two finest sizes differ by far more than 5 %, with either family. With the
pile a quarter, half or one cell wide the contact is not resolved; a uniform h = 0.0375 m (4x
the particles of 0.075 m, 2x the steps) was not run: the graded mesh below reaches it.
Graded mesh (--grade H_FAR, 2026-12-07 evening; graded_nodes): cells of size h for r < 0.6 m
and z > 7 m (the pile and the 3 m of soil under the surface), growing by 1.2 a cell to 0.3 m
outside. `--h H --grade 0.3 --blows 1` (serial, beside one or two other runs):
                                   h = 0.15 m    0.075 m      0.0375 m
    particles                      3,733         7,497        18,404
    steps / wall                   8,144 / 86 s  17,889 / 308 s  42,361 / 1010 s
    first-blow penetration         0.569 m       0.852 m      0.911 m
    (uniform mesh, same h)         0.624 m       0.888 m      -
    head settlement after 0.2 s    0.015 m       0.020 m      0.070 m
    first-blow peak resistance     97.7 kN       130.0 kN     118.3 kN
The first-blow penetration converges (differences 0.283 then 0.059 m, 4.8x smaller per
halving of h), the two finest 6.5 % apart (issue 18 asks for 5 %); the settlement under the
pile's own weight (a pile of 8.8 kN on its rounded tip, on sand at zero stress: a bearing
failure under the tip) does not; the second blow (`--blows 2`) drives the pile 0.313 / 0.488
m at h = 0.15 / 0.075 m (the void ratio near the tip then down to 0.546 / 0.472; 828 s wall
at 0.075 m). Still NOT converged in the issue's sense.
Penalty contact (--contact penalty, 2026-12-07 night, serial, 2 blows; `--h H [--grade 0.3]`):
                                   --quick (h 0.3)  h = 0.15 uniform  0.15 graded   0.075 graded
    particles / wall               2,311 / 9 s      8,911 / 142 s     3,733 / 93 s  7,497 / 421 s
    head settlement after settling 0.027 m          0.031 m           0.032 m       0.060 m
    penetration, blow 1 / blow 2   -0.064 / 0.153   0.384 / 0.127     0.385 / 0.127 0.715 / 0.806
    peak resistance, blow 1        140.4 kN         274.4 kN          272.9 kN      114.5 kN
(--quick: the pile rebounds off the blow and is still in flight at the end of its 0.25 s
period.) At h = 0.15 m the blows drive the pile 0.38 and 0.13 m (seed ~0.11 m a blow), but at
0.075 m the sand's surface line does not stay on the sand (`python3 -c "import sys;
sys.path.insert(0, 'demos'); import pile_driving as d; d.trace(0.075, 0.4, 'penalty')"`, and
'multi-velocity'): its vertices move with the sand's grid velocity, and the surface vertex on
the axis runs ahead of the sand there: 4.3 cm below the sand's highest particle at the axis at
t = 0.352 s (0.15 s into the first blow), 19 cm at t = 0.398 s, when it is 18 cm below the
pile's lowest vertex. Meanwhile the sand at the axis first opens a gap under the tip (its
highest particle 9.1 cm below the pile's lowest at t = 0.352 s; 1-3 cm, adjacent particles,
with multi-velocity contact) and closes it again (0.5 cm at t = 0.398 s). With no line under
its tip the pile keeps sinking between the blows (0.07 m from t = 0.43 to 0.69 s under a
contact force of 0-25 kN), blow 2 deeper than blow 1 (0.488 m with multi-velocity). Not
converged either; a surface that follows the particles (re-built from them, or CPDI corners
as the seed's) would be the next step. The run at 0.15 m first
fell through the sand (2.1 m in the first blow): the surface vertex on the axis had been
moved to r = -7e-9 by the preload and left the grid (mended in contact.penalty).
The seed's gravity stage (`--h 0.15 --start ramp --blows 0 [--contact penalty]`, 2 s ramp,
19,147 steps, one thread each, two runs side by side, 307 / 311 s wall, 2026-12-08): pile-head
settlement 0.065 m with multi-velocity contact and 0.078 m with penalty (seed 0.25 / 0.37 m:
the same order, penalty deeper, but a quarter of the seed's), the far-field surface 0.053 m
with both, base sigma_zz -271.0 / -270.9 kPa against rho g (H - z) = -259.0 kPa (+4.6 %: the
ramp leaves the column ringing; the K0 start reads within 0.4 %). The far-field figure is
taken from the particles that started in the top row (surface_settlement); before, they were
chosen by their current height and a surface that settled more than a quarter cell read
0.000 m (h = 0.15 m; the 0.060 m at h = 0.3 m above was unaffected).
The gap check lets a body one cell wide creep into the soil (an elastic rod on a block sinks
0.08 m in 0.2 s, tests/test_contact.py), so the default is the seed's plain detection, which
contacts one cell early and over-resists (as the seed says of its frictional MPM contact).
Hypoplastic sand in MPM: no NaN; soil particles pulled apart at the surface next to the pile
are held at the tension cap (the p -> 0 rule of fm.Hypoplastic: 'projections' in the JSON) and
their void ratio grows with tr D whatever the stress, beyond e_i (e up to 2-7 in a few
surface particles; the count is in the JSON and the test bounds it).
"""
import argparse
import json
import math
import os
import time

import numpy as np
from mpi4py import MPI
from dolfinx import mesh as dmesh

import fenicsmpm as fm
from fenicsmpm.collective import gmax, gmax_of, gmin_of, gsum
from fenicsmpm.contact.penalty import line
from fenicsmpm.io import particle_raster, raster_shape
from fenicsmpm.materials.hypoplastic import geostatic

comm = MPI.COMM_WORLD
R_SOIL, H_SOIL = 5.0, 10.0                 # soil body: radius 5 m, depth 10 m (seed §4.2.1)
R_PILE, L_PILE = 0.15, 5.0                 # pile radius and length; tip rounded (hemisphere)
RHO_SOIL, E_0 = 2600.0, 0.65
# seed 004 Table 4.1 (= Table 3.1) in SI: h_s = 5.8E6 kPa = 5.8e9 Pa, p_t = 1.6 kPa
TABLE_4_1 = dict(phi_c=30.0, h_s=5.8e9, n=0.28, e_d0=0.53, e_c0=0.84, e_i0=1.0, alpha=0.13,
                 beta=1.0, m_R=10.0, m_T=2.0, R=5e-5, beta_r=0.3, chi=1.0, p_t=1600.0)
E_PILE, NU_PILE, RHO_PILE = 100e6, 0.28, 2500.0
G = 10.0
MU = 0.2
Q_BLOW, T_ON, T_PERIOD = 1.0e6, 0.1, 0.5   # hammer: 1000 kPa for 0.1 s every 0.5 s (Fig 4.2)
P_MAX = 3.0e5                              # pressure of the soil's P-wave speed (time step)
R_FINE, Z_FINE = 0.6, 3.0                  # graded mesh (--grade): cells of size h for r < R_FINE
                                           # and z > H_SOIL - Z_FINE
GRADE_RATIO = 1.2                          # growth of the cells outside that zone
SOIL, PILE = 0, 1


def graded_nodes(length, fine_lo, fine_hi, h, h_far, ratio=GRADE_RATIO):
    """Grid lines on [0, length]: spacing h on [fine_lo, fine_hi] (a multiple of h from an end
    of the interval that it touches), growing by `ratio` a cell outside it up to h_far, then
    uniform; the coarse runs are stretched to end exactly at 0 and `length` (h_far > h)."""
    if not h_far > h:
        raise ValueError(f"graded_nodes: 'h_far' must be larger than h = {h:g}, got {h_far!r}")

    def run(gap):                   # spacings away from the fine zone, covering `gap` metres
        ds, s, d = [], 0.0, h
        while gap - s > 1e-9 * length:
            d = min(d * ratio, h_far)
            ds.append(d)
            s += d
        if not ds:
            return np.zeros(0)
        ds = np.array(ds)
        return ds * gap / ds.sum()
    lo, hi = max(fine_lo, 0.0), min(fine_hi, length)
    n_fine = int(round((hi - lo) / h))
    if lo == 0.0:
        hi = n_fine * h
    else:
        lo = hi - n_fine * h
    below = run(lo)[::-1]
    above = run(length - hi)
    steps = np.concatenate([below, np.full(n_fine, h), above])
    x = np.concatenate([[0.0], np.cumsum(steps)])
    x[-1] = length
    return x


def pile_outline(spacing):
    """The pile's boundary polyline for penalty contact, the pile on its left (counter-
    clockwise in (r, z)): from the tip on the axis round the hemispherical tip, up the shaft,
    across the head back to the axis; vertices about `spacing` apart."""
    z_c, top = H_SOIL + R_PILE, H_SOIL + L_PILE
    n_arc = max(4, int(math.ceil(0.5 * math.pi * R_PILE / spacing)))
    a = np.linspace(0.0, 0.5 * math.pi, n_arc + 1)
    arc = np.column_stack([R_PILE * np.sin(a), z_c - R_PILE * np.cos(a)])
    shaft = line((R_PILE, z_c), (R_PILE, top), max(1, int(math.ceil((top - z_c) / spacing))))
    head = line((R_PILE, top), (0.0, top), max(1, int(math.ceil(R_PILE / spacing))))
    return np.concatenate([arc, shaft[1:], head[1:]])


def penalty_stiffness(soil, pile, h):
    """k_n = M / h (force per unit area per unit penetration), M the larger constrained
    modulus of the two bodies: the sand's at p_max (the bound dt="auto" uses) and the pile's
    (contact.penalty, "Stability": the springs then keep the elastic wave step)."""
    return max(soil.constrained_modulus(P_MAX), pile.constrained_modulus) / h


def build(h, start="ramp", t_gravity=2.0, per_cell=2, gap=None, normal="max-gradient",
          shape="auto", h_far=None, contact="multi-velocity"):
    """Mesh, particles and simulation; gravity ramped over t_gravity ("ramp", seed) or a K0
    state with gravity on from t = 0 ("geostatic"); shape: Simulation(shape=...). h_far: a
    graded mesh (graded_nodes), cells of size h for r < R_FINE and z > H_SOIL - Z_FINE (the
    pile, the soil around it and below its tip), growing to h_far outside; None: uniform.
    contact: "multi-velocity" (with gap and normal) or "penalty" (pile_outline against the
    sand's surface line, k_n = penalty_stiffness)."""
    if contact not in ("multi-velocity", "penalty"):
        raise ValueError(f"build: 'contact' must be 'multi-velocity' or 'penalty', got {contact!r}")
    head = 1.0                                                      # headroom above the pile
    top = H_SOIL + L_PILE + head
    if h_far is None:
        nr, nz = int(round(R_SOIL / h)), int(round(top / h))
        rs, zs = np.arange(nr + 1) * h, np.arange(nz + 1) * h
        msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [nr * h, nz * h]], [nr, nz],
                                     dmesh.CellType.quadrilateral)
    else:
        rs = graded_nodes(R_SOIL, 0.0, R_FINE, h, h_far)
        zs = graded_nodes(top, H_SOIL - Z_FINE, top, h, h_far)
        nr, nz = len(rs) - 1, len(zs) - 1
        msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [float(nr), float(nz)]], [nr, nz],
                                     dmesh.CellType.quadrilateral)
        xg = msh.geometry.x                 # the unit lattice mapped onto the grid lines
        xg[:, 0] = np.interp(xg[:, 0], np.arange(nr + 1), rs)
        xg[:, 1] = np.interp(xg[:, 1], np.arange(nz + 1), zs)
    grid = fm.Grid(msh, axisymmetric=True)
    soil = fm.Hypoplastic(**TABLE_4_1, density=RHO_SOIL, e_0=E_0, p_max=P_MAX)
    pile = fm.LinearElastic(E=E_PILE, nu=NU_PILE, density=RHO_PILE)

    def in_pile(x):
        r, z = x[:, 0], x[:, 1]
        shaft = (r < R_PILE) & (z >= H_SOIL + R_PILE) & (z < H_SOIL + L_PILE)
        tip = r ** 2 + (z - H_SOIL - R_PILE) ** 2 < R_PILE ** 2       # rounded (hemispherical) tip
        return shaft | (tip & (z > H_SOIL))

    p = (fm.Particles.fill(grid, soil, per_cell=per_cell, region=lambda x: x[:, 1] < H_SOIL)
         + fm.Particles.fill(grid, pile, per_cell=per_cell, region=in_pile))
    if start == "geostatic":                   # K0 = 1 - sin phi_c, e = e_0; the pile unstressed
        geostatic(p, soil, G, surface=lambda x: np.full(len(x), H_SOIL))
        p.stress[p.material_id == PILE] = 0.0
    if contact == "penalty":            # seed eqs 2.40-2.53: the pile's outline and the sand's surface
        integ = fm.ExplicitContact(scheme="MUSL", mu=MU, algorithm="penalty",
                                   penalty=dict(k_n=penalty_stiffness(soil, pile, h)))
        # both lines on the particle domains' faces: the sand's top particle row and the
        # pile's lowest particle (on a grid whose lines miss z = H_SOIL both lie off it, alike)
        spacing = h / per_cell
        soil_top = gmax_of(comm, p.x[p.material_id == SOIL, 1]) + 0.5 * spacing
        pile_bottom = gmin_of(comm, p.x[p.material_id == PILE, 1]) - 0.5 * spacing
        integ.add_polyline(PILE, pile_outline(spacing) + [0.0, pile_bottom - H_SOIL])
        r_out = float(rs[-1])                     # the grid's outer side (R_SOIL to a cell)
        integ.add_polyline(SOIL, line((r_out, soil_top), (0.0, soil_top),
                                      int(math.ceil(r_out / spacing))))
    else:
        integ = fm.ExplicitContact(scheme="MUSL", mu=MU, gap=gap, normal=normal)
    # gravity_ramp T: g grows over T/2 (seed 002 eq 4.13), so T = 2 t_gravity
    sim = fm.Simulation(grid, p, integ, dt="auto", cfl=0.5, gravity=(0.0, -G),
                        gravity_ramp=2 * t_gravity if start == "ramp" else None, shape=shape)
    tol = 1e-6 * h
    sim.fix(lambda x: np.abs(x[:, 1]) < tol)                            # bottom fixed
    sim.fix(lambda x: np.abs(x[:, 0] - rs[-1]) < tol, [0])             # outer side on rollers
    return sim, soil, (rs, zs)


def surface_settlement(x, u, soil, r_min, h):
    """The mean settlement -u_z of the sand's top particle row at r > r_min (collective),
    chosen by where the particles started, x - u (by their current height a surface that
    settled more than a quarter cell would drop out of the selection)."""
    x0 = x - u
    top0 = gmax_of(comm, x0[soil, 1])
    far = soil & (x0[:, 0] > r_min) & (x0[:, 1] > top0 - 0.25 * h)
    return -gsum(comm, u[far, 1].sum()) / max(gsum(comm, far.sum()), 1)


def hammer(t0, period=T_PERIOD):
    """Whether the hammer load q is on at time t: for T_ON in every period from t0 (Fig 4.2)."""
    def on(t):
        s = t - t0
        return s >= 0.0 and (s % period) < T_ON - 1e-12
    return on


def trace(h, t_end, contact="penalty", h_far=0.3, every=600):
    """Diagnostic of the first blow (docstring, "Penalty contact"): build(h, "geostatic", 0.2,
    contact, h_far), then the blow as one particle load q pi R^2 (per radian q R^2 / 2) shared
    by the pile's head row (not per annulus as main); every `every` steps after t = 0.25 s
    prints (rank 0) the pile's lowest particle, the sand's highest particle within 0.04 m of
    the axis (below that + 0.3 m) and, with penalty contact, the lowest pile vertex and the
    sand's surface vertex on the axis. Collective."""
    sim, _, _ = build(h, "geostatic", 0.2, contact=contact, h_far=h_far)
    p = sim.particles
    pile = p.material_id == PILE
    p.add_field("head")[:] = pile & (p.x[:, 1] > gmax_of(comm, p.x[pile, 1]) - 0.25 * h)
    on = hammer(0.2)
    sim.add_particle_load(lambda x: sim.particles.head > 0,
                          lambda t: (0.0, -Q_BLOW * R_PILE ** 2 / 2 if on(t) else 0.0))
    n_pile = len(pile_outline(h / 2))            # the pile's vertices come first (build)

    def show(s):
        if s.t < 0.25:
            return
        q = s.particles
        tip = gmin_of(comm, q.x[q.material_id == PILE, 1])
        axis = (q.material_id == SOIL) & (q.x[:, 0] < 0.04) & (q.x[:, 1] < tip + 0.3)
        out = (f"t = {s.t:.4f} s: pile's lowest particle z = {tip:.4f} m, the sand's highest "
               f"at the axis {gmax_of(comm, q.x[axis, 1]):.4f} m")
        if contact == "penalty":
            xv = s.integrator.checkpoint_state()["penalty_x"]     # replicated
            out += (f", lowest pile vertex {xv[:n_pile, 1].min():.4f} m, the sand's vertex on "
                    f"the axis {xv[-1, 1]:.4f} m")
        if comm.rank == 0:
            print(out, flush=True)
    sim.observe(show, every=every)
    sim.run(t_end=t_end, progress=None)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/pile_driving", help="output directory")
    parser.add_argument("--quick", action="store_true",
                        help="h = 0.3 m, K0 start, 0.1 s settling, 2 blows every 0.25 s, gap "
                             "check 0 (test)")
    parser.add_argument("--h", type=float, default=None,
                        help="cell size [m] (near the pile with --grade; default 0.15, "
                             "--quick 0.3)")
    parser.add_argument("--grade", type=float, default=None, metavar="H_FAR",
                        help="graded mesh: cells of size h near the pile (r < %g m, z > %g m), "
                             "growing by %g a cell to H_FAR outside (default: uniform h)"
                             % (R_FINE, H_SOIL - Z_FINE, GRADE_RATIO))
    parser.add_argument("--per-cell", type=int, default=2, help="particles per cell and direction")
    parser.add_argument("--blows", type=int, default=None, help="hammer blows (default 2)")
    parser.add_argument("--start", choices=("ramp", "geostatic"), default=None,
                        help="geostatic (default): K0 stress and e_0 with gravity on, the pile "
                             "settles for --t-gravity (0.2 s); ramp: gravity ramped over "
                             "--t-gravity (2 s, the seed)")
    parser.add_argument("--t-gravity", type=float, default=None, help="gravity stage [s]")
    parser.add_argument("--period", type=float, default=None, help="blow period [s] (0.5)")
    parser.add_argument("--gap", type=float, default=None,
                        help="gap check of fm.ExplicitContact in cells; < 0: none, the plain "
                             "detection of seed eqs 2.34-2.39 (default; --quick: 0)")
    parser.add_argument("--contact", choices=("multi-velocity", "penalty"), default="multi-velocity",
                        help="pile-soil contact: multi-velocity (seed eqs 2.34-2.39, default) or "
                             "penalty node-to-segment (eqs 2.40-2.53) between the pile's outline "
                             "and the sand's surface")
    parser.add_argument("--normal", choices=("max-gradient", "average"), default="max-gradient",
                        help="contact normal of fm.ExplicitContact")
    parser.add_argument("--shape", default="auto",
                        help="shape family, Simulation(shape=...) (default auto: the standard "
                             "family for hypoplastic sand; e.g. cpgimp)")
    args = parser.parse_args(argv)
    h = args.h or (0.3 if args.quick else 0.15)
    if args.grade is not None and not args.grade > h:
        parser.error(f"--grade (the far cell size) must be larger than --h = {h:g}, got {args.grade:g}")
    blows = args.blows if args.blows is not None else 2
    start = args.start or "geostatic"
    t_grav = args.t_gravity or (2.0 if start == "ramp" else (0.1 if args.quick else 0.2))
    period = args.period or (0.25 if args.quick else T_PERIOD)
    gap = args.gap if args.gap is not None else (0.0 if args.quick else -1.0)
    sim, soil, (rs, zs) = build(h, start, t_grav, per_cell=args.per_cell,
                                gap=None if gap < 0 else gap, normal=args.normal,
                                shape=args.shape, h_far=args.grade, contact=args.contact)
    p = sim.particles
    pile = p.material_id == PILE
    mass0 = gsum(comm, p.mass.sum())
    ztop = gmax_of(comm, p.x[pile, 1])
    ztip = gmin_of(comm, p.x[pile, 1])
    p.add_field("head")[:] = pile & (p.x[:, 1] > ztop - 0.25 * h)
    p.add_field("tip")[:] = pile & (p.x[:, 1] < ztip + 0.25 * h)
    n_head = gsum(comm, p.head.sum())
    n_pile = gsum(comm, pile.sum())
    hist = []

    def uz(field):
        sel = getattr(sim.particles, field) > 0
        return gsum(comm, sim.particles.u[sel, 1].sum()) / gsum(comm, sel.sum())

    def record(s):
        q = s.particles
        fc = s.integrator.contact_force
        own = s.grid.n_owned_nodes
        pl = q.material_id == PILE
        zt = gmin_of(comm, q.x[pl, 1])
        f = fc[:own, PILE, 1] if fc is not None else np.zeros(own)
        at_tip = s.grid.node_x[:own, 1] < zt + 0.5 * h
        hist.append((s.t, uz("head"), uz("tip"),
                     2 * math.pi * gsum(comm, f.sum()), 2 * math.pi * gsum(comm, f[at_tip].sum())))

    sim.observe(record, every=5)     # u: displacement since t = 0 (never reset)
    t0 = time.perf_counter()
    sim.run(t_end=t_grav, progress=None)
    # after gravity: pile settlement and the vertical stress at the base
    soil_p = p.material_id == SOIL
    settle_head, settle_tip = -uz("head"), -uz("tip")
    base = soil_p & (p.x[:, 1] < 0.5 * zs[1])              # the bottom cell row
    sv_base = gsum(comm, p.stress[base, 1, 1].sum()) / gsum(comm, base.sum())
    sv_exact = -RHO_SOIL * G * (H_SOIL - gsum(comm, p.x[base, 1].sum()) / gsum(comm, base.sum()))
    settle_surface = surface_settlement(p.x, p.u, soil_p, rs[-2], h)
    # hammer blows (the pile head load follows the head particles)
    t_b = sim.t
    on = hammer(t_b, period)
    rs = np.unique(np.round(p.x[p.head > 0, 0], 9))
    # the radii of the head row: a few values (one per particle column of the pile, bounded
    # by that row, not by the particle count), so every rank may hold them all
    rs = np.unique(np.concatenate(comm.allgather(rs)))
    edges = np.concatenate([[0.0], 0.5 * (rs[1:] + rs[:-1]), [R_PILE]])
    for k, r in enumerate(rs):      # one load per radial column: q on its annulus, per radian
        f = Q_BLOW * (edges[k + 1] ** 2 - edges[k] ** 2) / 2
        sim.add_particle_load(lambda x, r=r: (sim.particles.head > 0) & (np.abs(x[:, 0] - r) < 1e-6),
                              lambda t, f=f: (0.0, -f if on(t) else 0.0))
    per_blow = []
    for k in range(blows):
        sim.run(t_end=t_b + (k + 1) * period, progress=None)
        per_blow.append(-uz("head"))
    wall = gmax(comm, time.perf_counter() - t0)
    ht = np.array(hist)
    pen = list(np.diff([settle_head] + per_blow))
    blow_res = []
    for k in range(blows):
        w = (ht[:, 0] > t_b + k * period) & (ht[:, 0] <= t_b + k * period + T_ON + 1e-9)
        i = np.argmax(ht[w, 3]) if np.any(w) else None
        blow_res.append(dict(total=float(ht[w, 3][i]), tip=float(ht[w, 4][i]),
                             shaft=float(ht[w, 3][i] - ht[w, 4][i]),
                             mean_total=float(ht[w, 3].mean()), mean_tip=float(ht[w, 4].mean()))
                        if i is not None else {})
    # void ratio after the blows
    soil_p = p.material_id == SOIL
    e = p.state[soil_p, 0]
    pr = np.maximum(-np.trace(p.stress[soil_p], axis1=1, axis2=2) / 3.0, 0.0)
    ed, ec, ei = soil.characteristic_void_ratios(pr)
    on_pile = p.material_id == PILE
    zt = gmin_of(comm, p.x[on_pile, 1])
    near = (p.x[soil_p, 0] < 1.0) & (np.abs(p.x[soil_p, 1] - zt) < 1.0)
    finite = (np.all(np.isfinite(p.stress)) and np.all(np.isfinite(p.x))
              and np.all(np.isfinite(p.state[soil_p])))
    res = dict(h=h, h_far=args.grade, per_cell=args.per_cell, shape=sim.shape, contact=args.contact,
               gap=gap if args.contact == "multi-velocity" else None, start=start,
               t_gravity=t_grav, blows=blows,
               period=period, dt=sim.dt,
               steps=sim.step_count, wall_s=wall, n_particles=p.n_global(),
               n_head_particles=int(n_head), n_pile_particles=int(n_pile),
               settlement_head_gravity=settle_head, settlement_tip_gravity=settle_tip,
               settlement_surface_far=settle_surface,
               sigma_v_base=sv_base, sigma_v_base_exact=sv_exact,
               head_settlement_after_blow=per_blow, penetration_per_blow=pen,
               resistance_peak=blow_res,
               e_min=gmin_of(comm, e), e_max=gmax_of(comm, e),
               e_min_near_tip=gmin_of(comm, e[near]),
               e_max_near_tip=gmax_of(comm, e[near]),
               n_below_e_d=int(gsum(comm, np.count_nonzero(e < ed * (1 - 1e-6)))),
               n_above_e_i=int(gsum(comm, np.count_nonzero(e > ei * (1 + 1e-6)))),
               e_d_min=gmin_of(comm, ed),
               mass_change=gsum(comm, p.mass.sum()) / mass0 - 1.0,
               finite=bool(comm.allreduce(bool(finite), op=MPI.LAND)),
               projections=int(gsum(comm, soil.stats[1])),
               # penalty: polyline vertices with no mass of their body around them (W_v = 0 in
               # contact.penalty: they stop moving and drop out of the detection)
               penalty_idle_vertices=(sim.integrator.penalty_stats["idle_vertices"]
                                      if args.contact == "penalty" else None),
               history=ht.tolist())
    # the void ratio near the pile for the plot: rasters of squares of 1.5 particle spacings
    # (the soil's mean e, the pile's cells in black)
    bounds = ((0.0, 2.0), (H_SOIL - 4.0, H_SOIL + 1.0))
    shape = raster_shape(bounds, 1.5 * h / args.per_cell)
    on_soil = p.material_id == SOIL
    e_r = particle_raster(comm, p.x[on_soil], p.state[on_soil, 0], bounds, shape)
    pile_r = particle_raster(comm, p.x[~on_soil], None, bounds, shape, reduce="count")
    if comm.rank != 0:
        return res
    print(f"pile driving (h = {h:g} m, {res['n_particles']} particles, shape {sim.shape}, "
          f"{args.contact} contact, "
          f"{start} start, {sim.step_count} steps of {sim.dt:.3g} s, {wall:.0f} s wall)")
    print(f"{'quantity':44s} {'here':>12s} {'seed 004':>12s}")
    print(f"{'pile-head settlement after gravity [m]':44s} {settle_head:12.3f} {'0.25':>12s}")
    print(f"{'pile-tip settlement after gravity [m]':44s} {settle_tip:12.3f} {'':>12s}")
    print(f"{'far-field surface settlement [m]':44s} {settle_surface:12.3f} {'':>12s}")
    print(f"{'sigma_zz at the base after gravity [kPa]':44s} {sv_base / 1e3:12.1f} {'-170':>12s}")
    print(f"{'  rho g (H - z) there [kPa]':44s} {sv_exact / 1e3:12.1f} {'':>12s}")
    for k in range(blows):
        b = blow_res[k]
        print(f"{f'blow {k + 1}: penetration [m]':44s} {pen[k]:12.3f} {'~0.11':>12s}")
        if b:
            print(f"{f'  peak resistance total/tip/shaft [kN]':44s} {b['total'] / 1e3:12.1f} "
                  f"{b['tip'] / 1e3:7.1f} / {b['shaft'] / 1e3:.1f}")
    print(f"{'void ratio min near the tip (after blows)':44s} {res['e_min_near_tip']:12.3f} {'0.35':>12s}")
    print(f"{'void ratio max near the tip':44s} {res['e_max_near_tip']:12.3f} {'0.65':>12s}")
    print(f"{'particles with e < e_d(p) / e > e_i(p)':44s} {res['n_below_e_d']:6d} / {res['n_above_e_i']}")
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "pile_driving.json"), "w") as f:
        json.dump(res, f, indent=1)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 3, figsize=(15, 5))
    ax[0].plot(ht[:, 0], -ht[:, 1], label="pile head")
    ax[0].plot(ht[:, 0], -ht[:, 2], label="pile tip")
    ax[0].axvline(t_grav, color="0.6", ls=":")
    ax[0].set_xlabel("t [s]")
    ax[0].set_ylabel("settlement [m]")
    ax[0].legend()
    ax[0].set_title("pile settlement (gravity, then blows)")
    ax[1].plot(ht[:, 0], ht[:, 3] / 1e3, label="total")
    ax[1].plot(ht[:, 0], ht[:, 4] / 1e3, label="tip nodes")
    ax[1].plot(ht[:, 0], (ht[:, 3] - ht[:, 4]) / 1e3, label="shaft nodes")
    ax[1].set_xlabel("t [s]")
    ax[1].set_ylabel("vertical contact force on the pile [kN]")
    ax[1].legend()
    ax[1].set_title("soil resistance")
    extent = (*bounds[0], *bounds[1])
    sc = ax[2].imshow(e_r.T, origin="lower", extent=extent, cmap="jet_r", vmin=0.35, vmax=0.75)
    ax[2].imshow(np.where(pile_r > 0, 0.0, np.nan).T, origin="lower", extent=extent,
                 cmap="gray", vmin=0.0, vmax=1.0)
    ax[2].set_xlim(0, 2.0)
    ax[2].set_ylim(H_SOIL - 4.0, H_SOIL + 1.0)
    ax[2].set_aspect("equal")
    ax[2].set_xlabel("r [m]")
    ax[2].set_ylabel("z [m]")
    ax[2].set_title("void ratio after the blows")
    fig.colorbar(sc, ax=ax[2], extend="both")
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, "pile_driving.png"), dpi=110)
    plt.close(fig)
    return res


if __name__ == "__main__":
    main()
