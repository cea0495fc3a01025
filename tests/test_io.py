"""Tests for fenicsmpm.io (run serially and under mpirun -n 2)."""
import io
import os
import shutil
import tempfile
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from mpi4py import MPI

from fenicsmpm.io import ParticleWriter, Progress, ProbeWriter, read_probe_csv

comm = MPI.COMM_WORLD
rank, size = comm.rank, comm.size


@pytest.fixture
def shared_dir():
    """One temporary directory shared by all ranks."""
    path = tempfile.mkdtemp(prefix="fenicsmpm_io_") if rank == 0 else None
    path = comm.bcast(path, root=0)
    yield path
    comm.barrier()
    if rank == 0:
        shutil.rmtree(path, ignore_errors=True)


def _fields(n, rng):
    return {
        "mass": rng.random(n),
        "v": rng.random((n, 2)),
        "stress": rng.random((n, 3, 3)),
        "id": np.arange(n, dtype=np.int64) + 1000 * rank,
    }


def _check_piece(fname, x, fields):
    import meshio

    m = meshio.read(fname)
    n = x.shape[0]
    assert m.points.shape == (n, 3)
    np.testing.assert_array_equal(m.points[:, :2], x)
    np.testing.assert_array_equal(m.points[:, 2], 0.0)
    pd = m.point_data
    np.testing.assert_array_equal(pd["mass"].reshape(n), fields["mass"])
    assert pd["v"].shape == (n, 3)
    np.testing.assert_array_equal(pd["v"][:, :2], fields["v"])
    np.testing.assert_array_equal(pd["v"][:, 2], 0.0)
    assert pd["stress"].shape == (n, 9)
    np.testing.assert_array_equal(pd["stress"], fields["stress"].reshape(n, 9))
    np.testing.assert_array_equal(pd["id"].reshape(n), fields["id"])
    assert len(m.cells) == 1 and m.cells[0].type == "vertex"
    np.testing.assert_array_equal(m.cells[0].data.ravel(), np.arange(n))


def _pvd(path):
    root = ET.parse(path).getroot()
    assert root.get("type") == "Collection"
    return [(float(d.get("timestep")), d.get("file")) for d in root.iter("DataSet")]


def test_vtu_round_trip(shared_dir):
    rng = np.random.default_rng(rank)
    base = os.path.join(shared_dir, "run", "particles")  # parent created by the writer
    w = ParticleWriter(base, comm)
    times = [0.0, 0.123456789012345678]
    written = []
    for t in times:
        n = 5 + rank
        x, f = rng.random((n, 2)), _fields(n, rng)
        w.write(t, x, f)
        written.append((x, f))
    w.close()
    comm.barrier()

    d = os.path.dirname(base)
    for step, (x, f) in enumerate(written):
        suffix = f"_{step:06d}" + ("" if size == 1 else f"_r{rank}")
        _check_piece(os.path.join(d, f"particles{suffix}.vtu"), x, f)

    entries = _pvd(base + ".pvd")
    assert [e[0] for e in entries] == times
    ext = "vtu" if size == 1 else "pvtu"
    assert [e[1] for e in entries] == [f"particles_{s:06d}.{ext}" for s in range(2)]
    for _, fname in entries:
        assert os.path.isfile(os.path.join(d, fname))

    if size > 1:
        root = ET.parse(os.path.join(d, "particles_000001.pvtu")).getroot()
        assert root.get("type") == "PUnstructuredGrid"
        grid = root.find("PUnstructuredGrid")
        pieces = [p.get("Source") for p in grid.findall("Piece")]
        assert pieces == [f"particles_000001_r{r}.vtu" for r in range(size)]
        decl = {a.get("Name"): (a.get("type"), a.get("NumberOfComponents"))
                for a in grid.find("PPointData")}
        assert decl == {"mass": ("Float64", "1"), "v": ("Float64", "3"),
                        "stress": ("Float64", "9"), "id": ("Int64", "1")}
        pts = grid.find("PPoints").find("PDataArray")
        assert pts.get("NumberOfComponents") == "3" and pts.get("type") == "Float64"


def test_empty_rank(shared_dir):
    rng = np.random.default_rng(10 + rank)
    base = os.path.join(shared_dir, "particles")
    w = ParticleWriter(base, comm, fields=["mass", "v", "stress"])
    empty_rank = size - 1
    for step in range(2):
        # In serial the only rank is empty on step 1 (layout taken from step 0);
        # in parallel the last rank always is.
        empty = rank == empty_rank and (size > 1 or step == 1)
        n = 0 if empty else 4
        if empty:  # shapes need not be known on an empty rank
            x = np.zeros((0,))
            f = {"mass": np.zeros(0), "v": np.zeros(0), "stress": np.zeros(0)}
        else:
            x, f = rng.random((n, 2)), _fields(n, rng)
        w.write(0.5 * step, x, f)
        comm.barrier()
        suffix = f"_{step:06d}" + ("" if size == 1 else f"_r{rank}")
        fname = os.path.join(shared_dir, f"particles{suffix}.vtu")
        if empty:
            root = ET.parse(fname).getroot()
            piece = root.find("UnstructuredGrid").find("Piece")
            assert piece.get("NumberOfPoints") == "0" and piece.get("NumberOfCells") == "0"
            decl = {a.get("Name"): (a.get("type"), a.get("NumberOfComponents"))
                    for a in piece.find("PointData")}
            assert decl == {"mass": ("Float64", None), "v": ("Float64", "3"),
                            "stress": ("Float64", "9")}
        else:
            import meshio

            m = meshio.read(fname)
            assert set(m.point_data) == {"mass", "v", "stress"}  # "id" filtered out
            np.testing.assert_array_equal(m.points[:, :2], x)
            np.testing.assert_array_equal(m.point_data["v"][:, :2], f["v"])
    w.close()
    comm.barrier()
    assert [e[0] for e in _pvd(base + ".pvd")] == [0.0, 0.5]


def test_mismatched_fields_raise_on_all_ranks(shared_dir):
    w = ParticleWriter(os.path.join(shared_dir, "bad"), comm)
    f = {"a": np.zeros(3)} if rank == 0 else {"b": np.zeros(3)}
    if size == 1:
        f = {"a": np.zeros(2)}  # wrong length
    with pytest.raises(ValueError):
        w.write(0.0, np.zeros((3, 2)), f)
    # 3D points with a vector of 3 components are written unchanged
    w.write(0.0, np.ones((3, 3)), {"a": np.ones((3, 3))})


def test_probe_csv_round_trip(shared_dir):
    owner = size - 1
    path = os.path.join(shared_dir, "probes", "point_A.csv")
    cols = ["t", "vx", "vy", "sxx"]
    pw = ProbeWriter(path, cols, comm, root=owner)  # not collective
    rng = np.random.default_rng(3)
    data = rng.standard_normal((20, 4)) * 10.0 ** rng.integers(-30, 30, (20, 4))
    if rank == owner:
        for i, row in enumerate(data):
            if i % 2:
                pw.write_row(dict(zip(cols, row)))
            else:
                pw.write_row(row)
        # line-buffered: readable before close
        assert len(read_probe_csv(path)["t"]) == 20
    pw.close()
    comm.barrier()
    out = read_probe_csv(path)
    assert list(out) == cols
    for j, c in enumerate(cols):
        np.testing.assert_allclose(out[c], data[:, j], rtol=1e-15, atol=0)
    with open(path) as fh:
        assert fh.readline().strip() == "t,vx,vy,sxx"


def test_progress_forced():
    s = io.StringIO()
    p = Progress(5000, 0.5, comm, stream=s, min_interval=0, force=True, delay=0)
    for step in (1200, 2400):
        p.update(step, step * 1e-4)
    p.close()
    out = s.getvalue()
    if rank == 0:
        assert "step 1200/5000 (24.0 %)" in out and "step 2400/5000" in out
        assert "ETA" in out and "t = 1.2e-01 s" in out and "wall" in out
        assert out.startswith("\r") and out.endswith("\n") and out.count("\n") == 1
    else:
        assert out == ""


class _FakeComm:
    def __init__(self, r):
        self.r = r

    def Get_rank(self):
        return self.r


def test_progress_quiet():
    s = io.StringIO()  # not a TTY
    p = Progress(10, 1.0, comm, stream=s, min_interval=0, delay=0)
    p.update(5, 0.5)
    p.close()
    assert s.getvalue() == ""

    for kwargs in ({"force": False}, {"force": True, "comm": _FakeComm(1)}):
        s = io.StringIO()
        kw = {"comm": comm, **kwargs}
        p = Progress(10, 1.0, stream=s, min_interval=0, delay=0, **kw)
        p.update(5, 0.5)
        p.close()
        assert s.getvalue() == ""

    # delay keeps short runs silent
    s = io.StringIO()
    p = Progress(10, 1.0, None, stream=s, min_interval=0, force=True, delay=60)
    p.update(5, 0.5)
    p.close()
    assert s.getvalue() == ""


def test_progress_count_follows_the_state_dt(monkeypatch):
    """With dt="auto" following the state (explicit, run(t_end=...)) the progress line's step
    count is re-estimated every step as the steps taken plus the time left / dt: it never
    falls behind the step (before, it stuck at the first estimate minus one, e.g. "step
    1546/1547" for the last 500 steps of the jacked pile), and ends at the steps taken.
    Here the granular column's front stretches and dt falls from 1.32 ms to 0.94 ms by
    t = 1 s (a = 2, h = L0 / 4: first estimate 758 steps, 865 taken)."""
    import fenicsmpm.simulation as simulation
    from fenicsmpm.problems.granular_collapse import granular_column
    seen = []

    class Recorder(Progress):
        def update(self, step, t):
            seen.append((step, self.total_steps))

    monkeypatch.setattr(simulation, "Progress", Recorder)
    sim, _, _ = granular_column(2.0, cells=4)
    dt0 = sim.dt
    sim.run(t_end=1.0)
    assert sim.dt < 0.8 * dt0                       # dt followed the state
    assert all(step <= total for step, total in seen)
    assert seen[-1] == (sim.step_count, sim.step_count)
    assert seen[0][1] < sim.step_count              # the first estimate was short
