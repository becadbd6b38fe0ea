"""Gzip of the server's responses, compressed once per static file and process (docs/app.md,
"Cheap sessions").

Every new browser session downloads Panel's and Bokeh's static bundles (≈ 6 MB of JavaScript
and CSS); Tornado's :class:`tornado.web.GZipContentEncoding` compresses them again for every
request, which was the largest single server cost of a new session (≈ 16 % of the CPU
samples of a served app while engineers signed in, docs/app.md). :class:`CachedGZip` keeps
the gzip bytes of a static response — a ``GET`` answered 200 with an ``Etag`` under
``/static/`` (Tornado's ``StaticFileHandler`` and Bokeh's subclass set the Etag from the
file's content hash) — keyed by path and Etag, and sends them again instead of compressing.
Anything else is compressed as Tornado does. The cache is bounded (:data:`MAX_BYTES`).
"""

from __future__ import annotations

import threading

from tornado.web import GZipContentEncoding

#: most bytes of compressed static responses kept per process (the bundles are ≈ 1.5 MB gzipped)
MAX_BYTES = 32 * 1024 * 1024

_cache: dict[tuple[str, str], bytes] = {}
_lock = threading.Lock()


def cached_size() -> int:
    """Bytes held by the cache now."""
    with _lock:
        return sum(len(v) for v in _cache.values())


def clear() -> None:
    with _lock:
        _cache.clear()


class CachedGZip(GZipContentEncoding):
    """:class:`tornado.web.GZipContentEncoding` that compresses a static file once: the first
    response is compressed chunk by chunk and its gzip bytes kept; a later response with the
    same path and Etag sends the kept bytes whole (one chunk, its Content-Length) and drops
    the file's chunks the handler still writes."""

    def __init__(self, request) -> None:
        super().__init__(request)
        self._static = request.method == "GET" and request.path.startswith("/static/")
        self._path = request.path
        self._key: tuple[str, str] | None = None
        self._hit = False
        self._parts: list[bytes] = []

    def transform_first_chunk(self, status_code, headers, chunk, finishing):
        etag = headers.get("Etag")
        if self._gzipping and self._static and status_code == 200 and etag:
            self._key = (self._path, etag)
            with _lock:
                body = _cache.get(self._key)
            if body is not None:
                self._hit = True
                headers["Vary"] = (headers["Vary"] + ", Accept-Encoding") if "Vary" in headers else "Accept-Encoding"
                headers["Content-Encoding"] = "gzip"
                headers["Content-Length"] = str(len(body))
                return status_code, headers, body
        return super().transform_first_chunk(status_code, headers, chunk, finishing)

    def transform_chunk(self, chunk: bytes, finishing: bool) -> bytes:
        if self._hit:
            return b""
        out = super().transform_chunk(chunk, finishing)
        if self._key is not None and self._gzipping:
            self._parts.append(out)
            if finishing:
                body = b"".join(self._parts)
                self._parts = []
                with _lock:
                    if sum(len(v) for v in _cache.values()) + len(body) <= MAX_BYTES:
                        _cache[self._key] = body
        return out
