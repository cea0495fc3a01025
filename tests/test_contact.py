"""Contact between bodies (issue 9): fm.ExplicitContact, multi-velocity frictional contact
(seed 004 eqs 2.34-2.39) with rigid bodies. Serial and under mpirun -n 2.

- BENCHMARKS C1, the cylinder on an incline at h = 0.4 m (fenicsmpm.bench.contact.incline):
  centre displacement at t = 1 s within 5 % of the rigid-cylinder answer, rolling
  (45 deg, mu = 0.495) and slipping (60 deg, mu = 2/7); single-field MPM's error is printed.
- Two elastic blocks pressed together without friction slide freely (the sliding block keeps
  its velocity, the tangential contact force is ~0) and separate when pulled apart.
- Momentum is conserved to round-off in a frictional collision of two free bodies.
- A rigid body with prescribed velocity moves exactly with it and pushes a free block."""
import numpy as np
import pytest
from dolfinx import mesh
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.bench.contact import incline

comm = MPI.COMM_WORLD


@pytest.mark.parametrize("case, theta, mu", [("rolling", 45.0, 0.495), ("slipping", 60.0, 2.0 / 7.0)])
def test_cylinder_on_incline_within_5_percent(case, theta, mu):
    """Measured at h = 0.4 m (serial): rolling -2.43 %, slipping +1.26 %; single-field
    -99.2 % and -99.4 % (the cylinder is glued to the plane)."""
    r = incline(theta, mu, "multi-velocity", h=0.4, t_end=1.0)
    single = incline(theta, mu, "single-field", h=0.4, t_end=1.0)
    if comm.rank == 0:
        print(f"\nC1 {case}: multi-velocity x = {r['x_end']:.4f} m, exact {r['x_exact']:.4f} m, "
              f"error {r['error']:+.2%}; single-field error {single['error']:+.2%}")
    assert abs(r["sim"].t - 1.0) < r["sim"].dt
    assert abs(r["error"]) < 0.05, (case, r["x_end"], r["x_exact"])


def _grid(L, H, n):
    msh = mesh.create_rectangle(comm, [[0.0, 0.0], [L, H]], [round(L * n), round(H * n)],
                                mesh.CellType.quadrilateral)
    return fm.Grid(msh)


def test_frictionless_blocks_slide_freely_and_separate():
    """A 0.4 m block B slides at 1 m/s on a wider block A (base fixed), pressed onto it by
    a load of 16 kN (100 m/s^2 on B) for 0.1 s, then pulled off by the same load for 0.1 s.
    Frictionless: B keeps vx = 1 m/s (measured 1.0022) and the net tangential contact force on
    B stays below 1 % of the largest normal one (measured 0.23 %: the corner nodes, where the
    normal is not vertical); pulled, B lifts off (measured gap 0.518 m at t = 0.2 s and
    vy = 10.17 m/s, against 100 m/s^2 x 0.1 s = 10 m/s of free flight plus the elastic
    rebound; glued, it would not move off)."""
    grid = _grid(2.0, 1.6, 20)
    matA = fm.LinearElastic(E=1e7, nu=0.3, density=1000.0)
    matB = fm.LinearElastic(E=1e7, nu=0.3, density=1000.0)
    A = fm.Particles.fill(grid, matA, per_cell=2,
                          region=lambda x: (x[:, 0] > 0.2) & (x[:, 0] < 1.8) & (x[:, 1] < 0.4))
    B = fm.Particles.fill(grid, matB, per_cell=2, velocity=(1.0, 0.0),
                          region=lambda x: (x[:, 0] > 0.4) & (x[:, 0] < 0.8)
                          & (x[:, 1] > 0.4) & (x[:, 1] < 0.8))
    p = A + B                                        # bodies: material_id 0 (A), 1 (B)
    integ = fm.ExplicitContact("MUSL", mu=0.0)
    sim = fm.Simulation(grid, p, integ, dt="auto")
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0))
    P = 16000.0
    sim.add_particle_load(lambda x: (x[:, 1] > 0.75) & (x[:, 0] > 0.4) & (x[:, 0] < 0.8),
                          lambda t: np.array([0.0, -P if t < 0.1 else P]))
    isB = p.material_id == 1
    mB = p.total(p.mass[isB])
    ft, fn = [], []
    while sim.t < 0.1 - 0.5 * sim.dt:
        sim.step()
        f = integ.body_contact_force[1]
        ft.append(abs(f[0]))
        fn.append(abs(f[1]))
    q = sim.particles
    isB = q.material_id == 1
    vx = p.total(q.mass[isB] * q.v[isB, 0]) / mB
    assert max(fn) > 0.5 * P, max(fn)                        # B was pressed onto A
    assert max(ft) < 1e-2 * max(fn), (max(ft), max(fn))
    assert abs(vx - 1.0) < 0.01, vx
    ux = p.total(q.mass[isB] * q.u[isB, 0]) / mB
    assert abs(ux - sim.t) < 0.01 * sim.t, ux                # slid 0.1 m freely
    sim.run(t_end=0.2)
    q = sim.particles
    isB = q.material_id == 1
    yB = q.x[isB, 1].min() if isB.any() else np.inf
    yA = q.x[~isB, 1].max() if (~isB).any() else -np.inf
    gap = comm.allreduce(yB, op=MPI.MIN) - comm.allreduce(yA, op=MPI.MAX)
    vy = p.total(q.mass[isB] * q.v[isB, 1]) / mB
    if comm.rank == 0:
        print(f"\nblocks: vx = {vx:.6f}, max |f_t|/max |f_n| = {max(ft) / max(fn):.2e}, "
              f"gap after pulling = {gap:.4f} m, vy = {vy:.4f} m/s")
    assert gap > 0.05, gap                                   # separated, not glued
    assert vy > 8.0, vy


def test_momentum_conserved_in_frictional_collision():
    """Two free elastic discs collide obliquely with mu = 0.3 (no gravity, no supports): the
    total momentum stays at its initial value to round-off (measured relative drift 2.9e-15,
    contact forces on the two bodies cancel to 5e-14) while B's x-momentum reverses (from
    about -rho pi r^2 = -393 to +342 kg m/s measured: they did collide)."""
    grid = _grid(2.0, 1.0, 25)
    m1 = fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)
    m2 = fm.LinearElastic(E=2e6, nu=0.3, density=2000.0)
    d1 = fm.Particles.fill(grid, m1, per_cell=2, velocity=(2.0, 0.5),
                           region=lambda x: (x[:, 0] - 0.6) ** 2 + (x[:, 1] - 0.45) ** 2 < 0.25 ** 2)
    d2 = fm.Particles.fill(grid, m2, per_cell=2, velocity=(-1.0, 0.0),
                           region=lambda x: (x[:, 0] - 1.2) ** 2 + (x[:, 1] - 0.55) ** 2 < 0.25 ** 2)
    p = d1 + d2
    integ = fm.ExplicitContact("MUSL", mu=0.3)
    sim = fm.Simulation(grid, p, integ, dt="auto")
    P0 = p.momentum()
    scale = p.total(p.mass * np.linalg.norm(p.v, axis=1))
    drift, f_sum = 0.0, 0.0
    for _ in range(int(0.25 / sim.dt)):
        sim.step()
        drift = max(drift, float(np.abs(sim.particles.momentum() - P0).max()) / scale)
        fb = integ.body_contact_force
        f_sum = max(f_sum, float(np.abs(fb[0] + fb[1]).max()) / max(np.abs(fb).max(), 1e-300))
    q = sim.particles
    s2 = q.material_id == 1
    p2x = q.total(q.mass[s2] * q.v[s2, 0])
    if comm.rank == 0:
        print(f"\ncollision: momentum drift {drift:.2e}, contact force imbalance {f_sum:.2e}, "
              f"B x-momentum {p2x:.2f}")
    assert drift < 1e-12, drift
    assert f_sum < 1e-10, f_sum
    assert p2x > 0.0, p2x                 # B (moving at -1 m/s) was pushed back: they collided


def test_rigid_pusher_moves_with_prescribed_velocity():
    """A rigid block (body 1) driven at 0.5 m/s pushes a free elastic block (frictionless,
    no gravity, 0.4 s): the rigid particles move exactly 0.5 t (measured error 0), the pushed
    block does not overlap the pusher's face by more than a cell (measured: 0.10 m ahead
    of it: the particle centres are half a spacing from the faces) and moves on at least
    0.45 m/s (measured 0.881 m/s: the elastic block bounces off the pusher)."""
    grid = _grid(2.0, 0.6, 20)
    soft = fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)
    hard = fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)
    blk = fm.Particles.fill(grid, soft, per_cell=2,
                            region=lambda x: (x[:, 0] > 0.6) & (x[:, 0] < 1.0) & (x[:, 1] > 0.1)
                            & (x[:, 1] < 0.5))
    pusher = fm.Particles.fill(grid, hard, per_cell=2,
                               region=lambda x: (x[:, 0] > 0.2) & (x[:, 0] < 0.6) & (x[:, 1] > 0.1)
                               & (x[:, 1] < 0.5))
    p = blk + pusher
    integ = fm.ExplicitContact("MUSL", mu=0.0, rigid={1: (0.5, 0.0)})
    sim = fm.Simulation(grid, p, integ, dt="auto")
    sim.run(t_end=0.4)
    q = sim.particles
    rig = q.material_id == 1
    err = np.abs(q.u[rig] - np.array([0.5, 0.0]) * sim.t).max() if rig.any() else 0.0
    err = comm.allreduce(err, op=MPI.MAX)
    face = comm.allreduce(q.x[rig, 0].max() if rig.any() else -np.inf, op=MPI.MAX)
    back = comm.allreduce(q.x[~rig, 0].min() if (~rig).any() else np.inf, op=MPI.MIN)
    mb = q.total(q.mass[~rig])
    vb = q.total(q.mass[~rig] * q.v[~rig, 0]) / mb
    if comm.rank == 0:
        print(f"\nrigid pusher: |u - v t| = {err:.2e}, block back - pusher face = "
              f"{back - face:+.4f} m, block velocity {vb:.3f} m/s")
    assert err < 1e-12, err
    assert back - face > -0.05, (back, face)
    assert vb > 0.45, vb


def test_contact_keeps_rollers():
    """A rigid body pushed diagonally onto a block with a roller (u_x = 0) on x = 0, mu = 0.5:
    the contact projection must not give the block's nodes on the roller an x-velocity (issue
    21: it did, up to 0.064 m/s in the footing scene)."""
    grid = _grid(1.0, 1.0, 10)
    mat = fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)
    p = fm.Particles.fill(grid, mat, per_cell=2, region=lambda x: x[:, 1] < 0.7)
    fm.set_body(p, 1, region=lambda x: (x[:, 1] > 0.5) & (x[:, 0] < 0.4))
    integ = fm.ExplicitContact("MUSL", mu=0.5, rigid={1: (-0.05, -0.05)})
    sim = fm.Simulation(grid, p, integ, dt="auto")
    roller = np.isclose(grid.node_x[:, 0], 0.0)
    sim.fix(lambda x: np.isclose(x[:, 0], 0.0), [0])
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0), [1])
    worst = []
    sim.observe(lambda s: worst.append(np.abs(s.nodal["body_velocity"][roller, 0, 0]).max(initial=0.0)))
    sim.run(t_end=0.02)
    assert max(worst) == 0.0, max(worst)


def test_rigid_body_material_does_not_set_the_time_step():
    """dt="auto" follows the deformable bodies only: a rigid body of a stiff material (E 1e12)
    pressing on a soft block (E 1e6) leaves dt = cfl h / c_p(soft) (issue 21)."""
    grid = _grid(1.0, 1.0, 10)
    soft = fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)
    stiff = fm.LinearElastic(E=1e12, nu=0.3, density=1000.0)
    blk = fm.Particles.fill(grid, soft, per_cell=2, region=lambda x: x[:, 1] < 0.5)
    rig = fm.Particles.fill(grid, stiff, per_cell=2, region=lambda x: (x[:, 1] > 0.5) & (x[:, 1] < 0.7))
    sim = fm.Simulation(grid, blk + rig, fm.ExplicitContact("MUSL", rigid={1: (0.0, -0.01)}),
                        dt="auto")
    assert abs(sim.dt / (0.5 * grid.h / soft.p_wave_speed) - 1) < 1e-12, sim.dt
    sim.run(steps=5)
    sim2 = fm.Simulation(grid, blk + rig, fm.ExplicitContact("MUSL"), dt="auto")   # both deform
    assert abs(sim2.dt / (0.5 * grid.h / stiff.p_wave_speed) - 1) < 1e-12, sim2.dt


@pytest.mark.parametrize("gap, limit", [(0.0, 0.12), (None, 0.002)])
def test_axisymmetric_rod_rests_on_a_block(gap, limit):
    """Axisymmetric contact (issue 18): an elastic rod of radius 0.1 m (the first cell column,
    on the axis) standing on an elastic block under gravity (g = 10, 0.2 s; free fall would be
    0.2 m). The gap check's particle half-sizes now come from the meridian area V_p / r_p;
    with V_p^(1/2) / 2 (V_p per radian) they were too small near the axis, the check saw a
    gap everywhere and the rod fell through the block (sank 0.194 m). With the default gap
    check (gap = 0) the rod still creeps into the block, 0.082 m (0.047 m in plane strain: a
    limitation of the position-based check for a body one cell wide, not specific to the
    axis); the plain detection (gap=None, seed eqs 2.34-2.39) holds it (< 1 mm)."""
    msh = mesh.create_rectangle(comm, [[0.0, 0.0], [0.5, 1.0]], [5, 10], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh, axisymmetric=True)
    mat = fm.LinearElastic(E=1e7, nu=0.3, density=1000.0)
    rod = fm.LinearElastic(E=1e7, nu=0.3, density=1000.0)
    p = (fm.Particles.fill(grid, mat, per_cell=2, region=lambda x: x[:, 1] < 0.5)
         + fm.Particles.fill(grid, rod, per_cell=2,
                             region=lambda x: (x[:, 1] > 0.5) & (x[:, 1] < 0.8) & (x[:, 0] < 0.1)))
    sim = fm.Simulation(grid, p, fm.ExplicitContact("MUSL", gap=gap), dt="auto",
                        gravity=(0.0, -10.0))
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0))
    sim.fix(lambda x: np.isclose(x[:, 0], 0.5), [0])
    sim.run(t_end=0.2)
    on_rod = p.material_id == 1
    zmin = comm.allreduce(float(p.x[on_rod, 1].min()) if np.any(on_rod) else np.inf, op=MPI.MIN)
    sink = 0.525 - zmin
    assert sink < limit, f"rod tip sank {sink:.4f} m"


def _dropped_block(half, interface):
    """An elastic block (0.6 m wide, E 1e7) moving down at 0.5 m/s onto an elastic layer
    (E 1e6, 0.8 m deep) on h = 0.1 m cells, as the half model (x >= 0, roller on x = 0) or
    whole; returns the block's mean vertical velocity every step to t = 0.15 s."""
    w = 1.0
    msh = mesh.create_rectangle(MPI.COMM_WORLD, [[0.0 if half else -w, 0.0], [w, 1.4]],
                                [10 if half else 20, 14], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    soil = fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)
    blk = fm.LinearElastic(E=1e7, nu=0.3, density=2000.0)
    p = (fm.Particles.fill(grid, soil, per_cell=2, region=lambda x: x[:, 1] < 0.8)
         + fm.Particles.fill(grid, blk, per_cell=2,
                             region=lambda x: (x[:, 1] > 0.8) & (x[:, 1] < 1.2)
                             & (np.abs(x[:, 0]) < 0.3)))
    top = p.material_id == 1
    p.v[top, 1] = -0.5
    sim = fm.Simulation(grid, p, fm.ExplicitContact("MUSL", interface=interface), dt=2e-4)
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0))
    sim.fix(lambda x: np.isclose(np.abs(x[:, 0]), w) | (np.isclose(x[:, 0], 0.0) if half
                                                           else np.zeros(len(x), bool)), [0])
    vy = []

    def record(s):
        q = s.particles
        b = q.material_id == 1
        vy.append(q.total(np.column_stack([q.mass[b] * q.v[b, 1], q.mass[b]])))
    sim.observe(record, every=1)
    sim.run(t_end=0.15, progress=False)
    return np.array([m / mass for m, mass in vy])


def test_half_model_of_deformable_contact_equals_the_whole():
    """Node-wise contact between deformable bodies (the default interface) treats a symmetry
    line's roller as a mirror: its normal there is the mirror-symmetric one, so a block
    dropped on a layer moves the same as a half model and whole (to 1e-6 m/s; measured
    1.3e-8, round-off); with interface="node" (the diagonal mass-gradient normal, the roller
    keeping part of the correction) the half model's block differs from the whole."""
    half, whole = _dropped_block(True, "auto"), _dropped_block(False, "auto")
    node = _dropped_block(True, "node")
    d_auto, d_node = np.abs(half - whole).max(), np.abs(node - whole).max()
    print(f"\nblock dropped on a layer, |half - whole|: {d_auto:.2e} m/s, node-wise {d_node:.2e}")
    assert half.max() > -0.4, half.max()                  # the block hits the layer
    assert d_auto < 1e-6, d_auto
    assert d_node > 1e-3, d_node
