"""Server-wide job limit: jobs of different browser sessions queue instead of running at
once (three calibrations used to run together: 8 processes, 1.8 GB), and a clashing
configuration name is refused before any computing."""

from __future__ import annotations

import threading
import time

import pytest

from railval.app.state import AppState, Backend
from railval.app.state import app as app_module


def test_jobs_of_two_sessions_run_one_after_the_other(sqlite_database):
    assert app_module.MAX_JOBS == 1
    backend = Backend(sqlite_database)
    first, second = AppState(backend), AppState(backend)
    release = threading.Event()
    started: list[str] = []

    def work(name):
        def run(progress):
            started.append(name)
            if name == "a":
                assert release.wait(60)
            return name
        return run

    first.run_job("simulate A", work("a"))
    deadline = time.monotonic() + 10
    while "a" not in started and time.monotonic() < deadline:
        time.sleep(0.01)
    second.run_job("simulate B", work("b"))
    time.sleep(0.5)
    assert started == ["a"], "the second session's job ran while the first was running"
    assert "queued" in second.status
    release.set()
    first.wait(30)
    second.wait(30)
    assert started == ["a", "b"]
    assert second.status == "simulate B: done"


def test_calibrate_refuses_an_existing_name_before_fitting(sqlite_database, tmp_path):
    from railval.app.services.calibration import calibrate
    from railval.core.errors import InvalidParameter
    from railval.db.importer import import_campaign
    from tests.factories import write_demo_campaign

    write_demo_campaign(tmp_path / "c", n_sections=1, fmt="parquet", n_configs=2)
    import_campaign(sqlite_database, tmp_path / "c")
    t = time.perf_counter()
    with pytest.raises(InvalidParameter, match="'variant1' already exists .* --replace"):
        calibrate(sqlite_database, "demo", "baseline", ["friction_damping"], "variant1")
    assert time.perf_counter() - t < 5


def test_cancel_stops_a_job_at_its_next_step(sqlite_database):
    state = AppState(Backend(sqlite_database))
    steps: list[int] = []
    go = threading.Event()

    def work(progress):
        for k in range(200):
            progress(k / 200, f"step {k}")
            steps.append(k)
            if k == 2:
                go.set()
            time.sleep(0.02)
        return "finished"

    state.run_job("calibrate", work)
    assert go.wait(30)
    state.cancel_job()
    state.wait(30)
    assert not state.busy
    assert state.status == "calibrate: cancelled"
    assert len(steps) < 200


def test_job_over_the_cost_cap_is_refused_with_its_cost(tmp_path, monkeypatch):
    from railval.app.state import DiagnoseState
    from tests.browser_support import demo_database

    db = demo_database(tmp_path)
    app = AppState(Backend(db))
    diag = DiagnoseState(app)
    assert diag.calibration_simulations() <= app_module.MAX_JOB_SIMULATIONS  # defaults run
    diag.effect = diag.param.effect.objects[0] if diag.param.effect.objects else "friction_damping"
    cost = diag.calibration_simulations()
    # the local fit of at most 3 parameters stays under the default cap: a lower cap refuses it
    monkeypatch.setattr(app_module, "MAX_JOB_SIMULATIONS", cost - 1)
    assert diag.run_calibration(background=False) is None
    assert app.status_level == "error" and not app.busy
    assert app.status.startswith(f"calibration refused: it would simulate the campaign {cost} "
                                 f"times, more than the limit of {app_module.MAX_JOB_SIMULATIONS}")
    db.dispose()


def test_a_queued_job_reserves_its_configuration_name(sqlite_database):
    """Two sessions submitting jobs that would store the same configuration: the second is
    refused when it is submitted (while the first still waits or runs), not at store time;
    after the first ends the name is free again."""
    backend = Backend(sqlite_database)
    first, second, third = AppState(backend), AppState(backend), AppState(backend)
    release = threading.Event()
    ran: list[str] = []

    def blocking(progress):
        ran.append("first")
        assert release.wait(60)
        return "first"

    first.run_job("calibration", blocking, reserves=("demo", "base+fd"))
    # the first job holds the only slot; a job for another name queues, one for the same name is refused
    assert second.run_job("calibration", lambda p: ran.append("same"), reserves=("demo", "base+fd")) is None
    assert second.status_level == "error" and "'base+fd'" in second.status and "another job" in second.status
    assert not second.busy
    third.run_job("calibration", lambda p: ran.append("other"), reserves=("demo", "base+other"))
    release.set()
    first.wait(30)
    third.wait(30)
    assert ran == ["first", "other"]
    # released at the end: the same name may be submitted again
    second.run_job("calibration", lambda p: ran.append("again"), reserves=("demo", "base+fd"))
    second.wait(30)
    assert ran[-1] == "again" and second.status == "calibration: done"
    assert not app_module._RESERVED
