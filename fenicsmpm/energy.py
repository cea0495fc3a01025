"""Energy monitor of a Simulation (EnergyMixin, inherited by fenicsmpm.Simulation): kinetic and
strain energy, the work of external and boundary forces recorded by the integrators, and the
balance check E_kin + E_strain - W_ext - W_boundary = E_0."""
import warnings

import numpy as np

from .io import ProbeWriter

ENERGY_COLUMNS = ("t", "kinetic", "strain", "external_work", "boundary_work", "balance_error")


class EnergyMixin:
    """Energy methods of fenicsmpm.Simulation."""

    def energy(self):
        """Global kinetic and strain energy, and with `monitor_energy` the work done by the
        external loads (gravity, tractions, particle loads) and by Robin/absorbing boundaries
        (negative: energy they took out) since monitoring started (collective)."""
        p = self.particles
        e = dict(kinetic=p.kinetic_energy(), strain=p.strain_energy())
        if self._work is not None:
            w = self.comm.allreduce(self._work) if self.comm.size > 1 else self._work
            e.update(external_work=float(w[0]), boundary_work=float(w[1]))
        return e

    @property
    def monitoring_work(self):
        """Whether `monitor_energy` asked the integrator to record the work of the forces."""
        return self._work is not None

    def record_work(self, f_ext, f_boundary, v_start, v_end, dt):
        """Integrators call this once per step when the energy is monitored: the work of the
        nodal external and boundary forces over the step, dt f . (v_start + v_end) / 2, summed
        over owned nodes (kept per rank; `energy` reduces it)."""
        if self._work is None:
            return
        n = self.grid.n_owned_nodes
        vm = 0.5 * (v_start[:n] + v_end[:n])
        self._work[0] += dt * float(np.einsum("ij,ij->", f_ext[:n], vm))
        if f_boundary is not None:
            self._work[1] += dt * float(np.einsum("ij,ij->", f_boundary[:n], vm))

    def monitor_energy(self, every=10, tolerance=0.02, path=None, warmup=20):
        """Track the energy balance E_kin + E_strain - W_ext - W_boundary = E_0 every `every`
        steps (history in `energy_history`, CSV at `path`) and warn, once, when its error
        exceeds `tolerance` times the scale.

        Scale: the largest of E_kin + E_strain, |W_ext| and |W_boundary| seen so far (so the
        balance error is a fraction of the work put in, or of the energy the body started
        with). The warning is armed only after `warmup` steps from the start of monitoring:
        in the first steps of a suddenly applied load the energies are tiny and the mapping
        between grid and particles makes the balance error tens of percent of them (measured
        -27.6 % at step 1, +5.4 % at step 5 and +1.5 % at step 20 on a point load,
        tests/test_energy_monitor.py). `balance_error` is recorded from the start.

        fm.Explicit, fm.ExplicitContact and fm.Newmark (implicit, trapezoidal work) record the
        external and boundary work; other integrators raise a ValueError here."""
        if not getattr(self.integrator, "records_work", False):
            raise ValueError(f"monitor_energy: {type(self.integrator).__name__} does not record "
                             f"the work of external and boundary forces")
        if isinstance(every, bool) or not (isinstance(every, (int, np.integer)) and every >= 1):
            raise ValueError(f"monitor_energy: 'every' must be a positive integer, got {every!r}")
        if not (isinstance(tolerance, (int, float, np.floating)) and tolerance > 0):
            raise ValueError(f"monitor_energy: 'tolerance' must be > 0, got {tolerance!r}")
        if isinstance(warmup, bool) or not (isinstance(warmup, (int, np.integer)) and warmup >= 0):
            raise ValueError(f"monitor_energy: 'warmup' must be a non-negative integer, got "
                             f"{warmup!r}")
        self._work = np.zeros(2)
        self.energy_history = []
        writer = None
        if path is not None:
            writer = ProbeWriter(path, ENERGY_COLUMNS, self.comm)
        state = self._energy_monitor = dict(e0=None, scale=0.0, warned=False,
                                            armed_at=self.step_count + warmup, writer=writer)

        def check(sim):
            e = sim.energy()
            total = e["kinetic"] + e["strain"]
            if state["e0"] is None:
                state["e0"] = total - e["external_work"] - e["boundary_work"]
            state["scale"] = max(state["scale"], total, abs(e["external_work"]),
                                 abs(e["boundary_work"]), 1e-300)
            err = (total - e["external_work"] - e["boundary_work"] - state["e0"]) / state["scale"]
            e.update(t=sim.t, balance_error=err)
            sim.energy_history.append(e)
            if state["writer"] is not None and sim.comm.rank == 0:
                state["writer"].write_row(e)
            if abs(err) > tolerance and not state["warned"] and sim.step_count >= state["armed_at"]:
                state["warned"] = True
                if sim.comm.rank == 0:
                    warnings.warn(f"step {sim.step_count}, t = {sim.t:.6g}: energy balance error "
                                  f"{err:.3%} of the largest energy or work exceeds {tolerance:.3%}",
                                  RuntimeWarning, stacklevel=2)

        check(self)
        self.observe(check, every)
        return self.energy_history

    def _energy_state(self):
        """The energy monitor's state for a checkpoint (None without `monitor_energy`): the
        balance's E_0, scale, warning state and history rows (columns ENERGY_COLUMNS), the
        same on every rank (each rank's share of the work, `_work`, goes in its rank file)."""
        if self._work is None:
            return None
        st = self._energy_monitor
        rows = np.array([[e[c] for c in ENERGY_COLUMNS] for e in self.energy_history],
                        dtype=np.float64).reshape(-1, len(ENERGY_COLUMNS))
        return dict(history=rows,
                    e0=np.nan if st["e0"] is None else st["e0"], scale=st["scale"],
                    warned=st["warned"], armed_at=st["armed_at"])

    def _restore_energy(self, saved, work):
        """Restore what _energy_state saved into a simulation that monitors its energy, with
        `work` this rank's share (the sum of the rank files it reads), so the balance goes on
        as in the continuous run; the history (and its CSV) is the saved one."""
        if self._work is None:
            return
        st = self._energy_monitor
        self._work = np.asarray(work, dtype=np.float64).copy()
        e0 = float(saved["e0"])
        st.update(e0=None if np.isnan(e0) else e0, scale=float(saved["scale"]),
                  warned=bool(saved["warned"]), armed_at=int(saved["armed_at"]))
        rows = np.asarray(saved["history"], dtype=np.float64).reshape(-1, len(ENERGY_COLUMNS))
        self.energy_history[:] = [dict(zip(ENERGY_COLUMNS, map(float, r))) for r in rows]
        if st["writer"] is not None and self.comm.rank == 0:
            st["writer"].rewrite(self.energy_history)
