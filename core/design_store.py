"""Arrays a library computed once, kept on disk by what they were computed from.

The EN filters' Butterworth designs (:func:`railval.core.filters.design`) and the Welch
window and frequencies (:func:`railval.core.psd.welch_setup`) are made by ``scipy.signal``,
whose import alone takes 0.7–1.2 s (SciPy 1.17 rewrites the docstrings of every array-API
function as it loads). A command that only filters and estimates PSDs with the compiled
kernels needs a handful of numbers from it; this store keeps those numbers, so a later
process reads them instead of importing ``scipy.signal`` (docs/app.md, "Start-up by need").

* **Key**: the name of what was computed, its inputs (exact ``repr`` of the floats) and the
  version of the library that computed it; another SciPy computes its designs anew.
* **Where**: the ``__pycache__`` folder beside this module — the place Python keeps this
  package's compiled bytecode and numba its compiled kernels. Whoever can write there can
  change the code that runs, so the store asks no more trust than the code itself; it is
  never a folder of the user's (``~/.cache``) that another program could write. Where that
  folder cannot be written (a read-only install), nothing is stored and every process
  computes the arrays itself, with the same result.
* **Reading**: ``numpy.load`` without pickles; a file that cannot be read, lacks an array
  or fails the caller's ``check`` is computed again and replaced. Files are written to a
  temporary name and renamed, so a reader never sees half a file.
* **Size**: at most :data:`MAX_FILES` files (≈ 13 kB each); a write beyond it removes the
  files used longest ago (a read marks its file as used) down to three quarters of it, so a
  process that filters at ever new rates cannot fill the disk.

The arrays are those the library returned, bit for bit (``tests/test_design_store.py``).
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import zipfile
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

#: the store's folder (:data:`STORE_ENV` names another, for tests and read-only installs)
STORE = Path(__file__).resolve().parent / "__pycache__" / "railval-designs"
#: environment variable naming the store's folder; empty: no store (compute every time)
STORE_ENV = "RAILVAL_DESIGN_STORE"
#: the layout of the stored files; a new layout ignores the old files
LAYOUT = 1
#: most files the store keeps (the EN chain at a dozen rates needs ≈ 50; 512 ≈ 7 MB)
MAX_FILES = 512


def folder() -> Path | None:
    """The store's folder, or None when it is switched off (``RAILVAL_DESIGN_STORE=""``)."""
    value = os.environ.get(STORE_ENV)
    if value is None:
        return STORE
    return Path(value) if value.strip() else None


def file_for(key: str) -> Path | None:
    """The file that holds the arrays of ``key`` (None: no store)."""
    base = folder()
    if base is None:
        return None
    digest = hashlib.sha256(f"{LAYOUT}\n{key}".encode()).hexdigest()[:32]
    return base / f"{digest}.npz"


def _read(path: Path, key: str, names: tuple[str, ...]) -> dict[str, np.ndarray] | None:
    try:
        with np.load(path, allow_pickle=False) as data:
            if str(data["key"]) != key or any(n not in data for n in names):
                return None
            return {n: np.array(data[n]) for n in names}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None


def _write(path: Path, key: str, arrays: Mapping[str, np.ndarray]) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".npz", dir=path.parent)
    except OSError:
        return  # not writable: every process computes the arrays
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, key=np.array(key), **arrays)
        os.replace(tmp, path)
    except OSError:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        return
    _trim(path.parent)


def _trim(base: Path) -> None:
    """Remove the files used longest ago (modification time, which a read renews) while the
    store holds more than :data:`MAX_FILES`, down to three quarters of it. Another process
    trimming at the same time or a file gone meanwhile is no error."""
    try:
        files = list(base.glob("*.npz"))
    except OSError:
        return
    if len(files) <= MAX_FILES:
        return
    aged = []
    for f in files:
        try:
            aged.append((f.stat().st_mtime_ns, f))
        except OSError:
            continue
    aged.sort()
    for _, f in aged[:max(0, len(aged) - (3 * MAX_FILES) // 4)]:
        try:
            f.unlink()
        except OSError:
            pass


def arrays(key: str, compute: Callable[[], Mapping[str, np.ndarray]], names: tuple[str, ...],
           check: Callable[[Mapping[str, np.ndarray]], bool] | None = None) -> dict[str, np.ndarray]:
    """The arrays ``names`` of ``key``: read from the store, else ``compute()`` (stored for
    the next process). ``check(arrays)`` False on what was read: computed again and replaced.
    ``key`` must name everything the arrays depend on (inputs and library version)."""
    path = file_for(key)
    if path is not None and path.is_file():
        got = _read(path, key, names)
        if got is not None and (check is None or check(got)):
            try:
                os.utime(path)  # used now: the last to go when the store is trimmed
            except OSError:
                pass
            return got
    made = {n: np.asarray(v) for n, v in compute().items()}
    if path is not None:
        _write(path, key, {n: made[n] for n in names})
    return {n: made[n] for n in names}


__all__ = ["LAYOUT", "MAX_FILES", "STORE", "STORE_ENV", "arrays", "file_for", "folder"]
