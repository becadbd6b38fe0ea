"""The stage split of a validation (railval.core.stages; railval bench dynotrain prints it):
nested stages count their own time only, worker threads report into the collector, and a
validation from the database reports every stage it runs through (docs/validation.md)."""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor

import pytest

from railval.app.services.validation import validate_configuration, validate_configurations
from railval.core.stages import collect, current, in_context, stage
from railval.db.importer import import_campaign

from tests.factories import write_demo_campaign


def test_nested_stage_counts_its_own_time():
    with collect() as st:
        with stage("outer"):
            time.sleep(0.05)
            with stage("inner"):
                time.sleep(0.1)
    assert 0.1 <= st.seconds["inner"] < 0.2
    assert 0.05 <= st.seconds["outer"] < 0.1  # without the inner 0.1 s


def test_without_a_collector_nothing_is_kept():
    assert current() is None
    with stage("x"):
        pass
    assert current() is None


def test_worker_threads_report_into_the_collector():
    def work():
        with stage("decode"):
            time.sleep(0.05)

    with collect() as st, ThreadPoolExecutor(2) as pool:
        with stage("database"):
            futures = [pool.submit(in_context(work)) for _ in range(2)]
        for f in futures:
            f.result()
    assert st.seconds["decode"] >= 0.1  # two threads, added up
    assert st.seconds["database"] >= 0.0  # the threads' time is not subtracted from it


@pytest.fixture
def stored(sqlite_database, tmp_path):
    write_demo_campaign(tmp_path / "c", n_sections=12, n_configs=2, fs=200.0)
    import_campaign(sqlite_database, tmp_path / "c")
    return sqlite_database


EN = {"checks", "filter", "statistics", "alternatives", "supplementary"}


def test_validation_reports_every_stage(stored):
    with collect() as cold, stored.write_session(deferred=True) as s:
        validate_configuration(s, "demo", "baseline", n_boot=200)
    assert EN | {"database", "decode", "cache_pack", "aggregation", "bootstrap"} <= set(cold.seconds)
    assert all(v >= 0 for v in cold.seconds.values())
    with collect() as warm, stored.write_session(deferred=True) as s:
        validate_configuration(s, "demo", "baseline", n_boot=200)
    assert "cache_unpack" in warm.seconds and not EN & set(warm.seconds)  # all from the cache


@pytest.mark.parametrize("workers", [1, 2])
def test_dynotrain_path_reports_worker_stages(stored, workers):
    with collect() as st:
        validate_configurations(stored, "demo", n_boot=100, workers=workers, chunk_sections=4)
    assert EN | {"database", "decode", "aggregation", "bootstrap"} <= set(st.seconds)
