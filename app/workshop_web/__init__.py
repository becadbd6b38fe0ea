"""Workshop pages served by ``railval serve`` next to the Panel app (docs/workshops.md).

Plain Tornado request handlers, not Panel sessions: a reviewer's page is one static HTML
page with a few lines of JavaScript that fetches a PNG and posts each answer as JSON. With
50 reviewers at once this costs the server one short request per answer instead of 50
live Bokeh documents and websockets, keeps no per-reviewer state in server memory (a
restart loses nothing: every answer is in the database the moment the server confirms
it), and serves each plot's stored bytes verbatim.

Routes
------
Reviewer (the personal link is the credential; only its SHA-256 is stored):

* ``GET  /review/{token}``            the review page
* ``GET  /review/{token}/state``      own sequence length, own answers, next unanswered place
* ``GET  /review/{token}/image/{i}``  the PNG at place ``i`` of the own sequence
* ``POST /review/{token}/answer``     ``{position, answer: yes|no, comment, seconds, submission}``
* ``POST /review/{token}/finish``

Organiser (signed-in user with ``workshop.run``; analysis needs ``workshop.results``):

* ``/workshops`` list, ``/workshops/new`` create form (count before creating),
  ``/workshops/{name}`` progress, links, close/reopen, ``/workshops/{name}/analysis``,
  ``/workshops/login``, ``/workshops/logout`` (served with the app: redirects to the app's
  ``/login`` and ``/logout`` — one sign-in). Creating a workshop is a job of the organiser:
  ``/workshops/{name}`` shows its progress until it is stored (``/workshops/{name}/creation``,
  JSON) and the list shows it "being created, n of N".

Panelist (signed in, ``workshop.answer``): ``/workshops/mine`` lists the own workshops;
``POST /workshops/mine/{name}/open`` issues a fresh personal link and opens it.
Every signed-in user: ``/workshops/mine/jobs`` (JSON) lists the own running and recently
finished jobs (workshop creations, the app's diagnoses and calibrations).

Every page carries the app's one navigation (:mod:`railval.app.navigation`) and every
``POST`` (forms and the reviewer's JSON answers) the anti-forgery token
(:func:`railval.app.security.with_xsrf`; Tornado ``xsrf_cookies``).

Roles come from :mod:`railval.core.roles` and are checked on every request. Served with the
app, the app's sign-in cookie identifies the user; on their own (no ``auth``) the pages keep
a sign-in of their own: :func:`railval.db.users.authenticate` (argon2id, rate-limited,
audited) and an HMAC-signed cookie (secret ``$RAILVAL_COOKIE_SECRET`` or a random one per
server process). Open
single-user mode (no user can sign in because none has a password, request from the
loopback interface without proxy headers) acts as :func:`railval.core.roles.open_principal`.
All user text is escaped.

Modules: ``common`` (page frame, sign-in, base handlers), ``reviewer``, ``organiser``,
``analysis``; :func:`routes` joins them.
"""

from __future__ import annotations

from tornado.web import RedirectHandler

from railval.app.workshop_web.analysis import (
    WorkshopAnalysis,
    WorkshopPlotImage,
    analysis_html,
    threshold_png,
)
from railval.app.workshop_web.common import Login, Logout
from railval.app.workshop_web.organiser import (
    MyJobs,
    MyWorkshops,
    WorkshopCreation,
    WorkshopList,
    WorkshopNew,
    WorkshopPage,
    WorkshopPlan,
    WorkshopScalingPreview,
    WorkshopStatus,
)
from railval.app.workshop_web.reviewer import (
    ReviewAnswer,
    ReviewFinish,
    ReviewImage,
    ReviewPage,
    ReviewState,
    clear_contexts,
)

__all__ = ["analysis_html", "clear_contexts", "routes", "threshold_png"]


def routes(database, auth=None) -> list[tuple]:
    """Tornado URL patterns of the workshop pages (``pn.serve(extra_patterns=…)``);
    ``auth``: the app's sign-in, whose session the organiser pages accept."""
    kw = {"database": database, "auth": auth}
    tok = r"([A-Za-z0-9_\-]{20,100})"
    name = r"([^/]+)"
    sign_in = ([(r"/workshops/login", Login, kw), (r"/workshops/logout", Logout, kw)]
               if auth is None else  # one sign-in for the whole app: the app's pages
               [(r"/workshops/login", _ToAppLogin), (r"/workshops/logout", RedirectHandler,
                                                     {"url": "/logout"})])
    return [
        (rf"/review/{tok}/?", ReviewPage, kw),
        (rf"/review/{tok}/state", ReviewState, kw),
        (rf"/review/{tok}/image/(\d+)", ReviewImage, kw),
        (rf"/review/{tok}/answer", ReviewAnswer, kw),
        (rf"/review/{tok}/finish", ReviewFinish, kw),
        *sign_in,
        (r"/workshops/?", WorkshopList, kw),
        (r"/workshops/mine", MyWorkshops, kw),
        (r"/workshops/mine/jobs", MyJobs, kw),
        (rf"/workshops/mine/{name}/open", MyWorkshops, kw),
        (r"/workshops/new", WorkshopNew, kw),
        (r"/workshops/plan", WorkshopPlan, kw),
        (r"/workshops/scaling-preview", WorkshopScalingPreview, kw),
        (rf"/workshops/{name}/status", _StatusOrPost, kw),
        (rf"/workshops/{name}/invite", _InvitePost, kw),
        (rf"/workshops/{name}/analysis", WorkshopAnalysis, kw),
        (rf"/workshops/{name}/creation", WorkshopCreation, kw),
        (rf"/workshops/{name}/plot/(\d+)", WorkshopPlotImage, kw),
        (rf"/workshops/{name}", WorkshopPage, kw),
    ]


class _StatusOrPost(WorkshopStatus):
    async def post(self, name: str) -> None:
        await WorkshopPage.post(self, name, "status")


class _InvitePost(WorkshopPage):
    async def post(self, name: str) -> None:  # type: ignore[override]
        await WorkshopPage.post(self, name, "invite")


class _ToAppLogin(RedirectHandler):
    """``/workshops/login?next=…`` → the app's ``/login?next=…`` (one sign-in)."""

    def initialize(self) -> None:  # type: ignore[override]
        super().initialize(url="/login{0}")

    def get(self, *args: str) -> None:
        query = self.request.query
        self.redirect(f"/login{'?' + query if query else ''}")
