"""Workshop storage on both backends: concurrent submissions of the same place never
duplicate an answer; a reviewer sees only their own answers; campaign deletion is refused
while a workshop uses it."""

from __future__ import annotations

import threading

import pytest
from railval.db import workshops as wsdb
from railval.db.models import Campaign, WorkshopAnswer
from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError


def _workshop(database, n_plots: int = 6):
    with database.session(write=True) as s:
        camp = Campaign(name="c")
        s.add(camp)
        s.flush()
        plots = [{"kind": "Y_time", "section": "S01", "configuration": "base",
                  "channel": f"Y_w{i}L", "render": {"i": i}, "image": b"\x89PNG fake %d" % i}
                 for i in range(n_plots)]
        w = wsdb.create_workshop(s, "W", camp.id, blind=False, repeat_share=0.0, auto_share=0.0,
                                 settings={}, scales={}, plots=plots)
        t1 = wsdb.invite(s, w, "alice", seed=1)
        t2 = wsdb.invite(s, w, "bob", seed=2)
    return t1, t2


def test_concurrent_submissions_of_one_place_store_one_answer(database):
    t1, _ = _workshop(database)
    errors: list[BaseException] = []
    barrier = threading.Barrier(8)

    def submit(k: int) -> None:
        try:
            with database.session() as s:
                ctx = wsdb.reviewer_by_token(s, t1)
            barrier.wait(10)
            with database.session(write=True) as s:  # as record_answer's docstring asks
                wsdb.record_answer(s, ctx, k % 2, k % 3 == 0, seconds=1.0, submission=f"s{k}")
        except BaseException as exc:  # noqa: BLE001 - collected for the assertion
            errors.append(exc)

    threads = [threading.Thread(target=submit, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    with database.session() as s:
        rows = s.execute(select(WorkshopAnswer.position, func.count())
                         .group_by(WorkshopAnswer.position)).all()
        assert sorted(rows) == [(0, 1), (1, 1)]
        # 4 submissions per place: one insert, three updates
        assert sorted(s.scalars(select(WorkshopAnswer.changes))) == [3, 3]


def test_own_answers_only_and_campaign_kept(database):
    t1, t2 = _workshop(database)
    with database.session(write=True) as s:
        a, b = wsdb.reviewer_by_token(s, t1), wsdb.reviewer_by_token(s, t2)
        wsdb.record_answer(s, a, 0, True, seconds=1.0, submission="x")
        wsdb.record_answer(s, b, 0, False, seconds=1.0, submission="y")
        wsdb.record_answer(s, b, 1, False, seconds=1.0, submission="z")
    with database.session() as s:
        assert set(wsdb.own_answers(s, a.reviewer_id)) == {0}
        assert {p: x.answer for p, x in wsdb.own_answers(s, b.reviewer_id).items()} == {0: False, 1: False}
        prog = {r["reviewer"]: (r["answered"], r["yes"]) for r in wsdb.progress(s, wsdb.get_workshop(s, "W"))}
        assert prog == {"alice": (1, 1), "bob": (2, 0)}
    with pytest.raises(IntegrityError), database.session(write=True) as s:
        s.delete(s.scalar(select(Campaign)))
        s.flush()
    with database.session() as s:
        assert s.scalar(select(func.count()).select_from(WorkshopAnswer)) == 3
