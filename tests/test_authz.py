"""Role × action matrix on the server side: pages, widget callbacks and jobs, downloads, CLI.

The expected matrix is written out here, independently of the registry
(:mod:`railval.core.roles`), so a change of the registry that widens a role fails a test.
The pages in the real served app are checked in a browser by ``test_browser_auth``.
"""

from __future__ import annotations

import argparse

import pytest

from railval.app.cli import authorize, build_parser, main
from railval.app.main import DeniedPage, Pages
from railval.app.state import AppState, Backend
from railval.core.roles import (
    ACTIONS,
    CLI_ACTIONS,
    PAGE_ACTIONS,
    PERMISSIONS,
    ROLES,
    PermissionDenied,
    Principal,
)
from railval.db import audit, users
from railval.db.importer import import_campaign
from tests.factories import write_demo_campaign

READ = {"overview", "compare", "dashboard", "metrics", "diagnose", "report", "signoff"}
#: role → pages it may open
PAGES_OF = {
    "admin": READ | {"audit"},
    "organiser": READ,
    "engineer": READ | {"import"},
    "panelist": set(),
    "reviewer": READ,
    "assessor": READ | {"audit"},
}
#: callback / job → roles that may run it
CALLBACKS = {
    "diagnose": {"engineer"},
    "calibrate": {"engineer"},
    "simulate": {"engineer"},
    "report.download": {"admin", "organiser", "engineer", "reviewer", "assessor"},
    "data.read": {"admin", "organiser", "engineer", "reviewer", "assessor"},
    "workshop.results": {"organiser", "reviewer", "assessor"},
    "signoff.create": {"reviewer"},
    "audit.read": {"admin", "assessor"},
    "data.import": {"engineer"},
    "data.delete": {"engineer"},
    "user.manage": {"admin"},
    "workshop.run": {"organiser"},
    "workshop.answer": {"panelist"},
}


def test_registry_matches_the_written_matrix():
    for action, roles in CALLBACKS.items():
        assert {r for r in ROLES if action in PERMISSIONS[r]} == roles, action
    assert not PERMISSIONS["assessor"] & {"data.import", "data.delete", "simulate", "diagnose",
                                          "calibrate", "validate", "signoff.create",
                                          "user.manage", "workshop.run", "workshop.answer"}
    for role, pages in PAGES_OF.items():
        assert {p for p, a in PAGE_ACTIONS.items() if a in PERMISSIONS[role]} == pages, role


def test_every_cli_verb_is_in_the_registry():
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    verbs = set()
    for name, p in sub.choices.items():
        inner = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        verbs |= {f"{name} {s}" for s in inner[0].choices} if inner else {name}
    assert verbs == set(CLI_ACTIONS)
    assert all(a is None or a in ACTIONS for a in CLI_ACTIONS.values())


@pytest.fixture(scope="module")
def demo_db(tmp_path_factory):
    from railval.db.engine import connect

    root = tmp_path_factory.mktemp("authz")
    write_demo_campaign(root / "demo", n_sections=12, fs=100.0, n_configs=2)
    db = connect(f"sqlite:///{root / 'authz.db'}")
    db.init()
    import_campaign(db, root / "demo")
    with db.session(write=True) as s:
        for role in ROLES:
            users.create_user(s, f"u_{role}", password=f"{role} password", roles=[role])
    yield db
    db.dispose()


def principal(role: str) -> Principal:
    return Principal(f"u_{role}", frozenset({role}))


@pytest.mark.parametrize("role", list(ROLES))
def test_pages_are_built_only_for_permitted_roles(demo_db, role):
    app = AppState(Backend(demo_db), principal=principal(role))
    assert set(app.pages_allowed()) == PAGES_OF[role]
    if PAGES_OF[role]:  # the first page shown is one the role may open
        assert app.page in PAGES_OF[role]
    pages = Pages(app)
    for name in PAGE_ACTIONS:
        view = pages[name]
        assert isinstance(view, DeniedPage) == (name not in PAGES_OF[role]), name
        if isinstance(view, DeniedPage):
            text = view.view[1].object
            assert text.startswith("Not allowed: u_") and "may not" in text


class _Stub:
    """Stands in for the expensive backend jobs: records what ran."""

    def __init__(self):
        self.ran: list[str] = []

    def __call__(self, name):
        def run(*args, **kwargs):
            self.ran.append(name)
            return {}
        return run


@pytest.mark.parametrize("role", list(ROLES))
def test_callbacks_and_jobs_are_checked_on_the_server(demo_db, role, monkeypatch):
    from railval.app.pages.audit import AuditPage
    from railval.app.pages.report import ReportPage
    from railval.app.pages.signoff import SignoffPage
    from railval.app.state.diagnose import DiagnoseState

    app = AppState(Backend(demo_db), principal=principal(role))
    stub = _Stub()
    for name in ("diagnose", "calibrate", "simulate"):
        monkeypatch.setattr(app.backend, name, stub(name))
    # "Run diagnosis" runs the diagnosis and lists the stored runs in one call (names resolved once)
    monkeypatch.setattr(app.backend, "diagnose_and_list", stub("diagnose"))
    d = DiagnoseState(app)
    d.effect = d.param.effect.objects[0] if d.param.effect.objects else "yaw_damper_degraded"
    outcomes = {}
    for action, run in (("diagnose", lambda: d.run_diagnosis(background=False)),
                        ("calibrate", lambda: d.run_calibration(background=False)),
                        ("simulate", lambda: d.run_calibration(background=False, calibrate=False))):
        app.set_status("")
        run()
        outcomes[action] = action in stub.ran
        if not outcomes[action]:
            assert app.status_level == "error" and app.status.startswith("Not allowed:"), app.status
    assert {a for a, ok in outcomes.items() if ok} == {a for a in outcomes if role in CALLBACKS[a]}
    # downloads: the callback itself refuses (a browser can call it without the button)
    rep = ReportPage.__new__(ReportPage)
    rep.app, rep._report = app, type("R", (), {"html": "<p>report</p>"})()
    body = rep._html_bytes().read().decode()
    assert (body == "<p>report</p>") == (role in CALLBACKS["report.download"]), body
    aud = AuditPage.__new__(AuditPage)
    aud.app = app
    body = aud._html_bytes().read().decode()
    assert ("Audit report" in body) == (role in CALLBACKS["audit.read"])
    if role not in CALLBACKS["audit.read"]:
        assert body.startswith("Not allowed:")
    so = SignoffPage(app)
    app.set_status("")
    monkeypatch.setattr("railval.app.services.signoff.sign", stub("sign"))
    # a complete form (the page has no default decision), so only the role decides
    so.decision.value = "not-validated"
    so.justification.value = "held-out sections show the lateral error"
    so.sign(background=False)
    assert ("sign" in stub.ran) == (role in CALLBACKS["signoff.create"])
    with demo_db.session() as s:  # no job of a denied role wrote anything
        assert not [r for r in audit.iter_rows(s) if r["actor"] == f"u_{role}"]


def _cli_args(url: str, verb: str, who: str) -> argparse.Namespace:
    v, _, sub = verb.partition(" ")
    return argparse.Namespace(verb=v, subverb=sub or None, db=url, as_user=who, bundle=None)


@pytest.mark.parametrize("role", list(ROLES))
def test_cli_verbs_check_the_acting_users_role(demo_db, role):
    for verb, action in CLI_ACTIONS.items():
        args = _cli_args(demo_db.url, verb, f"u_{role}")
        if action is None or action in PERMISSIONS[role]:
            authorize(args)
        else:
            with pytest.raises(PermissionDenied, match=f"u_{role} \\({role}\\) may not"):
                authorize(args)


def test_cli_end_to_end_refusals(demo_db, capsys, tmp_path, monkeypatch):
    monkeypatch.delenv("RAILVAL_USER", raising=False)
    url = demo_db.url
    assert main(["--db", url, "list"]) == 2
    assert "this database has users: name the user you act as" in capsys.readouterr().err
    assert main(["--db", url, "--as", "nobody", "list"]) == 2
    assert "no such user" in capsys.readouterr().err
    assert main(["--db", url, "--as", "u_panelist", "list"]) == 2
    assert "may not see campaigns" in capsys.readouterr().err
    assert main(["--db", url, "--as", "u_assessor", "list"]) == 0
    capsys.readouterr()
    assert main(["--db", url, "--as", "u_assessor", "user", "role", "u_engineer", "admin"]) == 2
    assert "may not add users" in capsys.readouterr().err
    assert main(["--db", url, "--as", "u_assessor", "audit", "checkpoint",
                 str(tmp_path / "cp.json")]) == 0
    assert main(["--db", url, "--as", "u_engineer", "audit", "checkpoint",
                 str(tmp_path / "cp2.json")]) == 2
    assert not (tmp_path / "cp2.json").exists()
    with demo_db.session() as s:
        assert users.get_user(s, "u_engineer").role_names == ["engineer"]
