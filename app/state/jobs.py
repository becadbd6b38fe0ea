"""Background jobs of the web app (docs/design.md §2): :class:`JobRunner` runs one browser
session's long work (simulation, calibration, diagnosis, metrics, import, sign-off) beside
the session's :class:`~railval.app.state.app.AppState`, which it reports to.

A job is ``work(progress)``: a thread calls it with a ``progress(fraction, message)``
callback; every change of the state (progress bar, status area, busy flag) is handed to
``dispatch`` (the view passes one that schedules on the Bokeh document's event loop; tests
pass none, which calls directly). Jobs of all sessions of this server share
:data:`MAX_JOBS` slots; further jobs wait in line with a "queued" status. A configuration
name a job will store is reserved from submission to its end, so a second job for it is
refused at once. Errors land in the status area as a plain message (the details in the
server log, :func:`railval.app.security.plain_message`).

Every job is also recorded in this server's job list (:class:`JobRecord`, :func:`jobs_of`):
its user, title, state (queued, running, done, failed, cancelled), progress (fraction and,
where the work counts, ``done`` of ``total``), start and end time and the link to its result
(the app page with the job's campaign and configuration selected, or the workshop's page).
A browser session that is reloaded, or any other page the user opens, lists the user's
running and recently finished jobs from it (the Panel sidebar, the workshop pages), never
another user's. Work that runs outside a Panel session (a workshop being created from its
web page) is started with :func:`start_tracked` and shares the same slots.
"""

from __future__ import annotations

import itertools
import math
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import urlencode

from railval.app.security import plain_message
from railval.app.services.overview import acting_as
from railval.core.errors import InvalidParameter, RailvalError

#: jobs (simulation, calibration, diagnosis, metrics) running at once in this server, over
#: all browser sessions (``$RAILVAL_MAX_JOBS``, default 1: one calibration already keeps the
#: two cores of the deployment busy); further jobs wait in line with a "queued" status
MAX_JOBS = max(1, int(os.environ.get("RAILVAL_MAX_JOBS", "1")))
_JOB_SLOTS = threading.BoundedSemaphore(MAX_JOBS)
#: (campaign, configuration) names that a running or queued job of this server will store:
#: a second job for the same name is refused when it is submitted, not at store time
_RESERVED: set[tuple[str, str]] = set()
_RESERVED_LOCK = threading.Lock()

Dispatch = Callable[[Callable[[], None]], None]


class JobCancelled(RailvalError):
    """The user cancelled a background job."""


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


# -------------------------------------------------------------------------- job list
#: finished jobs stay listed this long (seconds) ...
RECENT_S = 3600.0
#: ... and at most this many finished jobs per user
RECENT_PER_USER = 8
APP_URL = "/app"


def app_link(page: str, **selection: str | None) -> str:
    """The app's URL opening ``page`` with the given campaign/configuration selected."""
    query = {"page": page, **{k: v for k, v in selection.items() if v}}
    return f"{APP_URL}?{urlencode(query)}"


@dataclass
class JobRecord:
    """One job of this server as its user's job lists show it."""

    id: str
    user: str
    title: str
    link: str
    workshop: str | None = None
    state: str = "queued"
    fraction: float = 0.0
    message: str = ""
    done: int | None = None
    total: int | None = None
    error: str = ""
    started: float = field(default_factory=time.time)
    ended: float | None = None

    @property
    def active(self) -> bool:
        return self.state in ("queued", "running")

    def to_dict(self) -> dict[str, Any]:
        end = self.ended if self.ended is not None else time.time()
        return {"id": self.id, "title": self.title, "link": self.link, "workshop": self.workshop,
                "state": self.state, "fraction": round(self.fraction, 4), "message": self.message,
                "done": self.done, "total": self.total, "error": self.error,
                "elapsed_s": round(max(0.0, end - self.started), 1),
                "started": self.started, "ended": self.ended}


_JOBS: dict[str, JobRecord] = {}
_JOBS_LOCK = threading.Lock()
_IDS = itertools.count(1)


def track(user: str, title: str, link: str, *, workshop: str | None = None) -> JobRecord:
    """A new entry of ``user``'s job list (state ``queued``)."""
    rec = JobRecord(id=f"j{next(_IDS)}", user=user, title=title, link=link, workshop=workshop)
    with _JOBS_LOCK:
        _JOBS[rec.id] = rec
        _prune(user)
    return rec


def _prune(user: str) -> None:
    now = time.time()
    ended = sorted((r for r in _JOBS.values() if r.user == user and not r.active),
                   key=lambda r: r.ended or 0.0, reverse=True)
    for i, r in enumerate(ended):
        if i >= RECENT_PER_USER or now - (r.ended or now) > RECENT_S:
            _JOBS.pop(r.id, None)


def update(rec: JobRecord, **changes: Any) -> None:
    with _JOBS_LOCK:
        for k, v in changes.items():
            setattr(rec, k, v)
        if not rec.active and rec.ended is None:
            rec.ended = time.time()


def jobs_of(user: str) -> list[dict[str, Any]]:
    """``user``'s running and queued jobs, then those finished in the last :data:`RECENT_S`
    seconds, newest first (only that user's)."""
    with _JOBS_LOCK:
        _prune(user)
        mine = [r for r in _JOBS.values() if r.user == user]
        mine.sort(key=lambda r: (not r.active, -r.started))
        return [r.to_dict() for r in mine]


def creating(workshop: str) -> JobRecord | None:
    """The queued or running job creating ``workshop`` (any user's), else ``None``."""
    with _JOBS_LOCK:
        return next((r for r in _JOBS.values() if r.workshop == workshop and r.active), None)


def workshop_job(user: str, workshop: str) -> dict[str, Any] | None:
    """``user``'s latest job creating ``workshop`` (running or recently finished)."""
    with _JOBS_LOCK:
        mine = [r for r in _JOBS.values() if r.user == user and r.workshop == workshop]
        return max(mine, key=lambda r: r.started).to_dict() if mine else None


def start_tracked(user: str, title: str, work: Callable[[Callable[..., None]], Any], *,
                  link: str, workshop: str | None = None) -> JobRecord:
    """Run ``work(progress)`` in a thread outside any browser session (a workshop created
    from its web page) in one of the server's :data:`MAX_JOBS` slots, recorded in ``user``'s
    job list; ``progress(stage, fraction, info)`` with ``info`` ``{"done", "total"}`` when the
    work counts. Refused with :class:`~railval.core.errors.InvalidParameter` while another job
    creates the same workshop."""
    with _JOBS_LOCK:
        if workshop is not None and any(r.workshop == workshop and r.active for r in _JOBS.values()):
            raise InvalidParameter(f"workshop {workshop!r} is already being created; wait for "
                                   "it or choose another name")
        rec = JobRecord(id=f"j{next(_IDS)}", user=user, title=title, link=link, workshop=workshop)
        _JOBS[rec.id] = rec

    def progress(stage: str, fraction: float, info: dict | None = None) -> None:
        info = info or {}
        update(rec, state="running", message=stage,
               fraction=float(min(1.0, max(0.0, fraction if math.isfinite(fraction) else 0.0))),
               done=info.get("done", rec.done), total=info.get("total", rec.total))

    def run() -> None:
        _JOB_SLOTS.acquire()
        try:
            update(rec, state="running", started=time.time())
            work(progress)
        except Exception as exc:  # noqa: BLE001 - shown on the job's page
            update(rec, state="failed", error=plain_message(exc, title))
        else:
            update(rec, state="done", fraction=1.0, message="done")
        finally:
            _JOB_SLOTS.release()
    threading.Thread(target=run, name=f"railval-job-{title}", daemon=True).start()
    return rec


def _direct(fn: Callable[[], None]) -> None:
    fn()


class _Job:
    """One submitted job: its progress callback and its run (slot, work, outcome)."""

    def __init__(self, state: Any, title: str, work: Callable, on_done: Callable | None,
                 call: Dispatch, cancel: threading.Event, reserves: tuple[str, str] | None,
                 record: JobRecord):
        self.state, self.title, self.work, self.on_done = state, title, work, on_done
        self.call, self.cancel, self.reserves, self.record = call, cancel, reserves, record

    def progress(self, fraction: float, message: str = "") -> None:
        """Progress bar and status; raises :class:`JobCancelled` once cancel was asked (the
        job stops at its next progress report)."""
        if self.cancel.is_set():
            raise JobCancelled(f"{self.title}: cancelled")
        frac = float(min(1.0, max(0.0, fraction if math.isfinite(fraction) else 0.0)))
        update(self.record, state="running", fraction=frac, message=message)

        def apply():
            self.state.progress = frac
            self.state.set_status(f"{self.title}: {message}" if message else f"{self.title}: {frac:.0%}",
                                  "info")
        self.call(apply)

    def run(self) -> None:
        """Wait for a slot, run the work as the session's user, report the outcome."""
        if not _JOB_SLOTS.acquire(blocking=False):
            self.call(lambda: self.state.set_status(
                f"{self.title}: queued — {MAX_JOBS} job(s) of this server are running; it starts "
                "when one has finished", "info"))
            _JOB_SLOTS.acquire()
        update(self.record, state="running", started=time.time())
        try:
            if self.cancel.is_set():
                raise JobCancelled(f"{self.title}: cancelled before it started")
            with acting_as(self.state.principal.username):
                result = self.work(self.progress)
        except JobCancelled as exc:
            update(self.record, state="cancelled", message=str(exc))
            self.call(lambda msg=str(exc): self._ended(msg, "warning"))
            return
        except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
            detail = plain_message(exc, self.title)
            update(self.record, state="failed", error=detail)
            self.call(lambda: self._ended(f"{self.title} failed: {detail}", "error"))
            return
        finally:
            _JOB_SLOTS.release()
            if self.reserves is not None:
                release_name(*self.reserves)
        update(self.record, state="done", fraction=1.0, message="done")
        self.call(lambda: self._done(result))

    def _ended(self, message: str, level: str) -> None:
        self.state.busy = False
        self.state.set_status(message, level)

    def _done(self, result: Any) -> None:
        self.state.busy = False
        self.state.progress = 1.0
        self.state.set_status(f"{self.title}: done", "success")
        if self.on_done is None:
            return
        try:
            self.on_done(result)
        except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
            self.state.set_status(f"{self.title}: finished but showing the result failed: "
                                  f"{plain_message(exc, self.title)}", "error")


class JobRunner:
    """Runs the background jobs of one session's state (``busy``, ``progress``,
    ``set_status``, ``guard``, ``principal`` and the configuration selector of
    :class:`~railval.app.state.app.AppState`)."""

    def __init__(self, state: Any):
        self.state = state
        self.thread: threading.Thread | None = None
        self._cancel: threading.Event | None = None

    def submit(self, title: str, work: Callable[[Callable[[float, str], None]], Any],
               on_done: Callable[[Any], None] | None = None, dispatch: Dispatch | None = None,
               background: bool = True, action: str | None = None,
               reserves: tuple[str, str] | None = None) -> threading.Thread | None:
        """Run ``work(progress)`` (see :meth:`AppState.run_job`); the thread, or None when the
        job was refused or ran in the caller's thread (``background=False``)."""
        if not self._admit(title, action, reserves):
            return None
        cancel = self._cancel = threading.Event()
        self.state.busy = True
        self.state.progress = 0.0
        self.state.set_status(f"{title}: started", "info")
        job = _Job(self.state, title, work, on_done, dispatch or _direct, cancel, reserves,
                   track(self.state.principal.username, self._label(title, reserves),
                         self._link(reserves)))
        if not background:
            job.run()
            return None
        self.thread = threading.Thread(target=job.run, name=f"railval-job-{title}", daemon=True)
        self.thread.start()
        return self.thread

    def _label(self, title: str, reserves: tuple[str, str] | None) -> str:
        """The job as the user's job list names it: ``diagnosis of baseline (demo)``."""
        st = self.state
        conf = reserves[1] if reserves is not None else getattr(st, "configuration", None)
        camp = getattr(st, "campaign", None)
        return f"{title} of {conf} ({camp})" if conf and camp else title

    def _link(self, reserves: tuple[str, str] | None) -> str:
        """Where the job's result is shown: the page it was started on, with its campaign and
        its configuration (the one the job stores, when it stores one) selected."""
        st = self.state
        page = getattr(st, "page", None) or "overview"
        conf = reserves[1] if reserves is not None else getattr(st, "configuration", None)
        return app_link(page, campaign=getattr(st, "campaign", None), configuration=conf)

    def _admit(self, title: str, action: str | None, reserves: tuple[str, str] | None) -> bool:
        """False (with the reason in the status area) when the user may not do ``action``,
        a job of this session runs, or the configuration name is taken or reserved."""
        state = self.state
        if action is not None and not state.guard(action):
            return False
        if state.busy:
            state.set_status(f"{title}: another job is still running — wait for it to finish", "warning")
            return False
        if reserves is None:
            return True
        if reserves[1] in (state.param.configuration.objects or []):
            state.set_status(f"{title} refused: configuration {reserves[1]!r} already exists in "
                             f"{reserves[0]!r} — choose another name", "error")
            return False
        if not reserve_name(*reserves):
            state.set_status(f"{title} refused: another job is already computing configuration "
                             f"{reserves[1]!r} in {reserves[0]!r} — choose another name", "error")
            return False
        return True

    def cancel(self) -> bool:
        """Ask the running job to stop; False when none runs."""
        if self.state.busy and self._cancel is not None:
            self._cancel.set()
            return True
        return False

    def wait(self, timeout: float | None = None) -> None:
        if self.thread is not None:
            self.thread.join(timeout)
