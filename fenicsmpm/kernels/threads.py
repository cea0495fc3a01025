"""Threaded particle passes: the particles are cut into contiguous chunks [lo, hi) and a
numba `prange` runs the chunks on numba's threads.

The thread count is numba's: NUMBA_NUM_THREADS (default: every core), or
numba.set_num_threads. Under MPI without NUMBA_NUM_THREADS, `default_threads` gives each
rank its share of the cores on its node (called when this module is imported), so
`mpirun -n <cores>` runs one thread per rank.

Passes that write per particle only (G2P, dF, commit, shape functions, the linear-elastic
stress, the guards' scan) use particle_chunks(n) chunks, the plastic return mappings
particle_chunks(n, RETURN_CHUNK); neither depends on the thread count: the same bits on
any number of threads.
Passes that add into grid nodes (P2G) use one chunk per thread (n_chunks). Chunk 0 adds
straight into the output, every other chunk c into its own nodal array (kept between
calls: `scratch`), zeroed over the node indices its particles touch (node_range; for particles stored in fill order about
1/nc of the grid); these are added into the output afterwards, in chunk order, in
parallel over the nodes (add_chunks1/2):
    out_i += sum_p in chunk 0 (...) ;   out_i += sum_{c >= 1} buf_c,i.
No two threads write the same memory. The sums differ from the serial pass by round-off
only (the order of the particle sums depends on the number of chunks). A pass with fewer
than 2 MIN_CHUNK particles runs its serial loop directly: no thread start-up, and the
exact serial result."""
import math
import os
import threading

import numba
import numpy as np
from numba import get_num_threads, njit, prange, set_num_threads
from numba.core.cpu_options import ParallelOptions

# numba's parallel transform for the explicit prange loops only (njit(parallel=PRANGE)):
# no implicit parfors from array expressions, half the compile time of parallel=True
PRANGE = ParallelOptions(dict(prange=True, comprehension=False, reduction=False,
                              inplace_binop=False, setitem=False, numpy=False, stencil=False,
                              fusion=False))

MIN_CHUNK = 8192        # particles; below 2 MIN_CHUNK a pass runs serially (a thread
                        # start-up costs ~0.01-1 ms: worth it for passes of >~ 1 ms)
RETURN_CHUNK = 256      # the same for the return mappings of plastic materials (3-5 us per
                        # particle: a chunk of 256 is about 1 ms)
MAX_CHUNKS = 256        # chunks of a per-particle pass (numba spreads them over the threads)
# These are compiled into the cached kernels of other modules, and numba's cache does not
# notice a change in a callee's file: after changing them, delete the *.nbi/*.nbc files
# under fenicsmpm/ (the cached kernels then compile again).


def n_chunks(n):
    """Chunks of an n-particle pass: one per thread, none below MIN_CHUNK particles, >= 1.
    (Plain Python: numba cannot cache a kernel that asks for the thread count itself, so
    each threaded kernel takes the chunk count from a thin Python function.)"""
    return max(1, min(get_num_threads(), n // MIN_CHUNK))


@njit(cache=True)
def particle_chunks(n, min_chunk=MIN_CHUNK):
    """Chunks of an n-particle pass that writes per particle only: n // min_chunk, at most
    MAX_CHUNKS, >= 1. It does not depend on the thread count (nor does the result)."""
    return max(1, min(MAX_CHUNKS, n // min_chunk))


@njit(cache=True)
def chunk(n, nc, c):
    """Particle range [lo, hi) of chunk c of nc (contiguous, sizes differ by at most 1)."""
    return (n * c) // nc, (n * (c + 1)) // nc


@njit(cache=True)
def node_range(nodes, lo, hi, rng):
    """rng[:] = [a, b): the range of node indices the particles lo..hi-1 touch. One flat
    loop over their rows (a view of a C-contiguous array), which LLVM vectorises: 0.89 ms
    against 2.57 ms for a row-by-row loop over half of bench throughput's 1.04e6 cpGIMP rows."""
    flat = nodes[lo:hi].ravel()
    a, b = np.int64(1 << 62), np.int64(-1)
    for j in range(flat.shape[0]):
        x = np.int64(flat[j])
        a = min(a, x)
        b = max(b, x)
    rng[0], rng[1] = a, b + 1
    return a, b + 1


@njit(parallel=PRANGE, cache=True)
def add_chunks1(out, buf, rng):
    """out_i += sum_c buf[c - 1, i] over the chunks c >= 1 whose node range rng[c] holds i
    (their partial nodal sums, added in chunk order)."""
    for i in prange(out.shape[0]):
        for c in range(1, rng.shape[0]):
            if rng[c, 0] <= i and i < rng[c, 1]:
                out[i] += buf[c - 1, i]


@njit(parallel=PRANGE, cache=True)
def add_chunks2(out, buf, rng):
    """out_ik += sum_c buf[c - 1, i, k], as add_chunks1 for nodal vectors."""
    for i in prange(out.shape[0]):
        for c in range(1, rng.shape[0]):
            if rng[c, 0] <= i and i < rng[c, 1]:
                for k in range(out.shape[1]):
                    out[i, k] += buf[c - 1, i, k]


_SCRATCH = threading.local()


def scratch(slot, k, like):
    """A float64 work array of shape (k,) + like.shape (contents undefined) for the per-chunk
    nodal sums of P2G, kept between calls in slot `slot` of this Python thread: a fresh
    multi-MB array per call would fault its pages in again every time."""
    pool = _SCRATCH.__dict__.setdefault("pool", {})
    shape = (max(k, 0),) + like.shape
    size = math.prod(shape)                 # (np.prod costs ~10 us a call: every P2G pass)
    buf = pool.get(slot)
    if buf is None or buf.size < size:
        buf = pool[slot] = np.empty(size)
    return buf[:size].reshape(shape)


def _local_ranks():
    """Ranks of this MPI launch on this node, from the launcher's environment (1 if unknown)."""
    for k in ("OMPI_COMM_WORLD_LOCAL_SIZE", "MPI_LOCALNRANKS", "MV2_COMM_WORLD_LOCAL_SIZE",
              "PMI_LOCAL_SIZE", "SLURM_NTASKS_PER_NODE"):
        try:
            return max(1, int(os.environ[k]))
        except (KeyError, ValueError):
            pass
    return 1


def default_threads():
    """Under MPI (several ranks on this node) without NUMBA_NUM_THREADS, set numba's thread
    count to the cores numba sees divided among those ranks (at least 1) and return it;
    otherwise leave numba's default alone and return None (without starting numba's
    thread pool: that happens at the first threaded pass)."""
    if "NUMBA_NUM_THREADS" in os.environ:
        return None
    local = _local_ranks()
    if local == 1:
        return None
    n = max(1, numba.config.NUMBA_NUM_THREADS // local)
    set_num_threads(n)
    return n


default_threads()
