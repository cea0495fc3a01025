"""Reductions of per-rank values over the ranks of a communicator (collective calls: every
rank calls them with its local value; one process skips MPI).

    gsum(comm, x), gmin(comm, x), gmax(comm, x)    sum, smallest, largest of x over the ranks
    gmax_of(comm, a), gmin_of(comm, a)             the largest / smallest entry of the local
                                                   arrays a over the ranks (a rank without
                                                   entries adds -inf / +inf)

Scenes, benchmarks and demos use them for global figures (a run-out, a reaction, a wall
time); the library's own stages reduce in place where they need to."""
import numpy as np
from mpi4py import MPI


def gsum(comm, x):
    """Sum of x over the ranks."""
    return comm.allreduce(x, op=MPI.SUM) if comm.size > 1 else x


def gmin(comm, x):
    """Smallest x over the ranks."""
    return comm.allreduce(x, op=MPI.MIN) if comm.size > 1 else x


def gmax(comm, x):
    """Largest x over the ranks."""
    return comm.allreduce(x, op=MPI.MAX) if comm.size > 1 else x


def gmax_of(comm, a):
    """The largest entry of the local arrays a over the ranks (float; -inf if none has one)."""
    return gmax(comm, float(np.max(a)) if np.size(a) else -np.inf)


def gmin_of(comm, a):
    """The smallest entry of the local arrays a over the ranks (float; +inf if none has one)."""
    return gmin(comm, float(np.min(a)) if np.size(a) else np.inf)
