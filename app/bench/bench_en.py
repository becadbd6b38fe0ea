"""EN 14363 chain: batch path vs a straightforward per-signal scipy chain, equal work.

Both run in the same process on the same synthetic sections (default 17 sections × 20
channels — Y and Q of 8 wheels, car body ay/az above both bogies — 20 000 samples at 500 Hz,
variable speed) and produce the same 64 values per section under the chosen reading:

* **baseline** — per signal: ``scipy.signal.sosfiltfilt`` of each channel (designs made once),
  Y/Q and ΣY formed per wheel/wheelset, cut, then one ``np.quantile(method="inverted_cdf")``
  call per statistic; sliding mean by ``scipy.integrate.cumulative_trapezoid`` over distance
  and ``np.interp`` at the window edges;
* **batch** — :func:`railval.core.en14363.evaluate_batch` with ``alternatives=False,
  supplementary=False`` (the chosen reading alone, as the baseline): all channels of all
  sections filtered 16 in lockstep on the cores, percentiles from selected order statistics.

Figures: wall time of each (best of ``--repeat``), speed-up (target ≥ 5×), the CPU seconds
of each (all threads of the process; the work done, less moved by other jobs on a shared
machine than the wall time) and their ratio, the largest
difference between the two sets of values, and the split of the full chain (with the values
under the alternative readings and the supplementary values, as the application runs it):
checks, filter, statistics, alternatives, supplementary — best of ``--repeat`` per stage. The
1-minute load average is printed beside (the machine may be shared).

``machine`` — the physical limits the filter is held to (docs/validation.md, Throughput):
memory bandwidth (``numpy.copyto`` of 128 MiB, read + write counted), the scalar rate of the
biquad recursion (one signal, compiled) and its SIMD rate (the lockstep kernel of
:mod:`railval.core.filters` on a block held in the cache), each in ns per sample and section;
from them the lower bounds of the filter stage (36 flops and at least 16 bytes per sample
for the default low-pass: 2 sections × forward + backward × 9 flops; the sample read once,
the result written once) and how far the measured filter stage is from each.
"""

from __future__ import annotations

import argparse
import os
import time

import numba
import numpy as np
import scipy.integrate
import scipy.signal

from railval.core import filters, lazy
from railval.core.en14363 import evaluate_batch
from railval.core.filters import design
from railval.core.types import BODY_POSITIONS, WHEEL_POSITIONS, SectionInfo, SignalSet

#: deferred (railval.core.lazy): ``railval bench`` (the list) imports every benchmark module for its
#: docstring; what the benchmark runs loads when it runs
thread_count = lazy.function("railval.core.workers", "thread_count")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--sections", type=int, default=17, help="sections (default 17)")
    parser.add_argument("--samples", type=int, default=20_000, help="samples per signal")
    parser.add_argument("--fs", type=float, default=500.0, help="sampling rate, Hz")
    parser.add_argument("--repeat", type=int, default=3, help="repetitions, best taken")
    parser.add_argument("--order", type=int, default=4, help="Butterworth order")


def make_sections(n_sections: int, n: int, fs: float, seed: int = 0):
    """Synthetic sections: forces around plausible levels, accelerations, variable speed."""
    rng = np.random.default_rng(seed)
    sets, infos = [], []
    t = np.arange(n) / fs
    for i in range(n_sections):
        v = 25.0 * (1 + 0.05 * np.sin(2 * np.pi * t / 30.0 + i))
        d = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) / fs)])
        ch = {}
        for p in WHEEL_POSITIONS:
            ch[f"Y_{p}"] = rng.normal(10, 5) + 4 * rng.standard_normal(n)
            ch[f"Q_{p}"] = 75 + rng.normal(0, 5) + 6 * rng.standard_normal(n)
        for k in ("ay", "az"):
            for b in BODY_POSITIONS:
                ch[f"{k}_cb_{b}"] = 0.4 * rng.standard_normal(n)
        sets.append(SignalSet(fs, t, d, ch))
        run = 10.0 * 25.0  # ≈ 10 s run-in and run-out
        infos.append(SectionInfo(f"S{i + 1:02d}", 500.0, 120.0, 90.0, 1 + i % 4, run,
                                 float(d[-1]) - run))
    return sets, infos


def baseline_section(ss: SignalSet, sec: SectionInfo, order: int) -> dict:
    """The straightforward per-signal chain (see module docstring)."""
    lp = design(ss.fs, "lowpass", order).sos
    bp = design(ss.fs, "bandpass", order).sos
    d = ss.distance_m
    m = (d >= sec.eval_start_m) & (d <= sec.eval_end_m)

    def q(x, p):
        return np.quantile(x, p, method="inverted_cdf")

    def maxabs(x):
        return max(abs(q(x, 0.0015)), abs(q(x, 0.9985)))

    def slide(x):
        c = scipy.integrate.cumulative_trapezoid(x, d, initial=0.0)
        centres = np.arange(sec.eval_start_m + 1.0, sec.eval_end_m - 1.0 + 1e-9, 0.5)
        return (np.interp(centres + 1.0, d, c) - np.interp(centres - 1.0, d, c)) / 2.0

    f = {name: scipy.signal.sosfiltfilt(bp if "_cb_" in name else lp, x)
         for name, x in ss.channels.items()}
    out = {}
    for p in WHEEL_POSITIONS:
        y, qq = f[f"Y_{p}"], f[f"Q_{p}"]
        r = y / qq
        out[("Y_qst", p)] = q(y[m], 0.5)
        out[("Y_max", p)] = maxabs(y[m])
        out[("Q_qst", p)] = q(qq[m], 0.5)
        out[("Q_max", p)] = q(qq[m], 0.9985)
        out[("YQ_qst", p)] = q(r[m], 0.5)
        out[("YQ_max", p)] = maxabs(slide(r))
    for w in range(1, 5):
        s = f[f"Y_w{w}L"] + f[f"Y_w{w}R"]
        out[("SumY_qst", f"ws{w}")] = q(s[m], 0.5)
        out[("SumY_max", f"ws{w}")] = maxabs(slide(s))
    for k in ("ay", "az"):
        for b in BODY_POSITIONS:
            x = f[f"{k}_cb_{b}"][m]
            out[(f"{k}_rms", b)] = float(np.sqrt(np.mean(x * x)))
            out[(f"{k}_max", b)] = maxabs(x)
    return out


FLOPS_PER_SECTION_SAMPLE = 9  # y = b0·x + z0; z0 = b1·x − a1·y + z1; z1 = b2·x − a2·y


def machine_limits(repeat: int = 3) -> dict:
    """Memory bandwidth and the scalar / SIMD rate of the biquad recursion on this machine."""
    a = np.ones(16 * 1024 * 1024)
    b = np.empty_like(a)
    t_copy, _ = _best(lambda: np.copyto(b, a), repeat)
    bandwidth = 2 * a.nbytes / t_copy / 1e9
    del a, b

    @numba.njit(nogil=True)
    def scalar_cascade(sos, x):  # one signal: the recursion of scipy's sosfilt
        z0 = np.zeros(sos.shape[0])
        z1 = np.zeros(sos.shape[0])
        for i in range(x.shape[0]):
            v = x[i]
            for s in range(sos.shape[0]):
                y = sos[s, 0] * v + z0[s]
                z0[s] = sos[s, 1] * v - sos[s, 4] * y + z1[s]
                z1[s] = sos[s, 2] * v - sos[s, 5] * y
                v = y
            x[i] = v

    d = filters.design(500.0, "lowpass", 4)
    n_sec = d.sos.shape[0]
    x = np.random.default_rng(0).standard_normal(1_000_000)
    scalar_cascade(d.sos, x[:100].copy())
    t_scalar, _ = _best(lambda: scalar_cascade(d.sos, x), repeat)
    ext = np.random.default_rng(1).standard_normal((2000, filters._BLOCK))  # 500 KiB, in cache
    filters._cascade_pass(d.sos, d.zi, ext, 0, ext.shape[0], 1)
    t_simd, _ = _best(lambda: filters._cascade_pass(d.sos, d.zi, ext, 0, ext.shape[0], 1),
                      repeat)
    scalar_ns = 1e9 * t_scalar / (x.size * n_sec)
    simd_ns = 1e9 * t_simd / (ext.size * n_sec)
    return {"memory_bandwidth_gb_s": round(bandwidth, 2),
            "biquad_scalar_ns_per_sample_section": round(scalar_ns, 3),
            "biquad_simd_ns_per_sample_section": round(simd_ns, 3),
            "biquad_scalar_gflop_s": round(FLOPS_PER_SECTION_SAMPLE / scalar_ns, 2),
            "biquad_simd_gflop_s": round(FLOPS_PER_SECTION_SAMPLE / simd_ns, 2)}


def _best(fn, repeat: int, clock=time.perf_counter) -> tuple[float, object]:
    best, result = float("inf"), None
    for _ in range(repeat):
        t0 = clock()
        result = fn()
        best = min(best, clock() - t0)
    return best, result


def run(args: argparse.Namespace) -> dict:
    sets, infos = make_sections(args.sections, args.samples, args.fs)
    evaluate_batch(sets[:1], infos[:1], order=args.order)  # compile / warm the caches
    load = [os.getloadavg()[0]]
    t_batch, batch = _best(lambda: evaluate_batch(sets, infos, order=args.order,
                                                  alternatives=False, supplementary=False),
                           args.repeat)
    t_base, base = _best(lambda: [baseline_section(s, i, args.order) for s, i in zip(sets, infos)],
                         args.repeat)
    # CPU seconds of this process (all its threads): the work done, less moved by other jobs
    cpu_batch, _ = _best(lambda: evaluate_batch(sets, infos, order=args.order,
                                                alternatives=False, supplementary=False),
                         args.repeat, time.process_time)
    cpu_base, _ = _best(lambda: [baseline_section(s, i, args.order)
                                 for s, i in zip(sets, infos)], args.repeat, time.process_time)
    split: dict[str, float] = {}
    t_full = float("inf")
    for _ in range(args.repeat):
        stages: dict[str, float] = {}
        t0 = time.perf_counter()
        evaluate_batch(sets, infos, order=args.order, timings=stages)
        t_full = min(t_full, time.perf_counter() - t0)
        split = {k: min(split.get(k, float("inf")), v) for k, v in stages.items()}
    load.append(os.getloadavg()[0])
    diff_stat = diff_slide = 0.0
    for b, r in zip(batch, base):
        for key, val in r.items():
            delta = abs(b[key] - val) / max(1.0, abs(val))
            if key[0] in ("YQ_max", "SumY_max"):
                diff_slide = max(diff_slide, delta)
            else:
                diff_stat = max(diff_stat, delta)
    n_signals = args.sections * len(sets[0].channels)
    n_values = sum(len(b) for b in batch)
    machine = machine_limits(args.repeat)
    load.append(os.getloadavg()[0])
    # the filter stage against its bounds: per sample of the low-pass (2 sections, 2 passes)
    # and of the band-pass (twice the sections); the bench sections hold 16 low-pass and 4
    # band-pass channels of 20
    lp_share = 16 / 20
    sec_passes = (lp_share * 2 + (1 - lp_share) * 4) * 2 * (args.order / 4)
    samples = n_signals * args.samples
    filter_ns = 1e9 * split.get("filter", float("nan")) / samples
    simd_bound = sec_passes * machine["biquad_simd_ns_per_sample_section"] / thread_count()
    memory_bound = 16 / machine["memory_bandwidth_gb_s"]
    machine.update({
        "filter_ns_per_sample": round(filter_ns, 3),
        "filter_flops_per_sample": round(sec_passes * FLOPS_PER_SECTION_SAMPLE, 1),
        "filter_bound_simd_ns_per_sample": round(simd_bound, 3),
        "filter_bound_memory_ns_per_sample": round(memory_bound, 3),
        "filter_times_the_larger_bound": round(filter_ns / max(simd_bound, memory_bound), 2),
        "scalar_filter_ns_per_sample": round(
            sec_passes * machine["biquad_scalar_ns_per_sample_section"], 3),
    })
    return {
        "sections": args.sections, "signals": n_signals, "samples_per_signal": args.samples,
        "fs_hz": args.fs, "values": n_values, "filter_order": args.order,
        "threads": thread_count(), "load_average_1min": [round(x, 2) for x in load],
        "baseline_s": round(t_base, 4), "batch_s": round(t_batch, 4),
        "speedup": round(t_base / t_batch, 2),
        "baseline_ms_per_signal": round(1e3 * t_base / n_signals, 3),
        "batch_ms_per_signal": round(1e3 * t_batch / n_signals, 3),
        "batch_ns_per_sample": round(1e9 * t_batch / (n_signals * args.samples), 2),
        "target_speedup": 5.0, "target_met": bool(t_base / t_batch >= 5.0),
        "baseline_cpu_s": round(cpu_base, 4), "batch_cpu_s": round(cpu_batch, 4),
        "speedup_cpu": round(cpu_base / cpu_batch, 2),
        "full_chain_s": round(t_full, 4),
        "full_chain_split_s": {k: round(split[k], 4) for k in
                               ("checks", "filter", "statistics", "alternatives",
                                "supplementary") if k in split},
        "machine": machine,
        "max_rel_diff_percentile_values": float(diff_stat),
        # the baseline interpolates the cumulative integral linearly at the window edges;
        # the batch path integrates the linear interpolant exactly
        "max_rel_diff_sliding_mean_values": float(diff_slide),
    }
