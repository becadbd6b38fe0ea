"""The batch executor gives identical results serially, on the local process pool and on a
real Dask distributed cluster (``LocalCluster`` with 2 worker processes)."""

from __future__ import annotations

import numpy as np
import pytest

from app.services.batch import BatchExecutor, run_tasks
from core.errors import InvalidParameter
from core.modal import output_covariances, ssi_cov


def _tasks():
    rng = np.random.default_rng(42)
    data = [rng.standard_normal((3000, 2)).cumsum(axis=0) * 0.01 + rng.standard_normal((3000, 2))
            for _ in range(4)]
    tasks = [(output_covariances, (y, 8), {}) for y in data]
    tasks += [(ssi_cov, (y, 50.0), {"block_rows": 10, "max_order": 12}) for y in data[:2]]
    return tasks


def _same(a, b):
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        if isinstance(x, np.ndarray):
            np.testing.assert_array_equal(x, y)
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
    assert seen[-1] == (6, 6) and len(seen) == 6


def test_dask_local_cluster_equals_serial(serial_results):
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        got = run_tasks(_tasks(), scheduler=cluster.scheduler_address)
        with BatchExecutor(cluster.scheduler_address) as ex:
            assert ex.backend == "dask"
            squares = ex.map(np.square, [1.0, 2.0, 3.0])
    _same(serial_results, got)
    assert squares == [1.0, 4.0, 9.0]


def test_executor_is_a_differential_evolution_workers_map():
    with BatchExecutor("serial") as ex:
        assert ex(abs, [-1, 2, -3]) == [1, 2, 3]
    with pytest.raises(InvalidParameter):
        BatchExecutor(workers=0)
