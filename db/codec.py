"""Array codec: numpy array ⇄ compressed blob with a content hash.

Blob layout (all integers little-endian)::

    magic   4 bytes   b"RVA1"
    codec   1 byte    0 = raw, 1 = byte-shuffle + zlib, 2 = byte planes, each zlib or raw
    level   1 byte    zlib level used (informative)
    dlen    1 byte    length of the dtype string
    ndim    1 byte    number of dimensions
    dtype   dlen      numpy dtype string, always little-endian (``"<f8"``, ``"<i4"``, ``"|u1"``)
    shape   8·ndim    uint64 per dimension
    payload           codec 0: the C-ordered element bytes; codec 1: zlib(byte-shuffled
                      bytes); codec 2: per byte plane k = 0 … itemsize−1 a flag byte
                      (0 raw, 1 zlib), a uint32 length and the plane's bytes

Byte shuffling (the HDF5/Blosc "shuffle" filter) groups byte ``k`` of every element
together; for measured floating-point signals the sign/exponent and high mantissa planes
compress well while the low mantissa planes are noise. Codec 2 (written by
:func:`encode`) therefore probes each plane and stores noise planes raw, which halves the
encoding time against compressing everything at the same size. A blob falls back to codec
0 when compression would not save space. Codec 1 is still decoded.

Content hash: SHA-256 over ``b"dtype=<f8;shape=6000;"`` followed by the raw little-endian
C-ordered element bytes. It depends on the values only, never on the compression, so the
same samples always have the same hash whatever file format or codec carried them
(export → import reproduces it).

Decoding inflates with libdeflate (``deflate``) or ISA-L (``isal.isal_zlib``), whichever is
installed, in that order, else the standard :mod:`zlib` — the same stream format, identical
bytes; both come with ``asammdf`` (the ``formats`` extra). On the 714 compressed planes of
one source of the 6-configuration bench database they take 0.030 and 0.032 CPU-s against
0.066 s for :mod:`zlib`. With libdeflate, a well-formed codec-2 blob of an 8-byte dtype is
decoded by one compiled call (:mod:`railval.db.codec_planes`: plane table, libdeflate's
inflate called by address without the GIL, join straight into the output array); otherwise
the byte planes are inflated by the binding and joined by one compiled pass
(:func:`railval.db.codec_planes.interleave8`), and an irregular payload raises its error there. numba is imported on
first use: importing this module does not import it. :func:`decode_many` decodes a list of
blobs on the shared row threads (:func:`railval.core.workers.split_rows`): SHA-256
(:mod:`hashlib`), the compiled decode and the join release the GIL, so the hash of one blob
overlaps the decode of another. Neither libdeflate's nor ISA-L's Python binding releases the
GIL (two threads inflating 20 kB planes take as long as one; two threads hashing take half
the time).
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import math
import os
import struct
import threading
import zlib
from collections.abc import Sequence

import numpy as np

from railval.core import lazy
from railval.core.buffers import BufferPool
from railval.core.errors import InvalidSignal

#: deferred (railval.core.lazy): the worker-thread helpers only for a read of many blobs
split_rows = lazy.function("railval.core.workers", "split_rows")
thread_count = lazy.function("railval.core.workers", "thread_count")

MAGIC = b"RVA1"
CODEC_RAW = 0
CODEC_SHUFFLE_ZLIB = 1
CODEC_PLANES = 2
_PLANE = struct.Struct("<BI")
#: a plane is stored raw when zlib shrinks its first PROBE bytes, or the whole plane, by
#: less than MIN_SAVING: a plane that saves less costs more to inflate on every read than its
#: bytes cost to store (the second-highest mantissa plane of measured forces saves ≈ 28 % and
#: was a quarter of the inflate work of a DynoTRAIN source; stored raw, the source takes
#: 1.5 % more space, docs/database.md)
PROBE = 1024
MIN_SAVING = 0.3
_FIXED = struct.Struct("<4sBBBB")
_ALLOWED_KINDS = "fiub"

try:  # ISA-L inflate: same stream format as zlib, faster; optional
    from isal.isal_zlib import decompress as _isal_decompress
    from isal.isal_zlib import error as _isal_error
except ImportError:  # pragma: no cover - depends on the installation
    _isal_decompress = None
    _isal_error = zlib.error
try:  # libdeflate: same stream format, faster still on byte planes; optional
    from deflate import DeflateError as _deflate_error
    from deflate import zlib_decompress as _deflate_decompress
except ImportError:  # pragma: no cover - depends on the installation
    _deflate_decompress = None
    _deflate_error = zlib.error


def _zlib_inflate(data, size_hint: int) -> bytes:
    return zlib.decompress(data, bufsize=max(size_hint, 1))


def _isal_inflate(data, size_hint: int) -> bytes:
    return _isal_decompress(data, bufsize=max(size_hint, 1))


def _libdeflate_inflate(data, size_hint: int) -> bytes:
    """libdeflate needs the output size up front: ``size_hint`` is the most it may give (a
    longer stream is an error, a shorter one returns fewer bytes)."""
    return _deflate_decompress(data, max(size_hint, 1))


#: the inflate used by :func:`decode` (libdeflate, else ISA-L, else :mod:`zlib`)
inflate = (_libdeflate_inflate if _deflate_decompress is not None
           else _isal_inflate if _isal_decompress is not None else _zlib_inflate)
_INFLATE_ERRORS = (zlib.error, _isal_error, _deflate_error)


def _canonical(array: np.ndarray) -> np.ndarray:
    a = np.asarray(array)
    if a.dtype.kind not in _ALLOWED_KINDS:
        raise InvalidSignal(
            f"array dtype {a.dtype} is not storable (allowed: float, signed/unsigned int, bool)"
        )
    if a.dtype.byteorder == ">" or (a.dtype.byteorder == "=" and not _LITTLE):
        a = a.astype(a.dtype.newbyteorder("<"))
    return np.ascontiguousarray(a)


_LITTLE = np.little_endian


def content_hash(array: np.ndarray) -> str:
    """SHA-256 hex digest of the canonical dtype, shape and raw bytes of ``array``."""
    a = _canonical(array)
    return _hash_canonical(a)


def _hash_canonical(a: np.ndarray) -> str:
    h = _hash_prefix(a.dtype.str, a.shape).copy()
    h.update(a.reshape(-1).view(np.uint8))
    return h.hexdigest()


@functools.lru_cache(maxsize=256)
def _hash_prefix(dtype_str: str, shape: tuple[int, ...]):
    """SHA-256 state after ``dtype=…;shape=…;`` (copied for every array of that kind)."""
    h = hashlib.sha256()
    h.update(f"dtype={dtype_str};shape={'x'.join(str(s) for s in shape)};".encode("ascii"))
    return h


def encode(array: np.ndarray, *, level: int = 1, allow_nonfinite: bool = True) -> tuple[bytes, str]:
    """Encode ``array`` to a self-describing compressed blob; return ``(blob, sha256)``.

    ``allow_nonfinite=False`` rejects NaN/±inf with :class:`railval.core.errors.InvalidSignal`.
    Object, string and complex dtypes are rejected.
    """
    a = _canonical(array)
    if not allow_nonfinite and a.dtype.kind == "f" and a.size and not np.isfinite(a).all():
        bad = int(np.flatnonzero(~np.isfinite(a.ravel()))[0])
        raise InvalidSignal(f"array holds a non-finite value at flat index {bad}: {a.ravel()[bad]}")
    if a.ndim > 255:
        raise InvalidSignal(f"array has {a.ndim} dimensions, at most 255 are storable")
    sha = _hash_canonical(a)
    dstr = a.dtype.str.encode("ascii")
    header = _FIXED.pack(MAGIC, CODEC_PLANES, level, len(dstr), a.ndim) + dstr
    header += struct.pack(f"<{a.ndim}Q", *a.shape)
    raw = a.reshape(-1).view(np.uint8)
    itemsize = a.dtype.itemsize
    planes = raw.reshape(a.size, itemsize).T if a.size else raw.reshape(itemsize, 0)
    parts = [header]
    size = len(header)
    for plane in planes:
        data = plane.tobytes()
        probe = data[:PROBE]
        if probe and len(zlib.compress(probe, level)) < (1 - MIN_SAVING) * len(probe):
            packed = zlib.compress(data, level)
            if len(packed) < (1 - MIN_SAVING) * len(data):
                parts += [_PLANE.pack(1, len(packed)), packed]
                size += _PLANE.size + len(packed)
                continue
        parts += [_PLANE.pack(0, len(data)), data]
        size += _PLANE.size + len(data)
    if size >= len(header) + raw.nbytes:
        header = bytes([*header[:4], CODEC_RAW, 0]) + header[6:]
        return header + raw.tobytes(), sha
    return b"".join(parts), sha


class VerifiedCache:
    """Blobs already verified in this process, and the arrays decoded from them, by content
    hash (LRU, at most ``limit_bytes`` of arrays and blobs).

    An entry keeps the blob it was decoded from; a hit requires the same content hash *and*
    byte-for-byte the same blob (a comparison at memory speed, ~10 GB/s, against ~0.3 ms
    of inflate and SHA-256 for a 160 kB signal), so the result is exactly what decoding and
    verifying that blob gives — a blob changed in the database since is decoded and verified
    again. Never used without an expected hash: a first read is always verified.

    :func:`decode` records a first read with :meth:`mark` (the blob only: copying the
    arrays of a source cost 0.02–0.03 CPU-s, a fifth of its old decode); a second read
    of the same blob decodes without the hash and keeps a copy of the array (:meth:`put`);
    later reads return a copy of it (:meth:`get`; callers may write to their arrays).
    """

    def __init__(self, limit_bytes: int):
        from collections import OrderedDict

        self.limit_bytes = limit_bytes
        self.size = 0
        self.hits = 0
        self._entries: OrderedDict[str, tuple[bytes, np.ndarray | None]] = OrderedDict()
        self._lock = threading.Lock()

    def lookup(self, blob, sha: str) -> np.ndarray | bool:
        """A copy of the array kept for ``(blob, sha)``; ``True`` when that blob was verified
        but its array is not kept; ``False`` when the blob was not verified (no hit)."""
        with self._lock:
            entry = self._entries.get(sha)
            if entry is None or entry[0] != blob:
                return False
            self._entries.move_to_end(sha)
            self.hits += 1
        return True if entry[1] is None else entry[1].copy()

    def get(self, blob, sha: str) -> np.ndarray | None:
        """A copy of the array kept for ``(blob, sha)``, or ``None``."""
        found = self.lookup(blob, sha)
        return found if isinstance(found, np.ndarray) else None

    def mark(self, blob, sha: str) -> None:
        """Record that ``blob`` was decoded and matched ``sha`` (keeps the blob only)."""
        self._store(bytes(blob), sha, None)

    def put(self, blob, sha: str, array: np.ndarray) -> None:
        """Keep a copy of ``array``, decoded from ``blob`` and verified against ``sha``."""
        if len(blob) + array.nbytes <= self.limit_bytes:
            self._store(bytes(blob), sha, array.copy())

    def _store(self, blob: bytes, sha: str, kept: np.ndarray | None) -> None:
        cost = len(blob) + (0 if kept is None else kept.nbytes)
        if cost > self.limit_bytes:
            return
        with self._lock:
            old = self._entries.pop(sha, None)
            if old is not None:
                self.size -= len(old[0]) + (0 if old[1] is None else old[1].nbytes)
            self._entries[sha] = (blob, kept)
            self.size += cost
            while self.size > self.limit_bytes:
                _, (b, a) = self._entries.popitem(last=False)
                self.size -= len(b) + (0 if a is None else a.nbytes)

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()
            self.size = 0


#: the process's verified-array cache used by :func:`decode` (``$RAILVAL_DECODE_CACHE_MB``,
#: default 512 MB — the measured side of a DynoTRAIN-size campaign (340 signals of 20 000
#: samples, 54 MB decoded + its blobs) several times over; 0 turns it off)
VERIFIED = VerifiedCache(int(float(os.environ.get("RAILVAL_DECODE_CACHE_MB", "512")) * 2**20))


def decode(blob: bytes, expected_sha: str | None = None) -> np.ndarray:
    """Decode a blob made by :func:`encode` to a new array.

    Checks magic, codec, dtype and that the payload length matches the shape; with
    ``expected_sha`` also verifies the content hash. Raises :class:`InvalidSignal`.
    A verified decode is recorded in :data:`VERIFIED`: the same blob with the same expected
    hash is then not hashed again, and from its third read on not decoded (a copy of the
    array kept at the second read is returned).
    """
    return _decode_cached(blob, expected_sha, None)


def _decode_cached(blob, expected_sha: str | None, out: np.ndarray | None,
                   head: tuple | None = None) -> np.ndarray:
    """:func:`decode` through :data:`VERIFIED` (``out``, ``head``: see :func:`_decode`)."""
    if expected_sha is None or VERIFIED.limit_bytes <= 0:
        return _decode(blob, expected_sha, out, head)
    found = VERIFIED.lookup(blob, expected_sha)
    if found is False:
        array = _decode(blob, expected_sha, out, head)
        VERIFIED.mark(blob, expected_sha)
    elif found is True:  # this very blob was verified before: decode, keep the array
        array = _decode(blob, None, out, head)
        VERIFIED.put(blob, expected_sha, array)
    else:
        array = found
    return array


class BlobError(InvalidSignal):
    """:func:`decode_many`: item ``index`` failed to decode or verify (the message says why)."""

    def __init__(self, message: str, index: int):
        super().__init__(message)
        self.index = index


#: :func:`decode_many` decodes on one thread below this many blobs per thread
MIN_BLOBS_PER_THREAD = 4


def decode_many(items: Sequence[tuple[bytes, str | None]]) -> list[np.ndarray]:
    """``[decode(blob, sha) for blob, sha in items]`` on up to
    :func:`railval.core.workers.thread_count` threads (``$RAILVAL_THREADS``).

    The threads take the next blob from a shared counter (a blob is decoded whole by one
    thread); SHA-256 and the plane join release the GIL, the inflate does not (module
    docstring), so two threads overlap one blob's hash with another's inflate. Every blob is
    decoded and verified exactly as :func:`decode` does it (same :data:`VERIFIED` cache).
    Raises :class:`BlobError` for the first failing item in list order.
    """
    n = len(items)
    out, heads = _preallocate(items)
    failed: list[tuple[int, str]] = []
    taken = itertools.count()  # next() is atomic under the GIL

    def work(_start: int, _stop: int) -> None:
        while not failed and (i := next(taken)) < n:
            try:
                out[i] = _decode_cached(items[i][0], items[i][1], out[i], heads[i])
            except InvalidSignal as exc:
                failed.append((i, str(exc)))

    threads = min(thread_count(), n // MIN_BLOBS_PER_THREAD)
    if threads <= 1 or threading.current_thread().name.startswith("railval-rows"):
        work(0, n)  # in a pool thread already: never wait on the pool from inside it
    else:
        split_rows(work, threads)
    if failed:
        # every item before the first failure was taken earlier and finished by its thread
        index, message = min(failed)
        raise BlobError(message, index)
    return out


def _preallocate(items: Sequence[tuple[bytes, str | None]]
                 ) -> tuple[list[np.ndarray | None], list[tuple | None]]:
    """Output arrays for the codec-2 blobs of ``items``: rows of one block per dtype and
    shape (``None`` for the others, and for a blob whose header does not parse), and the
    parsed header (:func:`_header`) of each blob (``None`` where it does not parse).

    One large allocation instead of one per blob: the kernel maps fresh memory for both, but
    a block of many signals is mapped with far fewer page faults (transparent huge pages;
    numpy advises them for large arrays) — ≈ 13 900 faults and 0.03–0.05 CPU-s for 357
    arrays of 160 kB against ≈ 660 faults and 0.012–0.017 CPU-s for one block; a pooled
    buffer (:class:`_BlockPool`) needs neither. Rows of a block share its memory: it is
    released (or free for reuse) when no row is referenced any more.
    """
    groups: dict[tuple[np.dtype, tuple[int, ...]], list[int]] = {}
    heads: list[tuple | None] = [None] * len(items)
    for i, (blob, _sha) in enumerate(items):
        try:
            heads[i] = head = _header(memoryview(blob))
        except InvalidSignal:
            continue  # decoding it reports the problem
        codec, dtype, shape = head[:3]
        if codec == CODEC_PLANES:
            groups.setdefault((dtype, shape), []).append(i)
    out: list[np.ndarray | None] = [None] * len(items)
    for (dtype, shape), idx in groups.items():
        rows = max(1, BLOCK_BYTES // max(1, dtype.itemsize * math.prod(shape)))
        for first in range(0, len(idx), rows):
            part = idx[first:first + rows]
            block = _BLOCKS.take((len(part), *shape), dtype)
            for row, i in enumerate(part):
                out[i] = block[row]
    return out, heads


#: bytes per preallocated output block of :func:`decode_many`
BLOCK_BYTES = 64 << 20


class _BlockPool(BufferPool):
    """Buffers of :data:`BLOCK_BYTES` for output blocks, reused once no array uses them
    (:class:`railval.core.buffers.BufferPool`, fixed size).

    Fresh memory costs the kernel a page fault and zero fill per page (≈ 0.017 CPU-s for
    the 57 MB of one DynoTRAIN source, a fifth of its decode); a buffer whose arrays are
    all gone is handed out again as it is. At most ``keep`` buffers are kept (the pipeline
    of the validation service has two chunks in flight); blocks above a buffer or below a
    quarter of one, or more at once, are ordinary allocations.
    """

    def __init__(self, keep: int):
        super().__init__(keep, BLOCK_BYTES, BLOCK_BYTES // 4, fixed=True)


#: the output buffers of :func:`decode_many` (two: ≤ 128 MB kept per process)
_BLOCKS = _BlockPool(2)


def _header(mv: memoryview) -> tuple[int, np.dtype, tuple[int, ...], int, int]:
    """``(codec, dtype, shape, size, payload start)`` of a blob; raises :class:`InvalidSignal`."""
    if len(mv) < _FIXED.size:
        raise InvalidSignal(f"blob of {len(mv)} bytes is shorter than the {_FIXED.size}-byte header")
    magic, codec, _level, dlen, ndim = _FIXED.unpack_from(mv, 0)
    if magic != MAGIC:
        raise InvalidSignal(f"blob magic {bytes(magic)!r} is not {MAGIC!r}")
    pos = _FIXED.size
    dfield = bytes(mv[pos : pos + dlen])
    dtype = _DTYPES.get(dfield)
    if dtype is None:
        try:
            dtype = np.dtype(dfield.decode("ascii"))
        except (TypeError, UnicodeDecodeError) as exc:
            raise InvalidSignal(f"blob dtype field is invalid: {exc}") from None
        if dtype.kind not in _ALLOWED_KINDS:
            raise InvalidSignal(f"blob dtype {dtype} is not storable")
        if len(_DTYPES) < 64:
            _DTYPES[dfield] = dtype
    pos += dlen
    if len(mv) < pos + 8 * ndim:
        raise InvalidSignal("blob truncated inside the shape field")
    shape = struct.unpack_from(f"<{ndim}Q", mv, pos)
    size = 1
    for s in shape:
        size *= s
    return codec, dtype, shape, size, pos + 8 * ndim


#: dtype field of a blob → its (storable) dtype, so the header parse skips ``np.dtype``
_DTYPES: dict[bytes, np.dtype] = {}


def _decode(blob: bytes, expected_sha: str | None, out: np.ndarray | None = None,
            head: tuple | None = None) -> np.ndarray:
    """Decode (and with ``expected_sha`` verify) one blob; a codec-2 blob is written into
    ``out`` when that is a C-contiguous array of its dtype and shape (else a new array).
    ``head``: the blob's :func:`_header` when already parsed."""
    mv = memoryview(blob)
    codec, dtype, shape, size, pos = _header(mv) if head is None else head
    nbytes = size * dtype.itemsize
    if codec == CODEC_PLANES:
        if out is None or out.shape != shape or out.dtype != dtype or not out.flags.c_contiguous:
            out = np.empty(shape, dtype)
        _join_planes(mv, pos, out.reshape(-1))
        return _verified(out, expected_sha)
    payload = mv[pos:]
    if codec == CODEC_RAW:
        data = payload
    elif codec == CODEC_SHUFFLE_ZLIB:
        try:
            data = inflate(payload, nbytes)
        except _INFLATE_ERRORS as exc:
            raise InvalidSignal(f"blob payload does not decompress: {exc}") from None
    else:
        raise InvalidSignal(f"blob codec {codec} is unknown (known: 0 raw, 1 shuffle+zlib, "
                            "2 byte planes)")
    if len(data) != nbytes:
        raise InvalidSignal(
            f"blob payload holds {len(data)} bytes, shape {shape} of {dtype} needs {nbytes}"
        )
    if codec == CODEC_SHUFFLE_ZLIB and dtype.itemsize > 1 and size:
        out = np.frombuffer(data, np.uint8).reshape(dtype.itemsize, size).T.copy()
        array = out.view(dtype).reshape(shape)
    else:
        array = np.frombuffer(data, dtype).reshape(shape).copy()
    return _verified(array, expected_sha)


def _verified(array: np.ndarray, expected_sha: str | None) -> np.ndarray:
    if expected_sha is not None:
        got = _hash_canonical(array)
        if got != expected_sha:
            raise InvalidSignal(f"blob content hash {got} differs from the expected {expected_sha}")
    return array


def _join_planes(mv: memoryview, pos: int, out: np.ndarray) -> None:
    """Write the byte planes of a codec-2 payload starting at ``mv[pos]`` into the flat
    array ``out`` (its dtype and size are the header's).

    Raw planes are read in place in the blob; the compressed ones are inflated. With
    libdeflate, an 8-byte dtype is decoded by one compiled call
    (:func:`railval.db.codec_planes.join8`: plane table, inflate and join). Otherwise an
    8-byte dtype is joined by :func:`railval.db.codec_planes.interleave8` in one pass
    (≈ 14 µs for 20 000 elements against ≈ 55 µs for eight strided numpy copies); other
    sizes write each plane into its byte column (a strided uint8 copy).
    """
    itemsize, size = out.dtype.itemsize, out.size
    if itemsize == 8 and size and _LITTLE and inflate is _libdeflate_inflate:
        planes = _planes_module()
        if planes is not None and planes.join8(out, np.frombuffer(mv, np.uint8), pos):
            return  # else the loop below decodes it again and reports what is wrong
    offsets = [0] * itemsize  # plane k: ≥ 0 its start in the blob, < 0 -1 - start in `extra`
    inflated: list[bytes] = []
    end = len(mv)
    for k in range(itemsize):
        if end < pos + _PLANE.size:
            raise InvalidSignal(f"blob truncated before byte plane {k}")
        flag, length = _PLANE.unpack_from(mv, pos)
        pos += _PLANE.size
        if end < pos + length:
            raise InvalidSignal(f"blob truncated inside byte plane {k}")
        if flag == 0:
            got = length
            offsets[k] = pos
        elif flag == 1:
            try:
                plane = inflate(mv[pos : pos + length], size)
            except _INFLATE_ERRORS as exc:
                raise InvalidSignal(f"byte plane {k} does not decompress: {exc}") from None
            got = len(plane)
            offsets[k] = -1 - size * len(inflated)
            inflated.append(plane)
        else:
            raise InvalidSignal(f"byte plane {k} has unknown flag {flag}")
        if got != size:
            raise InvalidSignal(f"byte plane {k} holds {got} bytes, the shape needs {size}")
        pos += length
    if pos != end:
        raise InvalidSignal(f"blob has {end - pos} trailing bytes after the last plane")
    if size:
        _fill_planes(out, np.frombuffer(mv, np.uint8), inflated, offsets)


def _fill_planes(out: np.ndarray, src: np.ndarray, inflated: list[bytes],
                 offsets: list[int]) -> None:
    """Write the byte planes (``offsets`` as in :func:`_join_planes`) into ``out``."""
    extra = np.frombuffer(inflated[0] if len(inflated) == 1 else b"".join(inflated) or b"\0",
                          np.uint8)
    if out.dtype.itemsize == 8 and _LITTLE:
        from railval.db.codec_planes import interleave8  # imports numba on first use

        interleave8(out.view(np.uint64), src, extra, np.array(offsets, np.int64))
        return
    size = out.size
    cols = out.view(np.uint8).reshape(size, out.dtype.itemsize)
    for k, o in enumerate(offsets):
        cols[:, k] = src[o : o + size] if o >= 0 else extra[-1 - o : -1 - o + size]


_PLANES: list = []
_PLANES_LOCK = threading.Lock()


def _planes_module():
    """:mod:`railval.db.codec_planes` (imported on first use: it imports numba), or ``None``
    when libdeflate's symbols are not found."""
    if not _PLANES:
        with _PLANES_LOCK:
            if not _PLANES:
                from railval.db import codec_planes

                _PLANES.append(codec_planes if codec_planes.AVAILABLE else None)
    return _PLANES[0]
