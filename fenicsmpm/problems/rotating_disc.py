"""A rigidly rotating elastic disc (issue 15): radius R, angular velocity omega, no gravity, on
a square grid; one turn of a stress-free disc. Known answer: the angular momentum and the
kinetic energy stay at their initial values (no external moment; the elastic response to the
centrifugal load is small, rho omega^2 R^2 / E = 0.4 % for the defaults).

With the affine transfer (fm.Explicit(transfer="apic")) a particle carries, besides
x_p x m_p v_p, the spin of its affine velocity field: angular momentum and kinetic energy are
(Jiang et al. 2015, §5.3)
    L = sum_p m_p [x_p x v_p + (B_p)_yx - (B_p)_xy],   B_p = C_p D_p,
    K = sum_p m_p [|v_p|^2 + tr(C_p D_p C_p^T)] / 2,    D_p = sum_i N_ip (x_i - x_p)(x_i - x_p)^T."""
import numpy as np


def rotating_disc(integrator, shape="mpm", R=1.0, cells_r=4, omega=2 * np.pi, E=1e7, comm=None):
    """The disc (NeoHookean, nu 0.3, rho 1000, 2 x 2 particles per cell, radius `cells_r`
    cells) spinning at omega about the grid's centre; returns the Simulation (dt="auto")."""
    from dolfinx import mesh
    from mpi4py import MPI
    import fenicsmpm as fm
    comm = MPI.COMM_WORLD if comm is None else comm
    h = R / cells_r
    n = 2 * cells_r + 4
    L = n * h
    msh = mesh.create_rectangle(comm, [[-L / 2, -L / 2], [L / 2, L / 2]], [n, n],
                                mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, fm.NeoHookean(E=E, nu=0.3, density=1000.0), per_cell=2,
                          region=lambda x: (x ** 2).sum(1) < R ** 2,
                          velocity=lambda x: omega * np.column_stack([-x[:, 1], x[:, 0]]))
    return fm.Simulation(grid, p, integrator, dt="auto", shape=shape)


def momenta(sim):
    """(angular momentum about the origin, kinetic energy), global, including the particles'
    affine parts when they carry `apic_C` (module docstring); collective."""
    p = sim.particles
    ang = p.mass * (p.x[:, 0] * p.v[:, 1] - p.x[:, 1] * p.v[:, 0])
    kin = 0.5 * p.mass * (p.v ** 2).sum(1)
    if hasattr(p, "apic_C"):
        sim.locate_and_shape()
        r = sim.grid.node_x[sim.nodes] - p.x[:, None, :]
        Dm = np.einsum("pa,pak,pal->pkl", sim.N, r, r)
        B = np.einsum("pkj,pjl->pkl", p.apic_C, Dm)
        ang = ang + p.mass * (B[:, 1, 0] - B[:, 0, 1])
        kin = kin + 0.5 * p.mass * np.einsum("pkj,pjl,pkl->p", p.apic_C, Dm, p.apic_C)
    return p.total(ang), p.total(kin)
