"""An exception on one rank stops every rank with its message (no hang in a collective)."""
import os
import shutil
import subprocess
import sys

import pytest
from mpi4py import MPI

SCRIPT = """
import fenicsmpm
from mpi4py import MPI
comm = MPI.COMM_WORLD
if comm.rank == 1:
    raise ValueError("boom on rank 1")
comm.barrier()          # rank 0 would wait here for ever without the abort hook
print("unreachable")
"""


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="launches its own mpirun")
@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not on PATH")
def test_error_on_one_rank_aborts_all(tmp_path):
    script = tmp_path / "boom.py"
    script.write_text(SCRIPT)
    cmd = ["mpirun", "-n", "2"]
    if os.geteuid() == 0:
        cmd.append("--allow-run-as-root")
    env = dict(os.environ, OMPI_MCA_rmaps_base_oversubscribe="1")
    proc = subprocess.run(cmd + [sys.executable, str(script)], capture_output=True, text=True,
                          timeout=120, env=env)
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0
    assert "boom on rank 1" in out
    assert "unreachable" not in out
