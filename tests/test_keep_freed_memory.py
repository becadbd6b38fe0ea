"""keep_freed_memory (core/workers.py): a render worker that receives, draws and sends back
plot after plot reuses its heap instead of faulting fresh pages in each time — the page
faults it stops, counted by the kernel (getrusage ru_minflt) in the workers of two pools
that render the same review plots, each started by a fresh process (as ``railval workshop
create`` starts them: a long-running parent may have raised glibc's thresholds already)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from railval.core.workers import keep_freed_memory

_POOL = """
import hashlib, json, multiprocessing, os, resource, sys, time
import numpy as np
from railval.app.services import workshop_render as wr
from railval.core.workshop import AxisRange, Scale

def faults(_=0):
    time.sleep(0.05)  # (so that the probes reach both workers)
    return os.getpid(), resource.getrusage(resource.RUSAGE_SELF).ru_minflt

if __name__ == "__main__":
    if sys.argv[1] == "plain":
        wr.keep_freed_memory = lambda: False
    wr.start_context = lambda: multiprocessing.get_context("fork")
    rng = np.random.default_rng(5)
    x = np.linspace(0.0, 1000.0, 6000)  # a section's length of samples (the demo's: 5634)
    scale = Scale(AxisRange(0.0, 1000.0, 200.0), AxisRange(-40.0, 40.0, 10.0))
    specs = [wr.PlotSpec(x, 20 * np.sin(x / (30 + i)) + rng.standard_normal(x.size), x,
                         15 * np.sin(x / (29 + i)), scale, f"Guiding force Y, plot {i}",
                         "distance in m", "guiding force Y in kN") for i in range(48)]
    with wr.early_pool(len(specs), workers=2) as pool:
        start = dict(f.result() for f in [pool.submit(faults) for _ in range(6)])
        pngs = wr.render_many(specs, pool=pool)
        end = dict(f.result() for f in [pool.submit(faults) for _ in range(6)])
    assert set(start) == set(end) and len(start) == 2, (start, end)
    print(json.dumps({"faults": sum(end[p] - start[p] for p in start),
                      "sha": hashlib.sha256(b"".join(pngs)).hexdigest()}))
"""


def _run(mode: str, tmp_path: Path) -> dict:
    script = tmp_path / f"pool_{mode}.py"
    script.write_text(_POOL)
    proc = subprocess.run([sys.executable, str(script), mode], capture_output=True, text=True,
                          timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.splitlines()[-1])


def test_render_workers_reuse_freed_buffers_instead_of_faulting_them_in(tmp_path):
    plain, kept = _run("plain", tmp_path), _run("keep", tmp_path)
    assert kept["sha"] == plain["sha"]  # the same PNG bytes
    if not sys.platform.startswith("linux"):  # no glibc: nothing to tell the allocator
        assert keep_freed_memory() is False
        return
    # measured: ≈ 90 000 pages faulted in while rendering without, ≈ 4 200 with
    assert plain["faults"] > 4 * kept["faults"], (plain, kept)
