"""The background warm-up of ``railval serve`` (app/services/warmup.py): it compiles the
kernels a validation runs, so a validation afterwards compiles nothing; it runs at the lowest
priority and can be switched off."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

from railval.app.services import warmup


def _cache_files(folder: Path) -> dict[str, int]:
    """numba's cache files (index and compiled code) with their modification times."""
    return {str(p.relative_to(folder)): p.stat().st_mtime_ns
            for p in folder.rglob("*") if p.suffix in (".nbi", ".nbc")}


def test_warm_compiles_what_a_validation_needs(tmp_path, demo_campaign_dir):
    cache = tmp_path / "numba-cache"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "RAILVAL_DB": f"sqlite:///{tmp_path / 'w.db'}"}
    out = subprocess.run([sys.executable, "-m", "railval.app.services.warmup"], env=env,
                         capture_output=True, text=True, timeout=600, check=True)
    seconds = json.loads(out.stdout)
    assert set(seconds) == {"import_s", "codec_s", "en_chain_s", "total_s"}
    files = _cache_files(cache)
    for module in ("filters", "en_kernels", "codec_planes"):  # the EN chain and the codec
        assert any(f"{module}." in name and name.endswith(".nbc") for name in files), (module, files)

    for verb in (["init"], ["import", str(demo_campaign_dir)]):
        subprocess.run([sys.executable, "-m", "railval.app", *verb], env=env, check=True,
                       capture_output=True, timeout=600)
    res = subprocess.run([sys.executable, "-m", "railval.app", "validate", "demo", "--config",
                          "baseline"], env=env, capture_output=True, text=True, timeout=600,
                         check=False)
    assert res.returncode in (0, 1), res.stderr  # 1: the configuration is not validated
    assert "VALIDATED" in res.stdout
    # the validation found every kernel compiled for its types: no cache file new or rewritten
    assert _cache_files(cache) == files


def test_start_background_lowest_priority_and_switch(monkeypatch):
    monkeypatch.setenv(warmup.NO_WARMUP_ENV, "1")
    assert warmup.start_background() is None
    monkeypatch.setenv(warmup.NO_WARMUP_ENV, "0")
    proc = warmup.start_background()
    assert proc is not None
    try:
        assert proc.args[-1] == "railval.app.services.warmup"
        deadline = time.monotonic() + 30  # the child lowers itself first thing
        while os.getpriority(os.PRIO_PROCESS, proc.pid) != 19 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert os.getpriority(os.PRIO_PROCESS, proc.pid) == 19
    finally:
        proc.kill()
    deadline = time.monotonic() + 30  # reaped by the server's thread, not by this test
    while proc.returncode is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert proc.returncode is not None
