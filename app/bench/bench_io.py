"""Campaign import throughput and signal blob decode speed (against numpy.load of .npy files).

Generates a campaign folder (band-limited random signals, 12 channels, ``--sections``
sections of ``--seconds`` s at ``--fs`` Hz, files in ``--format``) in a temporary folder,
imports it into a temporary SQLite database and measures:

* import: wall time, MB/s of data files read, channel samples/s;
* decode: every signal blob of the campaign decoded (:func:`railval.db.codec.decode`) against the
  baseline of ``numpy.load`` of the same arrays from ``.npy`` files written in the same
  run (warm page cache), as a ratio decode/npy;
* load: :func:`railval.db.repo.load_signalsets` of the whole measurement (one query plus decode);
* size: stored blob bytes / raw float64 bytes.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from railval.core import lazy

#: deferred (railval.core.lazy): ``railval bench`` (the list) imports every benchmark module for its
#: docstring; what the benchmark runs loads when it runs
write_table = lazy.function("railval.db.io", "write_table")
codec = lazy.module("railval.db.codec")
repo = lazy.module("railval.db.repo")
connect = lazy.function("railval.db.engine", "connect")
import_campaign = lazy.function("railval.db.importer", "import_campaign")
validate_campaign_folder = lazy.function("railval.db.importer", "validate_campaign_folder")

CHANNELS = [f"{k}_{p}" for p in ("w1L", "w1R", "w2L", "w2R") for k in ("Y", "Q")] + [
    f"{k}_{p}" for p in ("b1", "b2") for k in ("ay_cb", "az_cb")]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--sections", type=int, default=24, help="sections (default 24)")
    parser.add_argument("--seconds", type=float, default=40.0, help="s per section (default 40)")
    parser.add_argument("--fs", type=float, default=200.0, help="sampling rate, Hz (default 200)")
    parser.add_argument("--format", default="parquet", help="data file format (default parquet)")
    parser.add_argument("--repeat", type=int, default=3, help="decode repetitions, best kept")


def _smooth_noise(rng: np.random.Generator, n: int, width: int = 8) -> np.ndarray:
    kernel = np.ones(width) / width
    return np.convolve(rng.standard_normal(n + width), kernel, mode="same")[:n]


def write_campaign(folder: Path, sections: int, seconds: float, fs: float, fmt: str) -> None:
    """A minimal valid campaign (straight sections, measured data only)."""

    rng = np.random.default_rng(0)
    n = int(seconds * fs)
    t = np.arange(n) / fs
    secs = []
    for i in range(sections):
        sid = f"S{i + 1:03d}"
        dist = t * 30.0
        cols = {"time_s": t, "distance_m": dist}
        for ch in CHANNELS:
            base = 77.0 if ch.startswith("Q") else 0.0
            cols[ch] = base + 3.0 * _smooth_noise(rng, n)
        rel = f"measured/{sid}.{fmt}"
        write_table(folder / rel, cols)
        secs.append({"id": sid, "radius_m": 0, "speed_kmh": 108.0,
                     "evaluated": {"start_m": float(dist[n // 4]), "end_m": float(dist[3 * n // 4])},
                     "measured": rel})
    manifest = {
        "format": {"id": "railval-campaign", "version": 1}, "name": "bench",
        "vehicle": {"kind": "passenger", "Q0_kN": 77.0},
        "channels": [{"name": ch, "kind": ch.rpartition("_")[0], "position": ch.rpartition("_")[2],
                      "unit": "kN" if ch[0] in "YQ" else "m/s^2"} for ch in CHANNELS],
        "sections": secs,
    }
    (folder / "campaign.json").write_text(json.dumps(manifest))


def run(args: argparse.Namespace) -> dict:
    with tempfile.TemporaryDirectory(prefix="railval-bench-io-") as tmp:
        root = Path(tmp)
        folder = root / "campaign"
        write_campaign(folder, args.sections, args.seconds, args.fs, args.format)
        n_bytes = sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())

        t = time.perf_counter()
        vc = validate_campaign_folder(folder)
        t_validate = time.perf_counter() - t

        database = connect(f"sqlite:///{root / 'bench.db'}")
        database.init()
        t = time.perf_counter()
        import_campaign(database, folder)
        t_import = time.perf_counter() - t

        with database.session() as s:
            blobs = repo.stored_blobs(s)
        arrays = [codec.decode(b) for b, _ in blobs]
        npy = []
        for k, a in enumerate(arrays):
            path = root / "npy" / f"{k}.npy"
            path.parent.mkdir(exist_ok=True)
            np.save(path, a)
            npy.append(path)
        raw_bytes = sum(a.nbytes for a in arrays)
        stored_bytes = sum(len(b) for b, _ in blobs)

        def best(fn) -> float:
            times = []
            for _ in range(max(1, args.repeat)):
                t0 = time.perf_counter()
                fn()
                times.append(time.perf_counter() - t0)
            return min(times)

        t_decode = best(lambda: [codec.decode(b) for b, _ in blobs])
        t_decode_verify = best(lambda: [codec.decode(b, h) for b, h in blobs])
        t_npy = best(lambda: [np.load(p) for p in npy])
        with database.session() as s:
            camp = repo.get_campaign(s, "bench")
            t_load = best(lambda: repo.load_signalsets(s, camp))
        database.dispose()

    n_signals = len(blobs)
    mb = raw_bytes / 1e6
    return {
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                    "numpy": np.__version__},
        "campaign": {"sections": args.sections, "seconds_per_section": args.seconds,
                     "fs_Hz": args.fs, "format": args.format, "signals": n_signals,
                     "channel_samples": vc.n_samples, "file_MB": round(n_bytes / 1e6, 2)},
        "import": {"seconds": round(t_import, 3), "validate_seconds": round(t_validate, 3),
                   "file_MB_per_s": round(n_bytes / 1e6 / t_import, 2),
                   "samples_per_s": round(vc.n_samples / t_import)},
        "decode": {"seconds": round(t_decode, 4), "MB_per_s": round(mb / t_decode, 1),
                   "with_hash_check_seconds": round(t_decode_verify, 4),
                   "npy_load_seconds": round(t_npy, 4),
                   "ratio_to_npy_load": round(t_decode / t_npy, 3)},
        "load_signalsets": {"seconds": round(t_load, 4),
                            "signals_per_s": round(n_signals / t_load)},
        "size": {"raw_MB": round(mb, 2), "stored_MB": round(stored_bytes / 1e6, 2),
                 "ratio": round(stored_bytes / raw_bytes, 3)},
    }
