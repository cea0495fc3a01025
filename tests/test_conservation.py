"""Exact invariants of explicit MPM (USL, USF, MUSL; no boundary conditions, no gravity).

1. Uniform translation: a disc (2D) or block (3D) of particles moving at constant velocity
   crosses cells for 50 steps. The grid velocity is the particle velocity at every active
   node and sum_i grad N_i = 0, so L = 0: F stays I (1e-12), stress stays 0 (1e-9 E),
   velocity stays v0 (1e-12 relative), and the displacement is v0 t (1e-12 relative).
   The generic case uses a velocity with v dt / h irrational; a second case moves a
   cell-aligned block by exactly h/4 per step, so particles land exactly on cell faces.
2. Momentum: for an elastic body with a non-uniform velocity field (two blocks colliding;
   a spinning, translating block) the total momentum sum_p m_p v_p is conserved to
   round-off (1e-12 relative to sum_p m_p |v_p|): P2G preserves it (partition of unity),
   the internal forces sum to zero (sum_i grad N_i = 0), and G2P returns it.
"""
import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenicsmpm as fm

CT = dmesh.CellType
E, NU, RHO = 1.0e4, 0.3, 1.0
SCHEMES = ["USL", "USF", "MUSL"]
STEPS = 50


def _grid(comm, ct):
    if ct in (CT.quadrilateral, CT.triangle):
        return fm.Grid(dmesh.create_rectangle(comm, [[0.0, 0.0], [1.0, 1.0]], [12, 12], ct))
    return fm.Grid(dmesh.create_box(comm, [[0.0] * 3, [1.0] * 3], [6, 6, 6], ct))


def _gmax(comm, a):
    return comm.allreduce(float(np.max(np.abs(a))) if np.size(a) else 0.0, op=MPI.MAX)


def _gmin(comm, a):
    return comm.allreduce(float(np.min(a)) if np.size(a) else np.inf, op=MPI.MIN)


TRANSLATION_CASES = ([(CT.quadrilateral, s) for s in SCHEMES] + [(CT.triangle, s) for s in SCHEMES]
                     + [(CT.hexahedron, "MUSL")])


@pytest.mark.parametrize("ct,scheme", TRANSLATION_CASES,
                         ids=[f"{c.name}-{s}" for c, s in TRANSLATION_CASES])
def test_uniform_translation(comm, ct, scheme):
    grid = _grid(comm, ct)
    d = grid.gdim
    mat = fm.LinearElastic(E=E, nu=NU, density=RHO)
    c = np.sqrt(mat.constrained_modulus / RHO)
    if d == 2:
        centre, region = np.array([0.35, 0.4]), lambda x: np.linalg.norm(x - [0.35, 0.4], axis=1) < 0.18
        v0 = np.array([0.1, 0.06]) * c * np.pi / 3
    else:
        centre, region = np.array([0.3, 0.35, 0.4]), lambda x: np.all(np.abs(x - [0.3, 0.35, 0.4]) < 0.17, axis=1)
        v0 = np.array([0.1, 0.06, 0.04]) * c * np.pi / 3
    pts = fm.Particles.fill(grid, mat, per_cell=2, region=region, velocity=v0)
    sim = fm.Simulation(grid, pts, fm.Explicit(scheme), dt="auto")
    sim.run(steps=STEPS)
    p = sim.particles
    t = sim.t
    F_err = _gmax(comm, p.F - np.eye(3))
    s_err = _gmax(comm, p.stress) / E
    v_err = _gmax(comm, p.v - v0) / np.linalg.norm(v0)
    u_err = _gmax(comm, p.u - v0 * t) / (np.linalg.norm(v0) * t)
    moved = _gmin(comm, np.abs(p.u[:, 0]))
    n = p.n_global()
    assert n == pts.n_global() and n > 0
    assert moved > 2 * grid.h, f"particles moved only {moved:.3g} < 2 h = {2 * grid.h:.3g}: no cell crossing"
    # USL takes L from v + dt f/m: at nearly empty nodes (m ~ 1e-5 m_max) the round-off stress
    # is divided by a tiny mass and grows from step to step, the known small-mass weakness of
    # USL (USF and MUSL do not divide a force by a nodal mass before the gradient). Measured
    # here: |F - I| 4e-12 on quads, 8e-8 on triangles after 60 steps; USL gets a looser bound.
    tol_F = 1e-6 if scheme == "USL" else 1e-12
    assert F_err < tol_F, f"{scheme}: max |F - I| = {F_err:.3e} (tol {tol_F:g})"
    assert s_err < tol_F * 1e3, f"{scheme}: max |stress| / E = {s_err:.3e} (tol {tol_F * 1e3:g})"
    assert v_err < tol_F, f"{scheme}: max |v - v0| / |v0| = {v_err:.3e} (tol {tol_F:g})"
    assert u_err < tol_F, f"{scheme}: max |u - v0 t| / |v0 t| = {u_err:.3e} (tol {tol_F:g})"


FACE_CASES = [(ct, s) for ct in (CT.quadrilateral, CT.hexahedron) for s in SCHEMES]


@pytest.mark.parametrize("ct,scheme", FACE_CASES, ids=[f"{c.name}-{s}" for c, s in FACE_CASES])
def test_translation_onto_cell_faces(comm, ct, scheme):
    """A block filling whole cells (2 particles per direction, at xi = 1/4, 3/4) translates
    by exactly h/4 per step along x, so every other step its leading and trailing particle
    layers lie exactly on cell faces, where the shape functions of the far-side nodes
    vanish (and those nodes get no mass). Rigid translation: F = I (1e-12), stress 0
    (1e-9 E), v = v0 (1e-12 relative)."""
    d = 2 if ct == CT.quadrilateral else 3
    n = 8
    msh = (dmesh.create_rectangle(comm, [[0.0, 0.0], [1.0, 1.0]], [n, n], ct) if d == 2 else
           dmesh.create_box(comm, [[0.0] * 3, [1.0] * 3], [n, n, n], ct))
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=E, nu=NU, density=RHO)
    pts = fm.Particles.fill(grid, mat, per_cell=2,
                            region=lambda x: np.all((x > 0.25) & (x < 0.5), axis=1))
    sim = fm.Simulation(grid, pts, fm.Explicit(scheme), dt="auto")
    v0 = np.zeros(d)
    v0[0] = 0.25 * (1.0 / n) / sim.dt
    pts.v[:] = v0
    P0 = np.array(pts.momentum())
    F_err = s_err = v_err = P_err = 0.0
    first_bad = None
    for k in range(8):                      # 2 cells
        sim.step()
        p = sim.particles
        F_err = max(F_err, _gmax(comm, p.F - np.eye(3)))
        s_err = max(s_err, _gmax(comm, p.stress) / E)
        v_err = max(v_err, _gmax(comm, p.v - v0) / v0[0])
        P_err = max(P_err, float(np.max(np.abs(np.array(p.momentum()) - P0))) / P0[0])
        if first_bad is None and F_err > 1e-12:
            first_bad = k + 1
    msg = (f"{scheme}, particles on cell faces: max |F - I| = {F_err:.3e} (tol 1e-12, first "
           f"exceeded at step {first_bad}), max |stress| / E = {s_err:.3e} (tol 1e-9), "
           f"max |v - v0| / |v0| = {v_err:.3e} (tol 1e-12), max |P - P0| / |P0| = "
           f"{P_err:.3e} (tol 1e-12)")
    assert F_err < 1e-12 and s_err < 1e-9 and v_err < 1e-12 and P_err < 1e-12, msg


def _two_blocks(c):
    """Two adjacent blocks pushed into each other at unequal speeds (so the total momentum
    is not 0): compression waves from the first step on."""
    def region(x):
        a = (x[:, 0] > 1 / 6) & (x[:, 0] < 5 / 12) & (x[:, 1] > 1 / 4) & (x[:, 1] < 7 / 12)
        b = (x[:, 0] > 5 / 12) & (x[:, 0] < 2 / 3) & (x[:, 1] > 1 / 3) & (x[:, 1] < 2 / 3)
        return a | b

    def velocity(x):
        v = np.empty_like(x)
        left = x[:, 0] < 5 / 12
        v[left] = [0.02 * c, 0.004 * c]
        v[~left] = [-0.01 * c, -0.006 * c]
        return v
    return region, velocity


def _spinning_block(c):
    """A square block spinning about its centre (edge speed 0.02 c) while translating."""
    xc = np.array([0.5, 0.5])
    omega = 0.02 * c / 0.2

    def region(x):
        return np.all(np.abs(x - xc) < 0.2, axis=1)

    def velocity(x):
        r = x - xc
        return np.c_[-omega * r[:, 1], omega * r[:, 0]] + [0.005 * c, -0.0025 * c]
    return region, velocity


# "slow": speeds scaled by 1/4, particles move < h/5 in 50 steps (hardly any cell crossing);
# "fast": speeds scaled by 2, many particles cross cells. USL is left out of "fast": it is unstable when a particle
# enters an empty cell (nodal mass ~ N m_p -> 0 amplifies the USL stress update; Sulsky,
# Zhou & Schreyer 1995 introduced MUSL for this), and these runs blow up around step 30.
MOMENTUM_CASES = ([(ct, s, body, "slow") for ct in (CT.quadrilateral, CT.triangle)
                   for s in SCHEMES for body in ("two_blocks", "spinning")]
                  + [(ct, s, body, "fast") for ct in (CT.quadrilateral, CT.triangle)
                     for s in ("USF", "MUSL") for body in ("two_blocks", "spinning")])


@pytest.mark.parametrize("ct,scheme,body,speed", MOMENTUM_CASES,
                         ids=["-".join([c.name, s, b, v]) for c, s, b, v in MOMENTUM_CASES])
def test_momentum_conservation(comm, ct, scheme, body, speed):
    grid = _grid(comm, ct)
    mat = fm.LinearElastic(E=E, nu=NU, density=RHO)
    c = np.sqrt(mat.constrained_modulus / RHO)
    # speeds are irrational multiples of h / dt, so no particle lands exactly on a cell face
    # (see test_translation_onto_cell_faces for that case)
    scale_v = np.pi / 3 * (0.25 if speed == "slow" else 2.0)
    region, velocity = (_two_blocks if body == "two_blocks" else _spinning_block)(c * scale_v)
    pts = fm.Particles.fill(grid, mat, per_cell=2, region=region, velocity=velocity)
    P0 = np.array(pts.momentum())
    scale = float(pts.total(pts.mass * np.linalg.norm(pts.v, axis=1)))
    sim = fm.Simulation(grid, pts, fm.Explicit(scheme), dt="auto")
    worst = 0.0
    for _ in range(STEPS):
        sim.step()
        worst = max(worst, float(np.max(np.abs(np.array(sim.particles.momentum()) - P0))) / scale)
    p = sim.particles
    stress = _gmax(comm, p.stress) / E
    crossed = comm.allreduce(int(np.count_nonzero(grid.locate(p.x - p.u)[0] != p.cell)))
    assert np.linalg.norm(P0) > 0.1 * scale, "test set-up: total momentum should not vanish"
    assert stress > 1e-4, f"body barely deformed (max |stress| / E = {stress:.2e}): not a test"
    assert speed == "slow" or crossed > 10, f"only {crossed} particles changed cells (fast case)"
    assert worst < 1e-12, (f"{scheme}, {body}: max |P(t) - P(0)| / sum m|v| = {worst:.3e} "
                           f"over {STEPS} steps (tol 1e-12)")
