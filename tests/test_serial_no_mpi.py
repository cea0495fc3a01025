"""A serial run makes no communication calls in the step loop."""
import numpy as np
import pytest
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.problems.elastic import colliding_discs, self_weight_column


class CountingComm:
    """Wraps a communicator; counts every method call except rank/size queries."""
    QUIET = {"Get_rank", "Get_size", "rank", "size"}

    def __init__(self, comm):
        self._comm, self.calls = comm, []

    def __getattr__(self, name):
        attr = getattr(self._comm, name)
        if callable(attr) and name not in self.QUIET:
            def counted(*a, **k):
                self.calls.append(name)
                return attr(*a, **k)
            return counted
        return attr


def _instrument(sim):
    spy = CountingComm(sim.comm)
    sim.comm = sim.grid.comm = spy
    return spy


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1,
                    reason="checks the one-rank code path; parallel runs must communicate")
@pytest.mark.parametrize("integrator", [fm.Explicit("USF"), fm.Explicit("MUSL")])
def test_explicit_step_loop_makes_no_mpi_calls(integrator):
    sim, _ = colliding_discs(integrator, comm=MPI.COMM_SELF)
    spy = _instrument(sim)
    probe = sim.probe((0.2, 0.2), ["velocity"])
    sim.run(steps=20)
    assert spy.calls == [], f"MPI calls in a serial step loop: {sorted(set(spy.calls))}"
    assert len(probe.rows) == 21


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1,
                    reason="checks the one-rank code path; parallel runs must communicate")
def test_quasistatic_step_loop_makes_no_python_mpi_calls():
    sim, _ = self_weight_column(fm.QuasiStatic(load_steps=2), comm=MPI.COMM_SELF)
    spy = _instrument(sim)
    sim.run(steps=2)
    assert spy.calls == [], f"MPI calls in a serial step loop: {sorted(set(spy.calls))}"
