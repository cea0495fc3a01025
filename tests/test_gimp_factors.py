"""bench gimp-factors (issue 16): the cpGIMP weights as per-axis factors give the padded rows'
P2G and internal force to the bit (the contract a factored particle pass must keep), and the
case writes its JSON and PNG (serial and 2 ranks)."""
import json
import os

from mpi4py import MPI

from fenicsmpm import bench
from fenicsmpm.bench import gimp_factors


def test_factored_passes_give_the_rows_bits(tmp_path_factory):
    comm = MPI.COMM_WORLD
    out = comm.bcast(str(tmp_path_factory.mktemp("gf")) if comm.rank == 0 else None)
    doc = gimp_factors.run(quick=True, out=out, verbose=False)
    assert bench.get_case("gimp-factors") is gimp_factors.run
    runs = {r["name"]: r["metrics"] for r in doc["runs"]}
    assert set(runs) == {"shape", "p2g", "force"}
    for m in runs.values():
        assert m["bits_equal"] == 1.0
        assert m["ms_rows"] > 0.0 and m["ms_factors"] > 0.0
        # 28 B a column (node, weight, 2 gradient components); as many columns as the
        # particle with the most nodes has (4, 6 or 9 in 2D), the same on every rank
        assert m["row_columns"] in (4, 6, 9)
        assert (m["bytes_rows"], m["bytes_factors"]) == (28 * m["row_columns"], 104)
    if comm.rank == 0:
        assert os.path.exists(os.path.join(out, "gimp-factors.png"))
        with open(os.path.join(out, "gimp-factors.json")) as f:
            assert json.load(f)["case"] == "gimp-factors"
