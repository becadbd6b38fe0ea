"""The filter designs and Welch windows kept on disk (core/design_store.py) are scipy's own
numbers, bit for bit; a damaged or foreign file is computed again; a process that finds them
filters and estimates PSDs without importing scipy.signal."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
import scipy.signal

from railval.core import design_store, filters, psd


@pytest.fixture
def store(tmp_path, monkeypatch):
    """An empty store of this test's own, and no design remembered in this process."""
    folder = tmp_path / "designs"
    monkeypatch.setenv(design_store.STORE_ENV, str(folder))
    filters.design.cache_clear()
    psd._welch_setup.cache_clear()
    yield folder
    filters.design.cache_clear()
    psd._welch_setup.cache_clear()


def _scipy_design(fs, kind, order):
    if kind == "lowpass":
        sos = scipy.signal.butter(order, filters.LOWPASS_HZ, btype="lowpass", fs=fs, output="sos")
    else:
        sos = scipy.signal.butter(order, list(filters.BANDPASS_HZ), btype="bandpass", fs=fs, output="sos")
    return sos, scipy.signal.sosfilt_zi(sos)


CASES = [(fs, kind, order) for fs in (200.0, 500.0, 123.4) for kind in filters.FILTER_KINDS
         for order in (2, 4, 5)]


@pytest.mark.parametrize("fs,kind,order", CASES)
def test_stored_design_is_scipys_bit_for_bit(store, fs, kind, order):
    made = filters.design(fs, kind, order)  # computed and stored
    filters.design.cache_clear()
    read = filters.design(fs, kind, order)  # read from the store
    sos, zi = _scipy_design(fs, kind, order)
    for d in (made, read):
        assert np.array_equal(d.sos, sos) and np.array_equal(d.zi, zi)
        assert d.settling_s == filters._settling_time(sos, fs)
    assert read.edge == made.edge and read.settling_s == made.settling_s
    assert len(list(store.glob("*.npz"))) == 1


def test_stored_window_is_scipys_bit_for_bit(store):
    rng = np.random.default_rng(3)
    x = rng.standard_normal(3001)
    first = psd.welch_psd(x, 200.0, 2.0)
    psd._welch_setup.cache_clear()
    again = psd.welch_psd(x, 200.0, 2.0)
    f, p = scipy.signal.welch(x, fs=200.0, nperseg=400, detrend=psd.detrend_linear)
    for got in (first, again):
        assert np.array_equal(got.frequency_hz, f) and np.array_equal(got.density, p)
        assert got.segment_s == 2.0


def test_a_damaged_file_is_computed_again_and_replaced(store):
    filters.design(200.0, "bandpass", 4)
    (path,) = store.glob("*.npz")
    path.write_bytes(b"not a zip file at all")
    filters.design.cache_clear()
    d = filters.design(200.0, "bandpass", 4)
    assert np.array_equal(d.sos, _scipy_design(200.0, "bandpass", 4)[0])
    assert path.read_bytes()[:2] == b"PK"  # replaced by a readable file


def test_an_implausible_or_foreign_file_is_not_used(store):
    key_lp = f"butterworth lowpass order 4 fs {200.0!r} scipy {scipy.__version__}"
    path = design_store.file_for(key_lp)
    good = filters.design(200.0, "lowpass", 4)
    # a design whose a0 is not 1 (not butter's layout): refused by the check
    with np.load(path) as data:
        arrays = {k: np.array(data[k]) for k in data.files}
    arrays["sos"] = arrays["sos"] * 2.0
    np.savez(path, **arrays)
    filters.design.cache_clear()
    assert np.array_equal(filters.design(200.0, "lowpass", 4).sos, good.sos)
    # another key's file under this key's name: refused by the key stored inside
    other = design_store.file_for(f"butterworth bandpass order 4 fs {200.0!r} scipy {scipy.__version__}")
    filters.design(200.0, "bandpass", 4)
    path.write_bytes(other.read_bytes())
    filters.design.cache_clear()
    assert np.array_equal(filters.design(200.0, "lowpass", 4).sos, good.sos)


def test_no_store_computes_every_time_and_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv(design_store.STORE_ENV, "")
    filters.design.cache_clear()
    try:
        assert design_store.folder() is None
        d = filters.design(250.0, "lowpass", 4)
        assert np.array_equal(d.sos, _scipy_design(250.0, "lowpass", 4)[0])
    finally:
        filters.design.cache_clear()


def test_an_unwritable_store_still_gives_the_design(tmp_path, monkeypatch):
    blocked = tmp_path / "file-not-folder"
    blocked.write_text("x")
    monkeypatch.setenv(design_store.STORE_ENV, str(blocked / "designs"))
    filters.design.cache_clear()
    try:
        d = filters.design(300.0, "bandpass", 3)
        assert np.array_equal(d.sos, _scipy_design(300.0, "bandpass", 3)[0])
    finally:
        filters.design.cache_clear()


_NO_SIGNAL = """
import json, sys
import numpy as np
from railval.core.filters import filtfilt_rows
from railval.core.psd import welch_psd
x = np.random.default_rng(1).standard_normal((3, 4000))
y = filtfilt_rows(x, 200.0, "lowpass")
b = filtfilt_rows(x, 200.0, "bandpass")
p = welch_psd(x[0], 200.0, 10.0)
print(json.dumps({"signal": "scipy.signal" in sys.modules, "stats": "scipy.stats" in sys.modules,
                  "sums": [float(y.sum()), float(b.sum()), float(p.density.sum())]}))
"""


def test_a_process_that_finds_the_designs_does_not_import_scipy_signal(store, monkeypatch):
    def run():
        proc = subprocess.run([sys.executable, "-c", _NO_SIGNAL], capture_output=True, text=True,
                              timeout=300, check=False)
        assert proc.returncode == 0, proc.stderr
        return json.loads(proc.stdout.splitlines()[-1])
    first = run()  # an empty store: scipy.signal makes the designs, the store keeps them
    assert first["signal"] is True
    second = run()
    assert second["signal"] is False and second["stats"] is False
    assert second["sums"] == first["sums"]  # the same numbers either way


def test_the_store_keeps_at_most_max_files_and_drops_those_used_longest_ago(store, monkeypatch):
    """Beyond ``MAX_FILES`` a write removes the files used longest ago down to three quarters;
    a file read recently stays, a removed one is computed again when asked for."""
    monkeypatch.setattr(design_store, "MAX_FILES", 8)
    made: list[str] = []

    def get(k: int) -> np.ndarray:
        def compute():
            made.append(f"k{k}")
            return {"x": np.full(3, float(k))}
        return design_store.arrays(f"test key {k}", compute, ("x",))["x"]

    for k in range(8):
        get(k)
    for k in range(8):  # key k last used at time k (long ago, in order)
        p = design_store.file_for(f"test key {k}")
        t = 1_000_000_000 + k
        os.utime(p, (t, t))
    assert float(get(0)[0]) == 0.0 and made.count("k0") == 1  # read from the store: now the newest
    get(8)  # the ninth file: trimmed to 6
    left = {k for k in range(9) if design_store.file_for(f"test key {k}").is_file()}
    assert left == {0, 4, 5, 6, 7, 8}
    assert float(get(1)[0]) == 1.0 and made.count("k1") == 2  # removed: computed again
