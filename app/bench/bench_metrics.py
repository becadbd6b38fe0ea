"""Curve-comparison metrics: per-signal throughput of the full metric set (raw + synchronised).

Builds a measured-like signal (two sinusoids, narrow-band noise) and a simulated one with a
gain error and a 0.35 s delay, ``--n`` samples at ``--fs`` Hz (default 20 000 at 200 Hz),
and times (CPU time of this process, best of ``--repeat`` runs):

* every metric family once (raw only),
* the full ``compare()`` (all families raw and synchronised, plus the lag search),
* ``compare()`` without ISO/TS 18571 (the DTW is by far the most expensive part),
* baseline in the same run: ``scipy.stats.ks_2samp`` + ``wasserstein_distance`` +
  ``anderson_ksamp`` on the same pair (what a plain scipy script would do), and the
  numba DTW's cell rate.
"""

from __future__ import annotations

import argparse
import math
import time
import warnings

import numpy as np
import scipy.stats

from railval.core import lazy

#: deferred (railval.core.lazy): ``railval bench`` (the list) imports every benchmark module for its
#: docstring; what the benchmark runs loads when it runs
core_metrics = lazy.module("railval.core.metrics")
dtw_magnitude_error = lazy.function("railval.core.metrics.iso18571", "dtw_magnitude_error")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--n", type=int, default=20_000, help="samples per signal (default 20000)")
    parser.add_argument("--fs", type=float, default=200.0, help="sampling rate in Hz (default 200)")
    parser.add_argument("--repeat", type=int, default=3, help="repetitions, best is reported (default 3)")


def _best(func, repeat: int) -> float:
    """Best CPU time of ``repeat`` calls in s (``time.process_time``: all code timed here is
    single-threaded, and CPU time is robust against other jobs on a shared machine, which
    inflate wall-clock times)."""
    func()  # warm-up (numba compile / cache load, FFT plans)
    best = math.inf
    for _ in range(repeat):
        t0 = time.process_time()
        func()
        best = min(best, time.process_time() - t0)
    return best


def _pair(n: int, fs: float) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    t = np.arange(n + 200) / fs
    noise = np.convolve(rng.normal(size=t.size), np.hanning(15) / 7.5, mode="same")
    base = np.sin(2 * np.pi * 0.6 * t) + 0.4 * np.sin(2 * np.pi * 2.3 * t) + 0.3 * noise
    lag = round(0.35 * fs)
    return base[100:100 + n], 1.08 * base[100 - lag:100 - lag + n]


def run(args: argparse.Namespace) -> dict:
    n, fs, rep = int(args.n), float(args.fs), max(1, int(args.repeat))
    m, c = _pair(n, fs)
    fam_ms = {}
    for name, fam in core_metrics.FAMILIES.items():
        fam_ms[name] = round(1e3 * _best(lambda f=fam: f.compute(m, c, fs, {}), rep), 2)
    full = _best(lambda: core_metrics.compare(m, c, fs), rep)
    cheap = _best(lambda: core_metrics.compare(m, c, fs, families=[f for f in core_metrics.FAMILIES
                                                                   if f != "iso18571"]), rep)

    def scipy_baseline():
        scipy.stats.ks_2samp(m, c)
        scipy.stats.wasserstein_distance(m, c)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scipy.stats.anderson_ksamp([m, c], variant="midrank")

    base = _best(scipy_baseline, rep)
    radius = math.ceil(0.1 * n)
    dtw = _best(lambda: dtw_magnitude_error(m, c, window=0.1), rep)  # band radius ceil(0.1·n)
    cells = n * (2 * radius - 1)
    return {
        "timing": "CPU time (process_time), best of repeats",
        "n_samples": n,
        "fs_hz": fs,
        "family_ms_raw": fam_ms,
        "compare_full_ms": round(1e3 * full, 1),
        "compare_full_signals_per_s": round(1.0 / full, 2),
        "compare_without_iso_ms": round(1e3 * cheap, 1),
        "compare_without_iso_signals_per_s": round(1.0 / cheap, 1),
        "baseline_scipy_ks_wasserstein_ad_ms": round(1e3 * base, 1),
        "dtw_ms": round(1e3 * dtw, 1),
        "dtw_cells_per_s": float(f"{cells / dtw:.3g}"),
    }
