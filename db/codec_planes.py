"""Compiled join of a codec-2 blob of an 8-byte dtype (:mod:`railval.db.codec`): the plane
table walked, the zlib planes inflated and the planes interleaved in one call, without the
interpreter between the planes.

The inflate is libdeflate's ``libdeflate_zlib_decompress`` — the very function the
``deflate`` binding (:func:`railval.db.codec._libdeflate_inflate`) calls, with the same
input bytes and output size, found in that binding's extension module — called from the
kernel through its address (:func:`_call_inflate`), into a scratch buffer of the thread.
So a plane inflates to the bytes the binding returns, with no ``bytearray`` allocated per
plane, no GIL held (the binding holds it) and no interpreter work per plane: ≈ 0.006 CPU-s
less per DynoTRAIN source (357 blobs, 534 zlib planes).

The kernel only succeeds on a well-formed payload; any irregularity (truncation, unknown
flag, a stream that does not inflate to exactly the plane size, trailing bytes) returns a
non-zero status and :func:`railval.db.codec._join_planes` decodes the blob again on its
interpreted path, which raises the error it always raised. Importing this module imports
numba (:mod:`railval.db.codec` imports it on first use); the kernel is cached on disk
(``cache=True``: the function address is an argument, not a constant of the code).
"""

from __future__ import annotations

import ctypes
import threading

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic


@intrinsic
def _call_inflate(typingctx, fn, dec, src, src_len, dst, dst_len, actual):
    """``((*fn)(dec, src, src_len, dst, dst_len, actual))`` with every argument an address or
    a size (``uintp``): libdeflate's ``enum libdeflate_result
    libdeflate_zlib_decompress(struct libdeflate_decompressor *, const void *in, size_t
    in_nbytes, void *out, size_t out_nbytes_avail, size_t *actual_out_nbytes_ret)``
    (libdeflate.h)."""
    args = (fn, dec, src, src_len, dst, dst_len, actual)
    if not all(isinstance(a, types.Integer) and a.bitwidth == 64 for a in args):
        return None
    sig = types.int32(*args)

    def codegen(context, builder, signature, args):
        word = ir.IntType(64)
        ptr = ir.IntType(8).as_pointer()
        fnty = ir.FunctionType(ir.IntType(32), [ptr, ptr, word, ptr, word, ptr])
        call = builder.inttoptr(args[0], fnty.as_pointer())
        return builder.call(call, [builder.inttoptr(args[1], ptr), builder.inttoptr(args[2], ptr),
                                   args[3], builder.inttoptr(args[4], ptr), args[5],
                                   builder.inttoptr(args[6], ptr)])

    return sig, codegen


@numba.njit(cache=True, nogil=True)
def interleave8(out, src, extra, offsets):  # pragma: no cover - compiled
    """``out[i]`` = the 8 bytes ``plane_k[i]`` (k = 0 … 7, little-endian) of a codec-2
    payload; plane k is ``src[offsets[k]:]`` when ``offsets[k] ≥ 0``, else
    ``extra[-1 - offsets[k]:]`` (the byte shuffle of :mod:`railval.db.codec`, undone). The
    join of :func:`_join8` and of the codec's interpreted plane path."""
    n = out.size
    o0, o1, o2, o3 = offsets[0], offsets[1], offsets[2], offsets[3]
    o4, o5, o6, o7 = offsets[4], offsets[5], offsets[6], offsets[7]
    p0 = src[o0:o0 + n] if o0 >= 0 else extra[-1 - o0:-1 - o0 + n]
    p1 = src[o1:o1 + n] if o1 >= 0 else extra[-1 - o1:-1 - o1 + n]
    p2 = src[o2:o2 + n] if o2 >= 0 else extra[-1 - o2:-1 - o2 + n]
    p3 = src[o3:o3 + n] if o3 >= 0 else extra[-1 - o3:-1 - o3 + n]
    p4 = src[o4:o4 + n] if o4 >= 0 else extra[-1 - o4:-1 - o4 + n]
    p5 = src[o5:o5 + n] if o5 >= 0 else extra[-1 - o5:-1 - o5 + n]
    p6 = src[o6:o6 + n] if o6 >= 0 else extra[-1 - o6:-1 - o6 + n]
    p7 = src[o7:o7 + n] if o7 >= 0 else extra[-1 - o7:-1 - o7 + n]
    for i in range(n):
        out[i] = (np.uint64(p0[i]) | (np.uint64(p1[i]) << 8) | (np.uint64(p2[i]) << 16)
                  | (np.uint64(p3[i]) << 24) | (np.uint64(p4[i]) << 32)
                  | (np.uint64(p5[i]) << 40) | (np.uint64(p6[i]) << 48)
                  | (np.uint64(p7[i]) << 56))


@numba.njit(cache=True, nogil=True)
def _join8(out, src, pos, scratch, actual, fn, dec):  # pragma: no cover - compiled
    """Decode the codec-2 payload ``src[pos:]`` of ``out.size`` 8-byte elements into the
    uint64 array ``out``; 0 on success, else 1 (``out`` then holds anything). ``scratch``:
    room for 8 inflated planes; ``actual``: one uint64 for the inflated size; ``fn``/``dec``:
    the addresses of ``libdeflate_zlib_decompress`` and of a decompressor of this thread."""
    n = out.size
    end = src.size
    offsets = np.empty(8, np.int64)  # plane k: ≥ 0 its start in src, < 0 -1 - start in scratch
    base = np.int64(src.ctypes.data)
    sbase = np.int64(scratch.ctypes.data)
    out_actual = np.int64(actual.ctypes.data)
    used = 0
    for k in range(8):
        if end < pos + 5:
            return 1
        flag = src[pos]
        length = (np.int64(src[pos + 1]) | (np.int64(src[pos + 2]) << 8)
                  | (np.int64(src[pos + 3]) << 16) | (np.int64(src[pos + 4]) << 24))
        pos += 5
        if end < pos + length:
            return 1
        if flag == 0:
            if length != n:
                return 1
            offsets[k] = pos
        elif flag == 1:
            if n == 0:
                return 1
            res = _call_inflate(fn, dec, base + pos, length, sbase + used, np.int64(n),
                                out_actual)
            if res != 0 or actual[0] != n:
                return 1
            offsets[k] = -1 - used
            used += n
        else:
            return 1
        pos += length
    if pos != end:
        return 1
    interleave8(out, src, scratch, offsets)
    return 0


def _libdeflate():
    """``(address of libdeflate_zlib_decompress, alloc, free)`` from the ``deflate``
    extension module (it exports libdeflate's symbols), or ``None``."""
    try:
        from deflate import _deflate

        lib = ctypes.CDLL(_deflate.__file__)
        decompress = ctypes.cast(lib.libdeflate_zlib_decompress, ctypes.c_void_p).value
        alloc = lib.libdeflate_alloc_decompressor
        free = lib.libdeflate_free_decompressor
    except (ImportError, OSError, AttributeError):  # pragma: no cover - other builds
        return None
    alloc.restype = ctypes.c_void_p
    alloc.argtypes = []
    free.restype = None
    free.argtypes = [ctypes.c_void_p]
    return decompress, alloc, free


_LIB = _libdeflate()
#: the kernel is usable (libdeflate's symbols found)
AVAILABLE = _LIB is not None


class _Decompressor:
    """A libdeflate decompressor (not thread-safe: one per thread), freed with this object."""

    def __init__(self):
        self.address = _LIB[1]() or 0
        self._free = _LIB[2]  # kept: module globals may be gone when this is collected
        self.actual = np.zeros(1, np.int64)
        self.scratch = np.empty(0, np.uint8)  # read-only view: the kernel reads src and it
        self.scratch.flags.writeable = False    # alike (the C call writes through its address)

    def __del__(self):
        if self.address:
            self._free(self.address)
            self.address = 0


_LOCAL = threading.local()


def join8(out: np.ndarray, src: np.ndarray, pos: int) -> bool:
    """Decode the codec-2 payload ``src[pos:]`` (uint8) into the flat 8-byte ``out``; False
    when the payload is irregular (nothing raised: the caller's interpreted path reports
    it) or no decompressor could be made."""
    d = getattr(_LOCAL, "d", None)
    if d is None:
        d = _LOCAL.d = _Decompressor()
    if not d.address:
        return False
    if d.scratch.size < 8 * out.size:
        d.scratch = np.empty(8 * out.size, np.uint8)
        d.scratch.flags.writeable = False
    if src.flags.writeable:  # one compiled form: both byte sources read-only
        src = src.view()
        src.flags.writeable = False
    return _join8(out.view(np.uint64), src, pos, d.scratch, d.actual, _LIB[0], d.address) == 0
