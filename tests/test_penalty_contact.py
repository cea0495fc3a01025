"""Penalty node-to-segment contact (issue 9; seed 004 eqs 2.40-2.53):
fm.ExplicitContact(algorithm="penalty"), contact.penalty. Serial and under
mpirun -n 2.

- BENCHMARKS C1 at h = 0.4 m (fenicsmpm.bench.contact.incline, k_n = (K + 4G/3)/h of the
  cylinder): centre displacement at t = 1 s within 5 % of the rigid-cylinder answer, rolling
  and slipping.
- Two elastic blocks pressed together without friction slide freely (tangential contact
  force ~ 0) and separate when pulled apart.
- Momentum is conserved to round-off in a frictional collision of two free discs.
- A rigid pusher's polyline moves with its prescribed velocity and pushes a free block.
- Input validation."""
import warnings

import numpy as np
import pytest
from dolfinx import mesh
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.bench.contact import incline
from fenicsmpm.contact.penalty import circle, line, rectangle

comm = MPI.COMM_WORLD


def _grid(L, H, n):
    msh = mesh.create_rectangle(comm, [[0.0, 0.0], [L, H]], [round(L * n), round(H * n)],
                                mesh.CellType.quadrilateral)
    return fm.Grid(msh)


@pytest.mark.parametrize("case, theta, mu", [("rolling", 45.0, 0.495), ("slipping", 60.0, 2.0 / 7.0)])
def test_cylinder_on_incline_penalty_within_5_percent(case, theta, mu):
    """Measured at h = 0.4 m (serial, default cpGIMP and normal dashpot): rolling -2.63 %,
    slipping +0.09 %."""
    r = incline(theta, mu, "penalty", h=0.4, t_end=1.0)
    st = r["sim"].integrator.penalty_stats
    if comm.rank == 0:
        print(f"\nC1 {case}: penalty x = {r['x_end']:.4f} m, exact {r['x_exact']:.4f} m, error "
              f"{r['error']:+.2%}, {st['pairs']} pairs ({st['slipping']} slipping), "
              f"penetration {st['max_penetration'] * 1e3:.2f} mm")
    assert abs(r["sim"].t - 1.0) < r["sim"].dt
    assert 0 < st["pairs"] and st["max_penetration"] < 0.1 * 0.4     # in contact, shallow
    assert abs(r["error"]) < 0.05, (case, r["x_end"], r["x_exact"])


def test_frictionless_blocks_slide_freely_and_separate():
    """The scene of test_contact.py: block B (0.4 m, 1 m/s) on a wider block A (base fixed),
    pressed by 16 kN for 0.1 s, then pulled off by the same load for 0.1 s; rectangular
    polylines 0.025 m apart, k_n = E/h. Frictionless: B keeps vx = 1 m/s (measured 0.9985) and
    the tangential contact force on B is below 1 % of the normal one (measured 0.062 %); pulled,
    B lifts off (measured gap 0.592 m, vy = 10.71 m/s)."""
    grid = _grid(2.0, 1.6, 20)
    matA = fm.LinearElastic(E=1e7, nu=0.3, density=1000.0)
    matB = fm.LinearElastic(E=1e7, nu=0.3, density=1000.0)
    A = fm.Particles.fill(grid, matA, per_cell=2,
                          region=lambda x: (x[:, 0] > 0.2) & (x[:, 0] < 1.8) & (x[:, 1] < 0.4))
    B = fm.Particles.fill(grid, matB, per_cell=2, velocity=(1.0, 0.0),
                          region=lambda x: (x[:, 0] > 0.4) & (x[:, 0] < 0.8)
                          & (x[:, 1] > 0.4) & (x[:, 1] < 0.8))
    p = A + B
    integ = fm.ExplicitContact("MUSL", mu=0.0, algorithm="penalty", penalty=dict(k_n=1e7 / 0.05))
    integ.add_polyline(0, rectangle((0.2, 0.0), (1.8, 0.4), 0.025), closed=True)
    integ.add_polyline(1, rectangle((0.4, 0.4), (0.8, 0.8), 0.025), closed=True)
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
    ux = p.total(q.mass[isB] * q.u[isB, 0]) / mB
    sim.run(t_end=0.2)
    q = sim.particles
    isB = q.material_id == 1
    yB = q.x[isB, 1].min() if isB.any() else np.inf
    yA = q.x[~isB, 1].max() if (~isB).any() else -np.inf
    gap = comm.allreduce(yB, op=MPI.MIN) - comm.allreduce(yA, op=MPI.MAX)
    vy = p.total(q.mass[isB] * q.v[isB, 1]) / mB
    if comm.rank == 0:
        print(f"\npenalty blocks: vx = {vx:.6f}, max |f_t|/max |f_n| = {max(ft) / max(fn):.2e}, "
              f"max f_n = {max(fn):.0f} N, gap after pulling = {gap:.4f} m, vy = {vy:.4f} m/s")
    assert max(fn) > 0.5 * P, max(fn)                        # B was pressed onto A
    assert max(ft) < 1e-2 * max(fn), (max(ft), max(fn))
    assert abs(vx - 1.0) < 0.01, vx
    assert abs(ux - 0.1) < 0.01 * 0.1, ux                    # slid 0.1 m freely
    assert gap > 0.05, gap                                   # separated, not glued
    assert vy > 8.0, vy
    assert integ.penalty_stats["pairs"] == 0


def test_momentum_conserved_in_penalty_collision():
    """Two free elastic discs collide obliquely with mu = 0.3 (no gravity, no supports): the
    total momentum stays at its initial value to round-off and the contact forces on the two
    bodies cancel (measured drift 2.7e-15 serial; force imbalance 4.1e-16), while B's
    x-momentum reverses (measured -393 -> +375 kg m/s: they collided)."""
    grid = _grid(2.0, 1.0, 25)
    m1 = fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)
    m2 = fm.LinearElastic(E=2e6, nu=0.3, density=2000.0)
    c1, c2, r = (0.6, 0.45), (1.2, 0.55), 0.25
    d1 = fm.Particles.fill(grid, m1, per_cell=2, velocity=(2.0, 0.5),
                           region=lambda x: (x[:, 0] - c1[0]) ** 2 + (x[:, 1] - c1[1]) ** 2 < r ** 2)
    d2 = fm.Particles.fill(grid, m2, per_cell=2, velocity=(-1.0, 0.0),
                           region=lambda x: (x[:, 0] - c2[0]) ** 2 + (x[:, 1] - c2[1]) ** 2 < r ** 2)
    p = d1 + d2
    integ = fm.ExplicitContact("MUSL", mu=0.3, algorithm="penalty",
                               penalty=dict(k_n=2.7e6 / 0.04, k_t=1e7))
    integ.add_polyline(0, circle(c1, r, 64), closed=True)
    integ.add_polyline(1, circle(c2, r, 64), closed=True)
    sim = fm.Simulation(grid, p, integ, dt="auto")
    P0 = p.momentum()
    scale = p.total(p.mass * np.linalg.norm(p.v, axis=1))
    drift, f_sum, pairs = 0.0, 0.0, 0
    for _ in range(int(0.25 / sim.dt)):
        sim.step()
        drift = max(drift, float(np.abs(sim.particles.momentum() - P0).max()) / scale)
        fb = integ.body_contact_force
        f_sum = max(f_sum, float(np.abs(fb[0] + fb[1]).max()) / max(np.abs(fb).max(), 1e-300))
        pairs = max(pairs, integ.penalty_stats["pairs"])
    q = sim.particles
    s2 = q.material_id == 1
    p2x = q.total(q.mass[s2] * q.v[s2, 0])
    if comm.rank == 0:
        print(f"\npenalty collision: momentum drift {drift:.2e}, contact force imbalance "
              f"{f_sum:.2e}, B x-momentum {p2x:.2f}, most pairs {pairs}")
    assert pairs > 0
    assert drift < 1e-12, drift
    assert f_sum < 1e-10, f_sum
    assert p2x > 0.0, p2x


def test_rigid_pusher_with_penalty():
    """A rigid block (body 1) driven at 0.5 m/s pushes a free elastic block (frictionless,
    no gravity, 0.4 s): the rigid polyline moves exactly 0.5 t, the pushed block stays ahead
    of the pusher's face and moves on at least 0.45 m/s (measured: polyline error 1.7e-14,
    0.176 m ahead, 0.903 m/s)."""
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
    integ = fm.ExplicitContact("MUSL", mu=0.0, rigid={1: (0.5, 0.0)}, algorithm="penalty",
                               penalty=dict(k_n=1.35e6 / 0.05))
    poly = rectangle((0.2, 0.1), (0.6, 0.5), 0.025)
    integ.add_polyline(0, rectangle((0.6, 0.1), (1.0, 0.5), 0.025), closed=True)
    integ.add_polyline(1, poly, closed=True)
    sim = fm.Simulation(grid, p, integ, dt="auto")
    sim.run(t_end=0.4)
    q = sim.particles
    rig = q.material_id == 1
    pc = integ._penalty
    moved = pc.x[pc.vbody == 1] - poly
    perr = np.abs(moved - np.array([0.5, 0.0]) * sim.t).max()
    face = comm.allreduce(q.x[rig, 0].max() if rig.any() else -np.inf, op=MPI.MAX)
    back = comm.allreduce(q.x[~rig, 0].min() if (~rig).any() else np.inf, op=MPI.MIN)
    vb = q.total(q.mass[~rig] * q.v[~rig, 0]) / q.total(q.mass[~rig])
    fx = integ.body_contact_force
    if comm.rank == 0:
        print(f"\npenalty rigid pusher: polyline |u - v t| = {perr:.2e}, block back - pusher "
              f"face = {back - face:+.4f} m, block velocity {vb:.3f} m/s")
    assert perr < 1e-12, perr
    assert back - face > -0.05, (back, face)
    assert vb > 0.45, vb
    assert np.allclose(fx[0], -fx[1], atol=1e-9 * max(np.abs(fx).max(), 1.0))


def _two_blocks(integ, polylines=True):
    grid = _grid(1.0, 1.0, 10)
    mat = fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)
    mat2 = fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)
    p = (fm.Particles.fill(grid, mat, region=lambda x: x[:, 1] < 0.3)
         + fm.Particles.fill(grid, mat2, region=lambda x: (x[:, 1] > 0.3) & (x[:, 1] < 0.6)))
    if polylines:
        integ.add_polyline(0, rectangle((0.0, 0.0), (1.0, 0.3), 0.05), closed=True)
        integ.add_polyline(1, rectangle((0.0, 0.3), (1.0, 0.6), 0.05), closed=True)
    return fm.Simulation(grid, p, integ, dt="auto")


def test_penalty_input_validation():
    pen = dict(k_n=1e7)
    with pytest.raises(ValueError, match="penalty"):
        fm.ExplicitContact(algorithm="penalty")                       # no k_n
    with pytest.raises(ValueError, match="penalty"):
        fm.ExplicitContact(penalty=pen)                               # not the algorithm
    for bad in (dict(k_n=0.0), dict(k_n=-1.0), dict(k_n=np.inf), dict(k_n=1.0, k_t=-1.0),
                dict(k_n=1.0, damping=-0.1), dict(k_n=1.0, damping=np.nan),
                dict(k_t=1.0), dict(k_n=1.0, kn=2.0), dict(k_n="1")):
        with pytest.raises(ValueError, match="k_n|k_t|penalty"):
            fm.ExplicitContact(algorithm="penalty", penalty=bad)
    with pytest.raises(ValueError, match="only for algorithm='penalty'"):
        fm.ExplicitContact().add_polyline(0, line((0, 0), (1, 0), 4))
    c = fm.ExplicitContact(algorithm="penalty", penalty=pen)
    for body, verts, closed in ((-1, line((0, 0), (1, 0), 2), False),
                                (0, np.zeros((3, 3)), False),              # not 2D
                                (0, [[0.0, 0.0]], False),                  # too few
                                (0, [[0, 0], [1, 0], [1, 0]], False),      # zero-length segment
                                (0, [[0, 0], [1, 0], [2, 0]], True),       # no area
                                (0, [[0, 0], [np.nan, 0]], False)):
        with pytest.raises(ValueError):
            c.add_polyline(body, verts, closed=closed)
    c.add_polyline(0, circle((0, 0), 1.0, 8)[::-1], closed=True)     # clockwise: reversed
    x = c.polylines[0][1]
    assert 0.5 * np.sum(x[:, 0] * np.roll(x[:, 1], -1) - np.roll(x[:, 0], -1) * x[:, 1]) > 0
    for bad in (dict(n=2), dict(radius=0.0)):
        with pytest.raises(ValueError):
            circle((0, 0), **{**dict(radius=1.0, n=8), **bad})
    # a body without a polyline, and a polyline of a body that does not exist
    integ = fm.ExplicitContact(algorithm="penalty", penalty=pen)
    sim = _two_blocks(integ, polylines=False)
    integ.add_polyline(0, rectangle((0.0, 0.0), (1.0, 0.3), 0.05), closed=True)
    with pytest.raises(ValueError, match=r"bodies \[1\] have no polyline"):
        sim.step()
    integ.add_polyline(1, rectangle((0.0, 0.3), (1.0, 0.6), 0.05), closed=True)
    integ.add_polyline(5, rectangle((0.0, 0.3), (1.0, 0.6), 0.05), closed=True)
    with pytest.raises(ValueError, match="polyline of body 5"):
        sim.step()


def test_penalty_stiffness_warning_and_unsupported_grids():
    """k_n far above (K + 4G/3)/h is warned about (dt > sqrt(rho h / k_n)); 3D grids are
    refused."""
    integ = fm.ExplicitContact(algorithm="penalty", penalty=dict(k_n=1e12))
    sim = _two_blocks(integ)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        sim.step()
    if comm.rank == 0:
        assert any("penalty spring" in str(x.message) for x in w), [str(x.message) for x in w]
    assert sim.dt > integ._penalty.dt_penalty
    msh = mesh.create_box(comm, [[0, 0, 0], [1, 1, 1]], [2, 2, 2], mesh.CellType.hexahedron)
    g3 = fm.Grid(msh)
    p3 = fm.Particles.fill(g3, fm.LinearElastic(E=1e6, nu=0.3, density=1000.0))
    with pytest.raises(NotImplementedError, match="2D"):
        fm.Simulation(g3, p3, fm.ExplicitContact(algorithm="penalty", penalty=dict(k_n=1.0)), dt=1e-4)


def test_axisymmetric_rod_on_a_block_with_penalty():
    """Penalty contact on an axisymmetric grid (forces per radian: each vertex stands for a
    ring of area l_s r_s, contact.penalty): an elastic rod (r < 0.2 m, 0.3 m tall, on the
    axis) put on an elastic block under gravity (g = 10) without a preload rings between 0
    and about 2.8 times its weight; averaged over 0.2-0.4 s the contact force equals the
    rod's weight per radian rho g H R^2 / 2 within 5 % (measured 0.982) and the rod does not
    sink (measured 0.26 mm). Without the r_s factor the vertices near the axis kick nodes of
    little mass and the run stops on a blow-up at step 70."""
    R, H0, g, rho, E, nu = 0.2, 0.3, 10.0, 1000.0, 1e7, 0.3
    M = E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
    msh = mesh.create_rectangle(comm, [[0.0, 0.0], [0.5, 1.0]], [10, 20], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh, axisymmetric=True)
    p = (fm.Particles.fill(grid, fm.LinearElastic(E=E, nu=nu, density=rho), per_cell=2,
                           region=lambda x: x[:, 1] < 0.5)
         + fm.Particles.fill(grid, fm.LinearElastic(E=E, nu=nu, density=rho), per_cell=2,
                             region=lambda x: (x[:, 1] > 0.5) & (x[:, 1] < 0.5 + H0) & (x[:, 0] < R)))
    integ = fm.ExplicitContact("MUSL", algorithm="penalty", penalty=dict(k_n=M / 0.05))
    integ.add_polyline(0, line((0.5, 0.5), (0.0, 0.5), 20))
    integ.add_polyline(1, rectangle((0.0, 0.5), (R, 0.5 + H0), 0.025), closed=True)
    sim = fm.Simulation(grid, p, integ, dt="auto", gravity=(0.0, -g))
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0))
    sim.fix(lambda x: np.isclose(x[:, 0], 0.5), [0])
    fy = []
    while sim.t < 0.4:
        sim.step()
        if sim.t > 0.2:
            fy.append(integ.body_contact_force[1][1])
    q = sim.particles
    on = q.material_id == 1
    zmin = comm.allreduce(float(q.x[on, 1].min()) if on.any() else np.inf, op=MPI.MIN)
    ratio = np.mean(fy) / (rho * g * H0 * R ** 2 / 2)
    if comm.rank == 0:
        print(f"\naxisymmetric penalty rod: contact force / weight {ratio:.4f}, sink "
              f"{1e3 * (0.5125 - zmin):.3f} mm")
    assert abs(ratio - 1.0) < 0.05, ratio
    assert 0.5125 - zmin < 0.005, zmin


def test_penalty_restart_is_bit_for_bit(shared_tmp_path):
    """A checkpoint keeps the penalty polylines' state (ExplicitContact.checkpoint_state:
    vertex positions, last displacements, tangential forces): the frictional disc collision
    restarted in the middle of the contact (step 80 of 120; contact from about step 60)
    reproduces the continuous run bit for bit (serial and 2 ranks, compared by particle id)."""
    import os

    from fenicsmpm.partition import strips

    def build():              # one partition for both runs (round-off follows the partition)
        grid = fm.Grid(mesh.create_rectangle(comm, [[0.0, 0.0], [2.0, 1.0]], [50, 25],
                                             mesh.CellType.quadrilateral,
                                             partitioner=strips(50, 25, vertex_ghosts=True)))
        m1 = fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)
        m2 = fm.LinearElastic(E=2e6, nu=0.3, density=2000.0)
        c1, c2, r = (0.6, 0.45), (1.2, 0.55), 0.25
        p = (fm.Particles.fill(grid, m1, per_cell=2, velocity=(2.0, 0.5),
                               region=lambda x: (x[:, 0] - c1[0]) ** 2 + (x[:, 1] - c1[1]) ** 2 < r ** 2)
             + fm.Particles.fill(grid, m2, per_cell=2, velocity=(-1.0, 0.0),
                                 region=lambda x: (x[:, 0] - c2[0]) ** 2 + (x[:, 1] - c2[1]) ** 2 < r ** 2))
        integ = fm.ExplicitContact("MUSL", mu=0.3, algorithm="penalty",
                                   penalty=dict(k_n=2.7e6 / 0.04, k_t=1e7))
        integ.add_polyline(0, circle(c1, r, 64), closed=True)
        integ.add_polyline(1, circle(c2, r, 64), closed=True)
        return fm.Simulation(grid, p, integ, dt="auto")

    path = os.path.join(shared_tmp_path, "ck")
    ref = build()
    ref.run(steps=120)
    first = build()
    first.run(steps=80, checkpoint=path, checkpoint_every=80)
    assert first.integrator.penalty_stats["pairs"] > 0                  # in contact there
    again = fm.Simulation.restart(path, build)
    again.run(steps=40)
    def by_id(p):          # the small scene gathered, sorted by particle id
        rows = np.concatenate(comm.allgather(
            np.column_stack([p.id, p.x, p.v, p.stress.reshape(len(p), 9)])))
        return rows[np.argsort(rows[:, 0])]

    assert np.array_equal(by_id(ref.particles), by_id(again.particles))
    assert np.array_equal(ref.integrator._penalty.x, again.integrator._penalty.x)
