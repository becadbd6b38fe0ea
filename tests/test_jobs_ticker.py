"""The served sessions' job lists are refreshed by one ticker per server IOLoop
(``railval.app.upkeep._tick_jobs``), not a Panel periodic callback per session (docs/app.md,
"Sessions that close"): a list whose text changed is set in its document's next tick, an
unchanged one schedules nothing, and a closed session's document is no longer visited. The
browser test tests/test_browser_jobs_nav.py sees the list change in a real session."""

from __future__ import annotations

import weakref

import panel as pn

from railval.app import upkeep
from railval.app.navigation import jobs_html
from railval.app.state import jobs


class FakeDoc:
    def __init__(self):
        self.scheduled = []

    def add_next_tick_callback(self, cb):
        self.scheduled.append(cb)


def test_only_a_changed_job_list_is_sent_and_in_its_own_document():
    panes = weakref.WeakKeyDictionary()
    quiet_doc, busy_doc = FakeDoc(), FakeDoc()
    quiet = pn.pane.HTML(jobs_html(jobs.jobs_of("ticker-quiet")))
    busy = pn.pane.HTML(jobs_html(jobs.jobs_of("ticker-busy")))
    panes[quiet_doc] = (quiet, "ticker-quiet")
    panes[busy_doc] = (busy, "ticker-busy")
    upkeep._tick_jobs(panes)
    assert quiet_doc.scheduled == [] and busy_doc.scheduled == []
    rec = jobs.track("ticker-busy", "Create workshop T", "/app?page=dashboard")
    upkeep._tick_jobs(panes)
    assert quiet_doc.scheduled == []
    assert len(busy_doc.scheduled) == 1
    busy_doc.scheduled.pop()()  # the next tick of that document
    assert "Create workshop T" in busy.object
    jobs.update(rec, state="done")
    upkeep._tick_jobs(panes)
    busy_doc.scheduled.pop()()
    assert "data-state='done'" in busy.object
    del panes[busy_doc]  # its session closed
    jobs.update(rec, message="later")
    upkeep._tick_jobs(panes)
    assert busy_doc.scheduled == []
