"""``railval.core.workers.background``: work started on a row thread while the caller goes
on (the verdict's bootstrap); inline with one row thread or inside a row thread."""

from __future__ import annotations

import threading

import pytest

from railval.core import workers


def test_runs_on_a_row_thread_and_returns_its_value():
    with workers.row_threads(2):
        fut = workers.background(lambda: threading.current_thread().name)
    assert fut.result().startswith("railval-rows")


def test_inline_with_one_row_thread_and_errors_reach_the_caller():
    with workers.row_threads(1):
        fut = workers.background(lambda: threading.current_thread().name)
        assert fut.done() and fut.result() == threading.current_thread().name
        bad = workers.background(lambda: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        bad.result()


def test_inside_a_row_thread_it_does_not_wait_on_the_pool():
    with workers.row_threads(2):
        outer = workers.background(
            lambda: workers.background(lambda: threading.current_thread().name).result())
    assert outer.result().startswith("railval-rows")  # ran inline in the same row thread
