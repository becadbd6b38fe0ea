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
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Callable
from typing import Any

from railval.app.security import plain_message
from railval.app.services.overview import acting_as
from railval.core.errors import RailvalError

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


def _direct(fn: Callable[[], None]) -> None:
    fn()


class _Job:
    """One submitted job: its progress callback and its run (slot, work, outcome)."""

    def __init__(self, state: Any, title: str, work: Callable, on_done: Callable | None,
                 call: Dispatch, cancel: threading.Event, reserves: tuple[str, str] | None):
        self.state, self.title, self.work, self.on_done = state, title, work, on_done
        self.call, self.cancel, self.reserves = call, cancel, reserves

    def progress(self, fraction: float, message: str = "") -> None:
        """Progress bar and status; raises :class:`JobCancelled` once cancel was asked (the
        job stops at its next progress report)."""
        if self.cancel.is_set():
            raise JobCancelled(f"{self.title}: cancelled")
        frac = float(min(1.0, max(0.0, fraction if math.isfinite(fraction) else 0.0)))

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
        try:
            if self.cancel.is_set():
                raise JobCancelled(f"{self.title}: cancelled before it started")
            with acting_as(self.state.principal.username):
                result = self.work(self.progress)
        except JobCancelled as exc:
            self.call(lambda msg=str(exc): self._ended(msg, "warning"))
            return
        except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
            detail = plain_message(exc, self.title)
            self.call(lambda: self._ended(f"{self.title} failed: {detail}", "error"))
            return
        finally:
            _JOB_SLOTS.release()
            if self.reserves is not None:
                release_name(*self.reserves)
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
        job = _Job(self.state, title, work, on_done, dispatch or _direct, cancel, reserves)
        if not background:
            job.run()
            return None
        self.thread = threading.Thread(target=job.run, name=f"railval-job-{title}", daemon=True)
        self.thread.start()
        return self.thread

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
