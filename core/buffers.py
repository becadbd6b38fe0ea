"""Reused memory for large output arrays (docs/validation.md, Throughput).

Fresh memory costs the kernel a page fault and a zero fill per page: on the bench machine
≈ 0.2 ns per byte (a first fill of 43 MB 16–18 ms, a second 8.5 ms, 2026-11-26). Arrays
above glibc's mmap threshold are mapped on allocation and unmapped on release, so a
computation that allocates its large output afresh on every call pays the faults every
time. A :class:`BufferPool` keeps a few large buffers and hands one out again once no
array uses it any more.

A buffer is free when the pool holds the only reference to it: every numpy view of a
buffer (the array handed out, its rows, their slices, ``.view``/``.reshape`` results)
refers to it through ``base``, so while any such array is alive the buffer's reference
count is above the pool's own and it is never handed out again. Arrays handed out hold
whatever an earlier user left (like ``numpy.empty``).
"""

from __future__ import annotations

import math
import sys
import threading

import numpy as np

#: largest dtype alignment a buffer serves (numpy's allocations are 16-byte aligned)
_ALIGNMENT = 16


class BufferPool:
    """At most ``keep`` reusable buffers for arrays of ``min_bytes``..``max_bytes`` bytes.

    ``fixed=True``: every buffer holds ``max_bytes`` bytes and serves any request in the
    range (the output blocks of ``railval.db.codec.decode_many``). ``fixed=False``: a buffer
    is sized for the request that made it (rounded up to an eighth of its power of two) and
    serves requests of more than half its size; when none fits and the pool is full, an idle
    buffer is replaced by one for the new size (the pool follows the largest recent
    requests). The buffers together hold at most ``max_total_bytes`` (default
    ``keep × max_bytes``); idle buffers are dropped to make room. Requests outside the range,
    of a dtype aligned above 16 bytes, or while every buffer is in use (or no room is left)
    are ordinary ``numpy.empty`` allocations. Thread-safe.

    Parameters
    ----------
    keep : int
        Buffers kept at most.
    max_bytes : int
        Largest request served (and the buffer size when ``fixed``).
    min_bytes : int
        Smallest request served (smaller arrays do not pin a buffer).
    fixed : bool
        Buffers of ``max_bytes`` (True) or sized per request (False).
    max_total_bytes : int or None
        Bytes kept by all buffers together at most.
    """

    def __init__(self, keep: int, max_bytes: int, min_bytes: int = 0, fixed: bool = False,
                 max_total_bytes: int | None = None):
        self.keep = int(keep)
        self.max_bytes = int(max_bytes)
        self.min_bytes = int(min_bytes)
        self.fixed = bool(fixed)
        self.max_total_bytes = (self.keep * self.max_bytes if max_total_bytes is None
                                else int(max_total_bytes))
        self._buffers: list[np.ndarray] = [np.empty(0, np.uint8)]  # a probe nothing else uses
        self._idle_refs = self._refcounts()[0]
        self._buffers.clear()
        self._lock = threading.Lock()

    def _refcounts(self) -> list[int]:
        """References to each buffer, counted the same way for the probe of ``__init__`` and
        later, so the figure of an unused buffer does not depend on interpreter details."""
        return [sys.getrefcount(b) for b in self._buffers]

    def _idle(self) -> list[int]:
        """Indices of the buffers no array refers to."""
        return [i for i, refs in enumerate(self._refcounts()) if refs <= self._idle_refs]

    def _size_for(self, nbytes: int) -> int:
        if self.fixed:
            return self.max_bytes
        step = 1 << max(0, nbytes.bit_length() - 4)  # an eighth of the power of two below
        return min(self.max_bytes, -(-nbytes // step) * step)

    def _fits(self, buf: np.ndarray, nbytes: int) -> bool:
        return nbytes <= buf.nbytes and (self.fixed or 2 * nbytes > buf.nbytes)

    def take(self, shape: tuple[int, ...], dtype=np.float64) -> np.ndarray:
        """A C-contiguous array of ``shape`` and ``dtype`` (uninitialised), in a pooled
        buffer when one is free (or may be made), else newly allocated.

        Parameters
        ----------
        shape : tuple of int
        dtype : numpy dtype

        Returns
        -------
        numpy.ndarray
        """
        dtype = np.dtype(dtype)
        shape = tuple(int(s) for s in shape)
        nbytes = math.prod(shape) * dtype.itemsize
        if not self.min_bytes <= nbytes <= self.max_bytes or dtype.alignment > _ALIGNMENT:
            return np.empty(shape, dtype)
        with self._lock:
            idle = self._idle()
            fitting = [i for i in idle if self._fits(self._buffers[i], nbytes)]
            if fitting:
                buf = min((self._buffers[i] for i in fitting), key=lambda b: b.nbytes)
            else:
                buf = self._new_buffer(self._size_for(nbytes), idle)
                if buf is None:
                    return np.empty(shape, dtype)
            return buf[:nbytes].view(dtype).reshape(shape)

    def _new_buffer(self, size: int, idle: list[int]) -> np.ndarray | None:
        """A new pooled buffer of ``size`` bytes, dropping idle buffers (largest first) while
        the pool is full or the room is short; ``None`` when that is not enough."""
        kept = [b.nbytes for b in self._buffers]
        drop = sorted(idle, key=lambda i: -kept[i])
        n_drop = 0
        while (len(kept) - n_drop >= self.keep
               or sum(kept) - sum(kept[i] for i in drop[:n_drop]) + size > self.max_total_bytes):
            if n_drop == len(drop):
                return None
            n_drop += 1
        for i in sorted(drop[:n_drop], reverse=True):
            del self._buffers[i]
        buf = np.empty(size, np.uint8)
        self._buffers.append(buf)
        return buf

    def clear(self) -> None:
        """Forget every buffer (those still in use stay alive with their arrays)."""
        with self._lock:
            self._buffers.clear()
