"""The engineer's selections shared by all pages, and background jobs (docs/design.md §2).

Long work runs through :meth:`AppState.run_job`: a thread calls the work function with a
``progress(fraction, message)`` callback; every state change is handed to ``dispatch`` (the
view passes one that schedules on the Bokeh document's event loop; tests pass the default,
which calls directly). Errors land in ``AppState.status`` with level ``"error"``.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Callable
from typing import Any

import param

from railval.app.security import plain_message
from railval.app.state.backend import Backend, CampaignOverview
from railval.core.quantities import derived_signals
from railval.core.errors import RailvalError
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


class JobCancelled(RailvalError):
    """The user cancelled a background job."""

#: jobs (simulation, calibration, diagnosis, metrics) running at once in this server, over
#: all browser sessions (``$RAILVAL_MAX_JOBS``, default 1: one calibration already keeps the
#: two cores of the deployment busy); further jobs wait in line with a "queued" status
MAX_JOBS = max(1, int(os.environ.get("RAILVAL_MAX_JOBS", "1")))
_JOB_SLOTS = threading.BoundedSemaphore(MAX_JOBS)
#: most campaign simulations one job may run (``$RAILVAL_MAX_JOB_SIMULATIONS``); a larger
#: diagnosis or calibration is refused with its cost shown, before it starts
MAX_JOB_SIMULATIONS = max(1, int(os.environ.get("RAILVAL_MAX_JOB_SIMULATIONS", "1000")))
#: (campaign, configuration) names that a running or queued job of this server will store:
#: a second job for the same name is refused when it is submitted, not at store time
_RESERVED: set[tuple[str, str]] = set()
_RESERVED_LOCK = threading.Lock()


def reserve_name(campaign: str, name: str) -> bool:
    """Reserve ``name`` in ``campaign`` for one job; ``False`` when another job holds it."""
    with _RESERVED_LOCK:
        if (campaign, name) in _RESERVED:
            return False
        _RESERVED.add((campaign, name))
        return True


def release_name(campaign: str, name: str) -> None:
    with _RESERVED_LOCK:
        _RESERVED.discard((campaign, name))


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
        self._job: threading.Thread | None = None
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

    def open_compare(self, section: str, channel: str, configuration: str | None = None) -> None:
        """Jump to the Compare page for one section/channel (dashboard drill-down)."""
        with param.parameterized.batch_call_watchers(self):
            if configuration is not None and configuration in self.param.configuration.objects:
                self.configuration = configuration
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
        """Run ``work(progress)`` in a thread; ``progress(fraction, message)`` updates the
        progress bar and status; ``on_done(result)`` runs through ``dispatch`` afterwards.
        Refuses (status warning) while another job runs so the page never double-submits,
        and (status error) when the session's user may not do ``action``. The job's database
        changes are recorded in the audit trail as that user. ``reserves=(campaign, name)``
        holds the configuration name the job will store from submission (also while queued)
        to its end: a second job for that name is refused at once."""
        if action is not None and not self.guard(action):
            return None
        if self.busy:
            self.set_status(f"{title}: another job is still running — wait for it to finish", "warning")
            return None
        if reserves is not None:
            if reserves[1] in (self.param.configuration.objects or []):
                self.set_status(f"{title} refused: configuration {reserves[1]!r} already exists in "
                                f"{reserves[0]!r} — choose another name", "error")
                return None
            if not reserve_name(*reserves):
                self.set_status(f"{title} refused: another job is already computing configuration "
                                f"{reserves[1]!r} in {reserves[0]!r} — choose another name", "error")
                return None
        call = dispatch or (lambda f: f())
        cancel = self._cancel = threading.Event()
        self.busy = True
        self.progress = 0.0
        self.set_status(f"{title}: started", "info")

        def progress(fraction: float, message: str = "") -> None:
            if cancel.is_set():  # the job stops at its next progress report
                raise JobCancelled(f"{title}: cancelled")
            frac = float(min(1.0, max(0.0, fraction if math.isfinite(fraction) else 0.0)))

            def apply():
                self.progress = frac
                self.set_status(f"{title}: {message}" if message else f"{title}: {frac:.0%}", "info")
            call(apply)

        def body():
            from railval.db.engine import acting_as

            if not _JOB_SLOTS.acquire(blocking=False):
                call(lambda: self.set_status(
                    f"{title}: queued — {MAX_JOBS} job(s) of this server are running; it starts "
                    "when one has finished", "info"))
                _JOB_SLOTS.acquire()
            try:
                if cancel.is_set():
                    raise JobCancelled(f"{title}: cancelled before it started")
                with acting_as(self.principal.username):
                    result = work(progress)
            except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
                if isinstance(exc, JobCancelled):
                    def cancelled(msg=str(exc)):
                        self.busy = False
                        self.set_status(msg, "warning")
                    call(cancelled)
                    return
                detail = plain_message(exc, title)

                def fail():
                    self.busy = False
                    self.set_status(f"{title} failed: {detail}", "error")
                call(fail)
                return
            finally:
                _JOB_SLOTS.release()
                if reserves is not None:
                    release_name(*reserves)

            def done():
                self.busy = False
                self.progress = 1.0
                self.set_status(f"{title}: done", "success")
                if on_done is not None:
                    try:
                        on_done(result)
                    except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
                        self.set_status(f"{title}: finished but showing the result failed: "
                                        f"{plain_message(exc, title)}", "error")
            call(done)

        if not background:
            body()
            return None
        self._job = threading.Thread(target=body, name=f"railval-job-{title}", daemon=True)
        self._job.start()
        return self._job

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
        cancel = getattr(self, "_cancel", None)
        if self.busy and cancel is not None:
            cancel.set()
            self.set_status("cancelling — the job stops after its current step", "warning")

    def wait(self, timeout: float | None = None) -> None:
        if self._job is not None:
            self._job.join(timeout)


