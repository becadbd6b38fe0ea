"""``railval bench diagnose`` reads a diagnosis's CPU time as its own process's and its ended
children's (the forked pool workers): a forked child's CPU counts once it has been joined, and
the calling process's does not take it in."""

from __future__ import annotations

import multiprocessing
import time

from railval.app.bench.bench_diagnose import _cpu


def _burn(seconds: float) -> None:
    t0 = time.process_time()
    x = 0
    while time.process_time() - t0 < seconds:
        x += 1


def test_a_joined_forked_childs_cpu_counts_as_the_workers_not_the_callers():
    own0, kids0 = _cpu()
    child = multiprocessing.get_context("fork").Process(target=_burn, args=(0.4,))
    child.start()
    child.join()
    own1, kids1 = _cpu()
    assert child.exitcode == 0
    assert kids1 - kids0 >= 0.35, (kids0, kids1)
    assert own1 - own0 < 0.2, (own0, own1)  # the caller only waited
