"""Context for numba parallel kernels called from torch code."""

from __future__ import annotations

import numba
import torch

SERIAL_BELOW = 32768  # per-item kernels (one Gaussian, one intersection) below this run on one thread


class KernelScope:
    """Run numba parallel kernels without side effects on torch.

    numba's OpenMP layer shares libgomp with torch and resets the process's OpenMP thread count when
    it launches a region, which silently undoes a caller's ``torch.set_num_threads``; the count is
    restored on exit. ``chunk`` is numba's parallel chunk size inside the scope: tiles are handed out
    in small chunks (uneven tiles balance across cores); per-Gaussian kernels use 0 (numba's default
    static split, the work per item being uniform).

    ``items`` below ``serial_below`` runs the kernel on the calling thread only: waking the worker
    threads costs milliseconds on a busy machine (measured 6-12 ms per launch with the cores shared),
    more than a small job takes on one core.
    """

    def __init__(self, chunk: int = 2, items: int | None = None, serial_below: int = SERIAL_BELOW):
        self.chunk_size = int(chunk)
        self.serial = items is not None and items < serial_below

    def __enter__(self):
        self.torch_threads = torch.get_num_threads()
        self.chunk = numba.get_parallel_chunksize()
        numba.set_parallel_chunksize(self.chunk_size)
        self.numba_threads = numba.get_num_threads()
        if self.serial:
            numba.set_num_threads(1)
        return self

    def __exit__(self, *exc):
        if self.serial:
            numba.set_num_threads(self.numba_threads)
        numba.set_parallel_chunksize(self.chunk)
        if torch.get_num_threads() != self.torch_threads:
            torch.set_num_threads(self.torch_threads)
        return False
