"""The validation services leave the heap alive on entry out of the garbage collector's passes
while they run (app/services/validation_exec.py ``heap_frozen``) and give it back afterwards, also
when validations nest or run on several threads at once."""

import gc
import threading

import pytest

from railval.app.services import validation as V
from railval.app.services.validation_exec import heap_frozen


@pytest.fixture(autouse=True)
def _no_frozen_heap():
    gc.unfreeze()
    yield
    gc.unfreeze()


def test_frozen_inside_and_given_back_after():
    keep = [{"x": 1}]  # a container alive on entry
    with heap_frozen():
        assert gc.get_freeze_count() > 0
        assert not any(o is keep for o in gc.get_objects())
    assert gc.get_freeze_count() == 0
    assert any(o is keep for o in gc.get_objects())


def test_nested_and_concurrent_uses_unfreeze_when_the_last_ends():
    inner_started, outer_may_end = threading.Event(), threading.Event()
    seen = []

    def other():
        with heap_frozen():
            inner_started.set()
            outer_may_end.wait(10)
        seen.append(gc.get_freeze_count())

    with heap_frozen():
        t = threading.Thread(target=other)
        t.start()
        assert inner_started.wait(10)
        with heap_frozen():
            pass
        assert gc.get_freeze_count() > 0  # the nested context ended, the others have not
    assert gc.get_freeze_count() > 0  # the thread's validation still runs
    outer_may_end.set()
    t.join(10)
    assert seen == [0] and gc.get_freeze_count() == 0


def test_given_back_when_the_validation_fails(monkeypatch):
    def boom(*_a, **_k):
        assert gc.get_freeze_count() > 0
        raise RuntimeError("planning failed")

    monkeypatch.setattr(V, "_plan", boom)
    with pytest.raises(RuntimeError, match="planning failed"):
        V.validate_configurations(object(), "c", ["x"])
    assert gc.get_freeze_count() == 0
