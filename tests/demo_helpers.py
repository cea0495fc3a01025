"""Helpers shared by the demo tests: load a demo script as a module, check output files."""
import importlib.util
import os
from pathlib import Path

from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]


def load_demo(name):
    """demos/<name>.py as a module (its main(argv) runs in-process, also under mpirun)."""
    spec = importlib.util.spec_from_file_location(f"demo_{name}", ROOT / "demos" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def exist_on_rank0(*paths):
    """Whether all paths exist, checked on rank 0 after every rank finished writing."""
    comm = MPI.COMM_WORLD
    comm.barrier()
    ok = all(os.path.isfile(p) for p in paths) if comm.rank == 0 else None
    return comm.bcast(ok, root=0)
