"""The pieces of the faster diagnosis give the results of the slower ones: band powers of a
section's channels from one Welch call equal each channel's own, and a batch map with a shared
object returns what the serial map returns while the object reaches each worker once
(docs/diagnosis.md "Diagnosis speed")."""

from __future__ import annotations

import os

import numpy as np
import pytest

from railval.app.services.batch import BatchExecutor
from railval.core.diagnosis import DEFAULT_BANDS_HZ, band_powers, section_band_powers, sections_band_powers
from railval.core.errors import InvalidSignal

#: unpickles of :class:`Shared` in this process (a worker counts its own)
UNPICKLED = [0]


def _rebuild(payload):
    UNPICKLED[0] += 1
    return Shared(payload)


class Shared:
    """A shared object that counts how often a process unpickles it."""

    def __init__(self, payload):
        self.payload = payload

    def __reduce__(self):
        return _rebuild, (self.payload,)


def _task(shared: Shared, item: int) -> tuple[int, int, float]:
    return os.getpid(), UNPICKLED[0], float(shared.payload[item] * 2.0)


def test_section_band_powers_equal_band_powers_of_each_channel():
    rng = np.random.default_rng(3)
    fs = 200.0
    t = np.arange(int(60 * fs)) / fs
    chans = {"ay_cb_b1": np.sin(2 * np.pi * 1.3 * t) + 0.3 * rng.standard_normal(t.size),
             "az_cb_b2": 0.5 * np.sin(2 * np.pi * 7.0 * t) + 0.1 * rng.standard_normal(t.size)}
    got = section_band_powers(chans, fs, DEFAULT_BANDS_HZ, 10.0)
    for ch, x in chans.items():
        np.testing.assert_allclose(got[ch], band_powers(x, fs, DEFAULT_BANDS_HZ, 10.0), rtol=1e-12, atol=0)
    # independently: a sine of amplitude A carries A²/2 in the band holding its frequency
    pure = section_band_powers({"s": np.sin(2 * np.pi * 7.0 * t)}, fs, [(5.0, 10.0)], 10.0)["s"][0]
    assert pure == pytest.approx(0.5, rel=0.02)


def _sections(seed: int) -> tuple[dict, dict]:
    """Sections of unequal lengths (odd and even, some shorter than a segment) and rates."""
    rng = np.random.default_rng(seed)
    sections, rates = {}, {}
    for k, (seconds, fs) in enumerate([(23.7, 200.0), (31.0, 200.0), (6.3, 200.0), (18.45, 100.0), (40.0, 200.0)]):
        n = int(seconds * fs) + k % 2
        t = np.arange(n) / fs
        sections[f"S{k:02d}"] = {ch: np.sin(2 * np.pi * (0.7 + j) * t) + rng.standard_normal(n) * (0.2 + 0.1 * j)
                                 for j, ch in enumerate(("ay_cb_b1", "ay_cb_b2", "az_cb_b1", "az_cb_b2")[: 4 - k % 2])}
        rates[f"S{k:02d}"] = fs
    return sections, rates


def test_sections_band_powers_are_each_sections_own_bit_for_bit():
    """One Welch call over all sections gives every section's :func:`section_band_powers`,
    same float bits. The blocking matters: estimated one channel at a time, 14 of these 18
    channels differ in their last bits (a row's BLAS product depends on its block's row count)."""
    sections, rates = _sections(5)
    sections["empty"], rates["empty"] = {}, 200.0
    got = sections_band_powers(sections, rates, DEFAULT_BANDS_HZ, 10.0)
    assert list(got) == list(sections)
    assert got["empty"] == {}
    for sid, chans in sections.items():
        if not chans:
            continue
        alone = section_band_powers(chans, rates[sid], DEFAULT_BANDS_HZ, 10.0)
        assert list(got[sid]) == list(alone)
        for ch in chans:
            assert np.array_equal(got[sid][ch], alone[ch]), (sid, ch)


def test_band_sums_equal_each_channels_own_band_powers_summed():
    """The calibration's band sums: every channel estimated alone (:func:`band_powers`), summed
    over the sections in their order — the same float bits as that loop."""
    from railval.app.services.campaign_context import band_sums
    from railval.core.types import SignalSet

    sections, rates = _sections(9)
    sets = {sid: SignalSet(fs=rates[sid], time_s=np.arange(len(next(iter(ch.values())))) / rates[sid],
                           distance_m=np.arange(len(next(iter(ch.values())))) * 1.0, channels=ch)
            for sid, ch in sections.items()}
    expected: dict = {}
    for ss in sets.values():
        for ch in ("ay_cb_b1", "ay_cb_b2", "az_cb_b1", "az_cb_b2"):
            if ch in ss.channels:
                expected[ch] = expected.get(ch, 0.0) + band_powers(ss.channels[ch], ss.fs, DEFAULT_BANDS_HZ, 10.0)
    got = band_sums(sets, DEFAULT_BANDS_HZ)
    assert list(got) == list(expected)
    for ch in expected:
        assert np.array_equal(got[ch], expected[ch]), ch


def test_sections_band_powers_names_the_bad_section_channel():
    good = np.zeros(4000)
    with pytest.raises(InvalidSignal, match="'az_cb_b1'"):
        sections_band_powers({"S1": {"ay_cb_b1": good}, "S2": {"az_cb_b1": np.r_[good[:-1], np.inf]}},
                             {"S1": 200.0, "S2": 200.0})


def test_section_band_powers_names_the_bad_channel():
    good = np.zeros(4000)
    with pytest.raises(InvalidSignal, match="'az_cb_b1'"):
        section_band_powers({"ay_cb_b1": good, "az_cb_b1": np.r_[good[:-1], np.nan]}, 200.0)
    with pytest.raises(InvalidSignal, match="one length"):
        section_band_powers({"ay_cb_b1": good, "az_cb_b1": good[:100]}, 200.0)


def test_shared_map_equals_serial_and_ships_the_object_once_per_worker():
    shared = Shared(np.arange(40.0))
    items = list(range(40))
    with BatchExecutor("serial") as ex:
        serial = [r[2] for r in ex.map(_task, items, shared=shared)]
    with BatchExecutor(None, 2) as ex:
        got = ex.map(_task, items, shared=shared)
        again = ex.map(_task, items[:6], shared=shared)  # same object: the same workers, no new copy
    assert [r[2] for r in got] == serial == [2.0 * i for i in items]
    per_worker = {}
    for pid, n, _ in got + again:
        per_worker.setdefault(pid, set()).add(n)
    assert all(max(ns) <= 1 for ns in per_worker.values()), per_worker  # not once per task


def test_shared_map_on_a_dask_cluster_scatters_once():
    distributed = pytest.importorskip("dask.distributed")
    shared = Shared(np.arange(12.0))
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster:
        with BatchExecutor(cluster.scheduler_address) as ex:
            got = ex.map(_task, list(range(12)), shared=shared)
    assert [r[2] for r in got] == [2.0 * i for i in range(12)]
    assert all(n <= 1 for _, n, _ in got)


_PRELOAD_SCRIPT = """
import sys, threading
from railval.app.services.batch import BatchExecutor

def main():
    out = []
    def run():  # from a background thread, as the Panel app runs a diagnosis: forkserver
        with BatchExecutor(None, 2) as ex:
            out.extend(ex.map(_loaded, [0, 1, 2, 3]))
    th = threading.Thread(target=run)
    th.start()
    th.join()
    print(sorted(set(out)))

def _loaded(_):
    # the modules imported, and the compiled kernels of a campaign run already in memory (a
    # numba dispatcher holds its overloads once a call has compiled or loaded them)
    if "railval.core.sim.model" not in sys.modules:
        return "simulator not imported"
    from railval.core import en_kernels, filters
    from railval.core.sim import kernel
    cold = [name for name, d in (("run_kernel", kernel.run_kernel), ("_section_kernel", en_kernels._section_kernel),
                                 ("_filtfilt_into", filters._filtfilt_into)) if not d.overloads]
    return "not loaded: " + " ".join(cold) if cold else True

if __name__ == "__main__":
    main()
"""


def test_forkserver_workers_start_with_the_simulator_imported_and_its_kernels_loaded(tmp_path):
    """From a background thread the pool uses the forkserver, which imports the simulator once
    and makes one short campaign run (``FORKSERVER_PRELOAD``, ``forkserver_warm``): a worker
    sees the modules loaded and the simulator's, EN chain's and filters' compiled kernels in
    memory before its first task (without the warm-up each worker loaded them on its first
    campaign run, 1.4–1.9 CPU-s)."""
    import subprocess
    import sys

    script = tmp_path / "preload_check.py"
    script.write_text(_PRELOAD_SCRIPT)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[True]"


_EARLY_SCRIPT = """
import subprocess, sys, threading, time
from railval.app.services.batch import BatchExecutor, start_forkserver

def main(after):
    warming = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(2)"]) if after else None
    t0 = time.perf_counter()
    assert start_forkserver(["railval.app.services.workshop_canvas"], after=warming)
    started = time.perf_counter() - t0
    if warming is not None:
        warming.wait()
        time.sleep(0.5)  # the starting thread's turn
    out = []
    def run():  # a background job's pool, as the server runs it: the forkserver started above
        with BatchExecutor(None, 2) as ex:
            out.extend(ex.map(_state, [0, 1]))
    th = threading.Thread(target=run)
    th.start()
    th.join()
    print(sorted(set(out)), started < (0.5 if after else 2.0))

def _state(_):
    from railval.core.sim import kernel
    return ("railval.app.services.workshop_canvas" in sys.modules, bool(kernel.run_kernel.overloads))

if __name__ == "__main__":
    main(sys.argv[1] == "after")
"""


@pytest.mark.parametrize("after", ["now", "after"])
def test_the_forkserver_started_early_serves_the_later_pools(tmp_path, after):
    """``railval serve`` starts the forkserver once the demo is seeded and its warm-up child has
    ended (``batch.start_forkserver``, with the workshop drawing as an extra module; ``after``:
    the process to wait for, then the call returns at once and a thread starts the forkserver
    when it has ended): the call does not wait for the forkserver's imports and warm-up, and a
    later pool of a background thread forks its workers from that forkserver — they have the
    drawing module imported (which the diagnosis pool's own preload list does not name) and the
    simulator's kernel loaded."""
    import subprocess
    import sys

    script = tmp_path / "early_check.py"
    script.write_text(_EARLY_SCRIPT)
    done = subprocess.run([sys.executable, str(script), after], capture_output=True, text=True, timeout=300,
                          check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[(True, True)] True"
