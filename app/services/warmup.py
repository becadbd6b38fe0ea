"""Load — on a fresh installation compile — the compiled kernels a validation runs, in a
separate low-priority process started by ``railval serve``.

The EN chain (:mod:`railval.core.filters`, :mod:`railval.core.en_kernels`,
:mod:`railval.core.en14363`), the blob codec (:mod:`railval.db.codec_planes`) and the
verdict's bootstrap (:mod:`railval.core.bootstrap`) are numba kernels
cached on disk (``cache=True``: ``__pycache__`` beside the module, or numba's per-user cache
directory when the installation is read-only). The first run after an installation compiles
them: about 25 s of one core on the 2-core reference machine, which the first user to press
Validate would otherwise wait through. :func:`start_background` runs :func:`warm` in a child
process while the server seeds the demo campaign and starts, so that user finds the kernels
compiled; when they already are, the child only loads them (≈ 1 CPU-s) and exits.

:func:`warm` goes the way a validation goes: arrays of every channel kind are encoded and
decoded by the codec (hash checked), then one batch of sections of every filter need runs
through :func:`railval.core.en14363.evaluate_batch` at the default filter order, with the
definition alternatives and supplementary values, and one bootstrap of a verdict, so the kernels are compiled for the types a
stored campaign gives them (tests/test_warmup.py checks that a validation afterwards compiles
nothing new). No database is opened and nothing is written except numba's cache.

``python -m railval.app.services.warmup`` runs :func:`warm` and prints its seconds as JSON.
``RAILVAL_NO_WARMUP=1`` stops ``railval serve`` from starting it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time

import numpy as np

from railval.core import lazy
from railval.core.types import CHANNELS, SectionInfo, SignalSet

#: deferred (railval.core.lazy): the warm-up child loads the EN chain inside its timed step
#: ("import_s"); the server process that starts it imports none of them
codec = lazy.module("railval.db.codec")
en14363 = lazy.module("railval.core.en14363")
bootstrap = lazy.module("railval.core.bootstrap")

#: environment variable that switches the background warm-up off (any non-empty value but "0")
NO_WARMUP_ENV = "RAILVAL_NO_WARMUP"


def _sections(rng: np.random.Generator):
    """Two sections (a curve and a straight) with every channel of the registry, stored and
    read back by the codec as a validation reads them."""
    fs, n = 200.0, 4000
    out_sets, infos = [], []
    for k, (radius, zone) in enumerate(((500.0, 3), (0.0, 1))):
        t = np.arange(n) / fs
        d = np.cumsum(np.full(n, 25.0 / fs)) - 25.0 / fs
        raw = {}
        for kind, spec in CHANNELS.items():
            for pos in spec.positions:
                base = 75.0 if kind == "Q" else 0.0
                raw[f"{kind}_{pos}"] = base + rng.standard_normal(n)
        blobs = [codec.encode(a) for a in [d, *raw.values()]]
        arrays = codec.decode_many(blobs)  # hashes checked, as on every read
        sset = SignalSet(fs, t, arrays[0], dict(zip(raw, arrays[1:], strict=True)))
        sset.hashes = {name: sha for name, (_b, sha) in zip(raw, blobs[1:], strict=True)}
        out_sets.append(sset)
        infos.append(SectionInfo(f"warm{k}", radius, 100.0, 90.0, zone, 100.0, 400.0))
    return out_sets, infos


def warm() -> dict[str, float]:
    """Compile or load the kernels of a validation (module docstring); returns the seconds
    of each step."""
    t0 = time.perf_counter()
    evaluate_batch, bootstrap_norm_ci = en14363.evaluate_batch, bootstrap.bootstrap_norm_ci
    t_import = time.perf_counter()
    sets, infos = _sections(np.random.default_rng(0))
    t_codec = time.perf_counter()
    evaluate_batch(sets, infos)
    # the verdict's bootstrap kernel, for the index arrays a validation gives it
    bootstrap_norm_ci(np.random.default_rng(1).standard_normal(17), 1.0, 1.0, n_boot=1000,
                      seed_key=(0, 17))
    t_en = time.perf_counter()
    return {"import_s": round(t_import - t0, 3), "codec_s": round(t_codec - t_import, 3),
            "en_chain_s": round(t_en - t_codec, 3), "total_s": round(t_en - t0, 3)}


def start_background() -> subprocess.Popen | None:
    """Start :func:`warm` in a child process, which first lowers itself to the lowest CPU
    priority (``nice`` 19); its output is discarded and a daemon thread reaps it when it
    ends. Returns the process, or None when :data:`NO_WARMUP_ENV` switches it off. The
    server does not wait for it."""
    if os.environ.get(NO_WARMUP_ENV, "") not in ("", "0"):
        return None
    proc = subprocess.Popen([sys.executable, "-m", "railval.app.services.warmup"],
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    # reaped when it ends, so a long-running server keeps no defunct child
    threading.Thread(target=proc.wait, name="railval-warmup-reaper", daemon=True).start()
    return proc


if __name__ == "__main__":
    os.nice(19)  # before the kernels load: the child never competes with the server it helps
    print(json.dumps(warm()))
