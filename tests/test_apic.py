"""The affine velocity transfers (fm.Explicit(transfer="apic" or "aflip");
kernels.transfer.p2g_affine / g2p_affine; issue 15) on a rigidly rotating elastic disc (fenicsmpm.problems.rotating_disc):
radius 4 cells, 2 x 2 particles per cell, cpGIMP, MUSL, one turn."""
import numpy as np
import pytest
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.problems.rotating_disc import momenta, rotating_disc


def _turn(integrator, shape="cpgimp"):
    sim = rotating_disc(integrator, shape=shape)
    L0, K0 = momenta(sim)
    sim.run(t_end=1.0)
    L1, K1 = momenta(sim)
    return L1 / L0 - 1.0, K1 / K0 - 1.0, sim


@pytest.mark.parametrize("transfer", ["apic", "aflip"])
def test_affine_transfer_conserves_angular_momentum_of_rotating_disc(transfer):
    """Issue 15 targets: angular momentum (with the particles' affine spin) within 0.5 % after
    one turn, kinetic energy within 2 %. Measured: APIC +0.009 % / -0.13 %, AFLIP -0.012 % /
    +0.15 % (with C_p = 0 at the start instead of Explicit.initial_affine, APIC's kinetic
    energy was -4.5 % and AFLIP gained 4.4 % of both); FLIP loses 10.8 % of the angular
    momentum."""
    dL, dK, sim = _turn(fm.Explicit("MUSL", transfer=transfer))
    assert abs(dL) < 0.005, dL
    assert abs(dK) < 0.02, dK
    dL_flip, _, _ = _turn(fm.Explicit("MUSL"))
    assert dL_flip < -0.05, dL_flip                 # the reason for the affine transfer


def test_initial_affine_state_is_the_velocity_gradient():
    """Explicit.initial_affine: a linear velocity field v = A x given to the particles starts
    with C_p = A to round-off on the particles whose nodes' cpGIMP supports hold only full
    rows of particles (radius < 1.2 cells here; nearer the rim C_p is the fixed point of two
    sweeps: measured within 0.02 of A at 2 cells), and v_p is left unchanged."""
    import fenicsmpm.problems.rotating_disc as rd
    sim = rotating_disc(fm.Explicit("MUSL", transfer="aflip"), shape="cpgimp")
    p = sim.particles
    A = np.array([[0.3, -1.2], [0.7, 0.1]])
    p.v[:] = p.x @ A.T
    v0 = p.v.copy()
    sim.integrator.initial_affine(sim)
    assert np.array_equal(p.v, v0)
    comm = sim.comm
    r = np.linalg.norm(p.x, axis=1) / sim.grid.h
    err = np.abs(p.apic_C - A).max(axis=(1, 2))
    assert comm.allreduce(int((r < 1.2).sum())) == 16
    inner = comm.allreduce(float(err[r < 1.2].max(initial=0.0)), op=MPI.MAX)
    near = comm.allreduce(float(err[r < 2.0].max(initial=0.0)), op=MPI.MAX)
    assert inner < 1e-12 and near < 0.03, (inner, near)
    assert rd.momenta(sim)[1] > 0.0


def test_apic_transfers_an_affine_field_exactly():
    """One P2G of a linear velocity field v = A x carried as (v_p, C_p = A) gives nodal
    velocities A x_i to round-off on every node with mass (cpGIMP weights reproduce affine
    fields)."""
    sim = rotating_disc(fm.Explicit("MUSL", transfer="apic"), shape="cpgimp")
    p, g = sim.particles, sim.grid
    A = np.array([[0.3, -1.2], [0.7, 0.1]])
    p.v[:] = p.x @ A.T
    p.apic_C[:] = A
    sim.locate_and_shape()
    m, mv = sim.integrator._p2g(sim)
    g.accumulate(m, mv)
    on = m > 1e-12 * m.max()
    v = mv[on] / m[on, None]
    assert np.abs(v - g.node_x[on] @ A.T).max() < 1e-12 * np.abs(v).max()


def test_transfer_input_validation():
    with pytest.raises(ValueError, match="'transfer' must be one of"):
        fm.Explicit("MUSL", transfer="tpic")
    with pytest.raises(ValueError, match="'flip' applies to transfer='flip' or 'aflip'"):
        fm.Explicit("MUSL", flip=0.5, transfer="apic")
    assert fm.Explicit("MUSL", flip=0.5, transfer="aflip").flip == 0.5
