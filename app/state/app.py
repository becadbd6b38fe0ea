"""The engineer's selections shared by all pages, and background jobs (docs/design.md §2).

Long work runs through :meth:`AppState.run_job`, which hands it to the session's
:class:`~railval.app.state.jobs.JobRunner` (its own module): a thread calls the work
function with a ``progress(fraction, message)`` callback and every state change goes
through ``dispatch``. Errors land in ``AppState.status`` with level ``"error"``.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from typing import Any

import param

from railval.app.security import plain_message
from railval.app.state.backend import Backend, CampaignOverview
from railval.app.state.jobs import (  # noqa: F401 - re-exported for callers
    _RESERVED,
    MAX_JOBS,
    JobCancelled,
    JobRunner,
    release_name,
    reserve_name,
)
from railval.core.quantities import derived_signals
from railval.core.roles import ACTIONS, PAGE_ACTIONS, Principal, allowed, open_principal

PAGES = ("overview", "compare", "dashboard", "metrics", "diagnose", "report", "signoff", "audit",
         "import")
PAGE_TITLES = {
    "overview": "Campaign overview",
    "compare": "Compare signals",
    "dashboard": "Validation dashboard",
    "metrics": "Curve metrics",
    "diagnose": "Diagnose & model workshop",
    "report": "Report",
    "signoff": "Sign-off",
    "audit": "Audit trail",
    "import": "Import",
}

#: a session's user is re-read from the database at most this long after the last check
#: (page reads); every action (store, calibrate, simulate, sign) re-reads it at once
ACCESS_RECHECK_S = 2.0
ACCESS_ENDED = ("Your access has ended: the account was disabled, its password changed or "
                "the sign-in expired. Sign in again at /login.")


#: most campaign simulations one job may run (``$RAILVAL_MAX_JOB_SIMULATIONS``); a larger
#: diagnosis or calibration is refused with its cost shown, before it starts
MAX_JOB_SIMULATIONS = max(1, int(os.environ.get("RAILVAL_MAX_JOB_SIMULATIONS", "1000")))


class AppState(param.Parameterized):
    """What the engineer has selected, shared by all pages."""

    campaign = param.Selector(default=None, objects=[], allow_None=True)
    configuration = param.Selector(default=None, objects=[], allow_None=True)
    page = param.Selector(default="overview", objects=list(PAGES))
    section = param.Selector(default=None, objects=[], allow_None=True)
    channel = param.Selector(default=None, objects=[], allow_None=True)
    status = param.String(default="", doc="message of the status area")
    status_level = param.Selector(default="info", objects=["info", "success", "warning", "error"])
    busy = param.Boolean(default=False, doc="a background job is running")
    progress = param.Number(default=0.0, bounds=(0.0, 1.0))
    revision = param.Integer(default=0, doc="bumped when the database changed (new configuration)")

    def __init__(self, backend: Backend, principal: Principal | None = None, *,
                 recheck: Callable[[], Principal | None] | None = None, **params):
        super().__init__(**params)
        self.backend = backend
        #: who acts in this browser session (server side; open mode without users)
        self.principal = principal or open_principal()
        #: re-reads the session's user from the database (cookie → user, enabled, roles,
        #: password unchanged, not expired); ``None`` in tests that fix the principal
        self._recheck = recheck
        self._checked_at = time.monotonic()
        self.access_ended = False
        self.jobs = JobRunner(self)
        if not self.page_allowed(self.page):
            permitted = self.pages_allowed()
            self.page = permitted[0] if permitted else "overview"
        self.refresh_campaigns()

    # -- authorization (core/roles.py is the registry)
    def current_principal(self, *, fresh: bool = False) -> Principal | None:
        """The session's user as the database has it now (re-read when ``fresh`` or after
        :data:`ACCESS_RECHECK_S`); ``None`` once access has ended (disabled, password
        changed, cookie expired) — for good: the tab can do nothing more."""
        if self.access_ended:
            return None
        if self._recheck is None:
            return self.principal
        now = time.monotonic()
        if fresh or now - self._checked_at >= ACCESS_RECHECK_S:
            p = self._recheck()
            self._checked_at = now
            if p is None:
                self.access_ended = True
                self.set_status(ACCESS_ENDED, "error")
                return None
            self.principal = p
        return self.principal

    def allowed(self, action: str, *, fresh: bool = False) -> bool:
        p = self.current_principal(fresh=fresh)
        return p is not None and allowed(p, action)

    def page_allowed(self, page: str) -> bool:
        return page in PAGE_ACTIONS and self.allowed(PAGE_ACTIONS[page])

    def pages_allowed(self) -> list[str]:
        return [p for p in PAGES if self.page_allowed(p)]

    def denial(self, action: str) -> str:
        """The message shown when ``action`` is refused (never a traceback)."""
        held = ", ".join(sorted(self.principal.roles)) or "no role"
        return (f"Not allowed: {self.principal.printed_name} ({held}) may not "
                f"{ACTIONS[action]}.")

    def guard(self, action: str) -> bool:
        """True when allowed (the user re-read from the database first); otherwise an error
        in the status area and False."""
        if self.allowed(action, fresh=True):
            return True
        self.set_status(ACCESS_ENDED if self.access_ended else self.denial(action), "error")
        return False

    # -- selections
    def refresh_campaigns(self) -> None:
        try:
            names = self.backend.campaigns()
        except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
            self.set_status(f"cannot list campaigns: {plain_message(exc, 'campaigns')}", "error")
            names = []
        self.param.campaign.objects = names
        if names and self.campaign not in names:
            self.campaign = names[0]
        elif self.campaign is not None:
            self._campaign_changed()

    @param.depends("campaign", watch=True)
    def _campaign_changed(self) -> None:
        if self.campaign is None:
            return
        try:
            ov = self.backend.overview(self.campaign)
        except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
            self.set_status(f"cannot open campaign {self.campaign!r}: "
                            f"{plain_message(exc, 'campaign')}", "error")
            return
        self.overview = ov
        configs = [c.name for c in ov.configurations]
        sections = [s.id for s in ov.sections]
        raw = [c["name"] for c in ov.channels]
        # the Compare page also shows the derived signals the quantities use (Y/Q, ΣY)
        chans = raw + list(derived_signals(raw))
        with param.parameterized.batch_call_watchers(self):
            self.param.configuration.objects = configs
            self.param.section.objects = sections
            self.param.channel.objects = chans
            if self.configuration not in configs:
                self.configuration = configs[0] if configs else None
            if self.section not in sections:
                self.section = sections[0] if sections else None
            if self.channel not in chans:
                self.channel = chans[0] if chans else None

    overview: CampaignOverview | None = None

    def reload_configurations(self, select: str | None = None) -> None:
        """Re-read configurations after a job stored a new one; optionally select it."""
        self.backend.invalidate()
        self._campaign_changed()
        if select is not None and select in self.param.configuration.objects:
            self.configuration = select
        self.revision += 1

    def open_compare(self, section: str, channel: str, config: str | None = None) -> None:
        """Jump to the Compare page for one section/channel (dashboard drill-down)."""
        with param.parameterized.batch_call_watchers(self):
            if config is not None and config in self.param.configuration.objects:
                self.configuration = config
            if section in self.param.section.objects:
                self.section = section
            if channel in self.param.channel.objects:
                self.channel = channel
            self.page = "compare"

    def set_status(self, message: str, level: str = "info") -> None:
        self.status_level = level
        self.status = message

    # -- background jobs
    def run_job(self, title: str, work: Callable[[Callable[[float, str], None]], Any],
                on_done: Callable[[Any], None] | None = None,
                dispatch: Callable[[Callable[[], None]], None] | None = None,
                background: bool = True, action: str | None = None,
                reserves: tuple[str, str] | None = None) -> threading.Thread | None:
        """Run ``work(progress)`` in a thread (:class:`~railval.app.state.jobs.JobRunner`);
        ``progress(fraction, message)`` updates the progress bar and status; ``on_done(result)``
        runs through ``dispatch`` afterwards. Refuses (status warning) while another job runs
        so the page never double-submits, and (status error) when the session's user may not
        do ``action``. The job's database changes are recorded in the audit trail as that
        user. ``reserves=(campaign, name)`` holds the configuration name the job will store
        from submission (also while queued) to its end: a second job for that name is
        refused at once."""
        return self.jobs.submit(title, work, on_done, dispatch=dispatch, background=background,
                                action=action, reserves=reserves)

    def within_cost_cap(self, title: str, simulations: int) -> bool:
        """``True`` when a job of ``simulations`` campaign simulations may run; else the
        status says the cost and the cap and ``False`` is returned."""
        if simulations > MAX_JOB_SIMULATIONS:
            self.set_status(f"{title} refused: it would simulate the campaign {simulations} times, "
                            f"more than the limit of {MAX_JOB_SIMULATIONS} per job — choose fewer "
                            "candidates, values or generations", "error")
            return False
        return True

    def cancel_job(self) -> None:
        """Ask the running job to stop: it ends at its next progress report (a simulation
        or calibration step), or before it starts when it is still queued."""
        if self.jobs.cancel():
            self.set_status("cancelling — the job stops after its current step", "warning")

    def wait(self, timeout: float | None = None) -> None:
        self.jobs.wait(timeout)
