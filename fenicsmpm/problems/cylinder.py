"""Axisymmetric verification: a thick cylinder a <= r <= b under internal pressure, plane
strain in z (rollers on z = 0 and z = H), quasi-static (fenicsmpm.kernels.axisymmetric).

- Linear elastic (Lame): sigma_rr = A - B / r^2, sigma_tt = A + B / r^2,
  u_r = (1 + nu) / E (A (1 - 2 nu) r + B / r),  A = p a^2 / (b^2 - a^2), B = p a^2 b^2 / (b^2 - a^2).
- Mohr-Coulomb with phi = 0 (Tresca, cohesion c), partly plastic to the radius rho (Hill 1950,
  The Mathematical Theory of Plasticity, ch. V): p = c (1 - rho^2 / b^2 + 2 ln(rho / a));
  plastic zone sigma_r = -p + 2 c ln(r / a), sigma_t = sigma_r + 2 c; elastic zone
  sigma_r,t = c rho^2 / b^2 (1 -+ b^2 / r^2).
Stresses are compared as cell means (the particles of a radial column of cells) at the
cell centres, where the Q1 stress superconverges; displacements particle by particle."""
import time

import numpy as np

A_IN, B_OUT, HEIGHT = 1.0, 2.0, 0.25


def lame(r, pressure, E, nu, a=A_IN, b=B_OUT):
    """Exact (sigma_rr, sigma_tt, u_r) of the elastic thick cylinder at radii r."""
    A = pressure * a**2 / (b**2 - a**2)
    B = pressure * a**2 * b**2 / (b**2 - a**2)
    return A - B / r**2, A + B / r**2, (1 + nu) / E * (A * (1 - 2 * nu) * r + B / r)


def hill_pressure(c, rho, a=A_IN, b=B_OUT):
    """Internal pressure that makes a Tresca cylinder plastic out to r = rho."""
    return c * (1 - rho**2 / b**2 + 2 * np.log(rho / a))


def hill(r, c, rho, a=A_IN, b=B_OUT):
    """Exact (sigma_rr, sigma_tt) of the partly plastic Tresca cylinder at radii r."""
    p = hill_pressure(c, rho, a, b)
    plastic = r < rho
    s_r = np.where(plastic, -p + 2 * c * np.log(r / a), -(c * rho**2 / b**2) * (b**2 / r**2 - 1))
    s_t = np.where(plastic, s_r + 2 * c, (c * rho**2 / b**2) * (b**2 / r**2 + 1))
    return s_r, s_t


def thick_cylinder(nx, material, pressure, steps=1, shape="mpm", per_cell=2, comm=None):
    """Build and run the cylinder on nx x nx/4 quadrilateral cells, the pressure ramped over
    `steps` quasi-static steps; returns (sim, wall seconds of the run)."""
    from dolfinx import mesh as dmesh
    from mpi4py import MPI
    import fenicsmpm as fm
    comm = MPI.COMM_WORLD if comm is None else comm
    msh = dmesh.create_rectangle(comm, [[A_IN, 0.0], [B_OUT, HEIGHT]], [nx, max(1, nx // 4)],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh, axisymmetric=True)
    p = fm.Particles.fill(grid, material, per_cell=per_cell)
    sim = fm.Simulation(grid, p, fm.QuasiStatic(), dt=1.0, shape=shape)
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0) | np.isclose(x[:, 1], HEIGHT), [1])
    sim.add_traction(lambda x: np.isclose(x[:, 0], A_IN),
                     lambda t: [pressure * min(t, steps) / steps, 0.0])
    t0 = time.perf_counter()
    sim.run(steps=steps)
    wall = time.perf_counter() - t0
    return sim, (comm.allreduce(wall, op=MPI.MAX) if comm.size > 1 else wall)


def cell_means(sim, nx):
    """(r_centre, mean sigma_rr, mean sigma_tt) per radial column of cells (global)."""
    p = sim.particles
    h = (B_OUT - A_IN) / nx
    k = np.floor(((p.x - p.u)[:, 0] - A_IN) / h).astype(int)
    sums = [np.bincount(k, w, minlength=nx) for w in (None, p.stress[:, 0, 0], p.stress[:, 2, 2])]
    if sim.comm.size > 1:
        sums = [sim.comm.allreduce(s) for s in sums]
    return A_IN + (np.arange(nx) + 0.5) * h, sums[1] / sums[0], sums[2] / sums[0]


def lame_errors(sim, nx, pressure, E, nu):
    """(sigma_rr error / p, max relative sigma_tt error, max relative u_r error)."""
    r, srr, stt = cell_means(sim, nx)
    e_rr, e_tt, _ = lame(r, pressure, E, nu)
    p = sim.particles
    r0 = (p.x - p.u)[:, 0]
    ur = lame(r0, pressure, E, nu)[2]
    err_u = float(np.max(np.abs(p.u[:, 0] / ur - 1.0), initial=0.0))
    if sim.comm.size > 1:
        from mpi4py import MPI
        err_u = sim.comm.allreduce(err_u, op=MPI.MAX)
    return (float(np.max(np.abs(srr - e_rr)) / pressure), float(np.max(np.abs(stt / e_tt - 1.0))),
            err_u)


def hill_error(sim, nx, c, rho):
    """max |sigma - exact| / p over the cell means of sigma_rr and sigma_tt."""
    r, srr, stt = cell_means(sim, nx)
    s_r, s_t = hill(r, c, rho)
    return float(max(np.max(np.abs(srr - s_r)), np.max(np.abs(stt - s_t))) / hill_pressure(c, rho))
