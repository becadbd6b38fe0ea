"""``railval bench dynotrain`` on a tiny build: the all-configurations figure carries the
worker start-up, the main process's idle time and CPU seconds besides the stage split, on
both back ends, and the threads back end gives the same verdicts as the process pool (no
timing is asserted: the figures are printed, not tested)."""

from __future__ import annotations

import argparse

import pytest

from railval.app.bench import bench_dynotrain as bench


@pytest.mark.parametrize("backend", ["processes", "threads"])
def test_bench_prints_start_up_idle_and_split(tmp_path, backend):
    args = argparse.Namespace(configs=2, sections=4, samples=5000, fs=200.0, workers=2,
                              boot=20, data=str(tmp_path / "d"), dask=False, part="both",
                              repeat=1, backend=backend)
    out = bench.run(args)
    fig = out["all"]
    assert fig["backend"] == backend and fig["configurations"] == 2
    for key in ("worker_start_s", "main_idle_s", "cpu_seconds_main_process", "cpu_seconds"):
        assert fig[key] >= 0.0
    assert {"decode", "filter", "aggregation", "main_idle"} <= set(fig["split_s"])
    assert list(fig["split_s"])[:2] == ["database", "decode"]
    assert out["new_config"]["values"] > 0


def test_threads_and_processes_agree_on_the_bench_data(tmp_path):
    from railval.app.services.validation import validate_configurations
    from railval.db import repo
    from railval.db.engine import connect

    bench.build(tmp_path, 2, 4, 5000, 200.0)
    db = connect(f"sqlite:///{tmp_path / 'dynotrain.db'}")
    try:
        runs = []
        for backend in ("threads", "processes"):
            with db.session(write=True) as s:
                repo.cache_delete(s, prefix="en14363:")
            runs.append(validate_configurations(db, "dynotrain-bench", n_boot=30, workers=2,
                                                chunk_sections=2, backend=backend))
        assert list(runs[0]) == list(runs[1]) == ["c000", "c001"]
        for name in runs[0]:
            assert runs[0][name].to_dict() == runs[1][name].to_dict()
    finally:
        db.dispose()
