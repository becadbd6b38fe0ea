"""The batch executor gives identical results serially, on the local process pool and on a
real Dask distributed cluster (``LocalCluster`` with 2 worker processes)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from railval.app.services.batch import BatchExecutor, run_tasks
from railval.core.errors import InvalidParameter
from railval.core.modal import output_covariances, ssi_cov


def _sim_tasks():
    """Simulate two short sections (one with an effect) and evaluate a third, independently."""
    from railval.core.en14363 import evaluate_section
    from railval.core.sim import TrackSection, VehicleModel, simulate_section
    from railval.core.types import SectionInfo

    veh = VehicleModel("coach")
    tracks = [TrackSection(f"T{k}", speed_kmh=80, radius_m=400, cant_mm=100, straight_in_m=100,
                           transition_in_m=50, curve_m=150, transition_out_m=50, straight_out_m=100,
                           seed=k) for k in range(2)]
    tasks = [(simulate_section, (veh, tracks[0], {}), {"fs_out": 100.0}),
             (simulate_section, (veh, tracks[1], {"friction_damping": {"force_kN": 2.0}}), {"fs_out": 100.0})]
    ss = simulate_section(veh, tracks[0], {}, fs_out=100.0)
    info = SectionInfo("T0", 400, 100, 80, 3, 160.0, 290.0)
    tasks.append((evaluate_section, (ss, info), {}))
    return tasks


def _tasks():
    rng = np.random.default_rng(42)
    data = [rng.standard_normal((3000, 2)).cumsum(axis=0) * 0.01 + rng.standard_normal((3000, 2))
            for _ in range(4)]
    tasks = [(output_covariances, (y, 8), {}) for y in data]
    tasks += [(ssi_cov, (y, 50.0), {"block_rows": 10, "max_order": 12}) for y in data[:2]]
    return tasks + _sim_tasks()


def _same(a, b):
    from railval.core.types import SignalSet

    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        if isinstance(x, np.ndarray):
            np.testing.assert_array_equal(x, y)
        elif isinstance(x, SignalSet):
            assert x.channels.keys() == y.channels.keys()
            for ch in x.channels:
                np.testing.assert_array_equal(x.channels[ch], y.channels[ch])
        elif isinstance(x, dict):
            assert dict(x) == dict(y) and len(x) > 10
        else:
            np.testing.assert_array_equal(x.frequencies, y.frequencies)
            assert x.to_dict() == y.to_dict()


@pytest.fixture(scope="module")
def serial_results():
    return run_tasks(_tasks(), scheduler="serial")


def test_process_pool_equals_serial(serial_results):
    seen = []
    got = run_tasks(_tasks(), workers=2, progress=lambda d, t: seen.append((d, t)))
    _same(serial_results, got)
    assert seen[-1] == (9, 9) and len(seen) == 9


def test_dask_local_cluster_equals_serial(serial_results):
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster:
        got = run_tasks(_tasks(), scheduler=cluster.scheduler_address)
        with BatchExecutor(cluster.scheduler_address) as ex:
            assert ex.backend == "dask"
            squares = ex.map(np.square, [1.0, 2.0, 3.0])
    _same(serial_results, got)
    assert squares == [1.0, 4.0, 9.0]


def _blob_task(job):
    blob, k = job
    return len(blob), blob[:4], k


def test_broadcast_sends_a_large_object_to_the_workers_once_not_inside_each_task():
    """The diagnosis's families get their 19 MiB of evidence this way: on Dask a future that every
    task's argument resolves (the object does not travel inside each task through the scheduler:
    no "Sending large graph" warning), elsewhere the object itself."""
    distributed = pytest.importorskip("dask.distributed")
    blob = b"rail" + bytes(12 * 2**20)
    with BatchExecutor("serial") as ex:
        assert ex.broadcast(blob) is blob
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster, BatchExecutor(cluster.scheduler_address) as ex, \
            warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        ref = ex.broadcast(blob)
        got = ex.map(_blob_task, [(ref, k) for k in range(4)])
    assert got == [(len(blob), b"rail", k) for k in range(4)]
    assert not [w for w in seen if "large graph" in str(w.message)], [str(w.message) for w in seen]


def test_executor_is_a_differential_evolution_workers_map():
    with BatchExecutor("serial") as ex:
        assert ex(abs, [-1, 2, -3]) == [1, 2, 3]
    with pytest.raises(InvalidParameter):
        BatchExecutor(workers=0)
