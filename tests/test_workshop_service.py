"""Review workshops end to end below the browser: creation (plot set, one scaling per kind,
deterministic images with stored SHA-256), answers (idempotent), CSV import (bad input
leaves nothing stored) and export, analysis, the CLI contracts."""

from __future__ import annotations

import csv
import hashlib
import json

import pytest
from railval.app.cli import main as cli
from railval.app.services import workshop_cards
from railval.app.services import workshop_answers as wa
from railval.app.services import workshops as ws
from railval.core.errors import InvalidParameter
from railval.core.workshop import PLOT_KINDS
from railval.db import repo
from railval.db import workshops as wsdb
from railval.db.models import AppUser, WorkshopAnswer, WorkshopReviewer
from sqlalchemy import func, select

KINDS = ["Y_time", "ay_cb_time", "ay_cb_psd"]


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """A demo database with one workshop (2 sections × 2 configurations × 3 kinds, a share
    with automatic scaling)."""
    from tests.browser_support import demo_database

    folder = tmp_path_factory.mktemp("ws")
    db = demo_database(folder, n_configs=2)
    summary = ws.create(db, "W", "demo", sections=["S01", "S05"], kinds=KINDS, repeats=0.2,
                        auto_share=0.25, seed=3)
    from railval.db import users

    with db.session(write=True) as s:  # the CLI's acting user once the database has users
        users.create_user(s, "orga", password="organiser-pass", roles=["organiser"])
        users.create_user(s, "revx", roles=["panelist"])
    yield db, summary, folder
    db.dispose()


def _count(db, model) -> int:
    with db.session() as s:
        return s.scalar(select(func.count()).select_from(model))


def test_plan_counts_before_creating(made):
    db, summary, _ = made
    with db.session() as s:
        planned = ws.plan(s, "demo", None, ["S01", "S05"], KINDS)
        assert len(planned) == summary["fixed_plots"] == 2 * 2 * (2 + 2 + 2)
        with pytest.raises(InvalidParameter, match="unknown plot kind"):
            ws.plan(s, "demo", None, None, ["Y_time", "wobble"])
        with pytest.raises(InvalidParameter, match="unknown section"):
            ws.plan(s, "demo", None, ["S99"], None)


def test_plots_contract_and_one_scaling_per_kind(made):
    db, _, _ = made
    with db.session() as s:
        doc = ws.plots_document(s, "W")
        w = wsdb.get_workshop(s, "W")
        rows = wsdb.plots(s, w)
        for p in doc["plots"]:
            assert {"id", "kind", "section", "configuration", "channel", "deviation",
                    "image_sha256"} <= set(p)
            img, sha = wsdb.plot_image(s, w.id, p["id"])
            assert hashlib.sha256(img).hexdigest() == sha == p["image_sha256"]
            assert img[:8] == b"\x89PNG\r\n\x1a\n"
        fixed = [r for r in rows if r.scaling == "fixed"]
        auto = [r for r in rows if r.scaling == "auto"]
        assert len(auto) == round(0.25 * len(fixed)) and all(a.twin_id for a in auto)
        assert w.settings["scaling"] == "zone" == ws.workshop_scaling(w.settings)
        zones = {sec.id: sec.zone for sec in repo.section_infos(s, w.campaign)}
        for kind in KINDS:
            for zone in {zones[r.section] for r in fixed if r.kind == kind}:
                group = [r for r in fixed if r.kind == kind and zones[r.section] == zone]
                scales = {json.dumps(r.render["scale"], sort_keys=True) for r in group}
                assert len(scales) == 1, (kind, zone)       # one range per kind within a zone
                assert {r.render["scale_key"] for r in group} == {f"{kind} zone {zone}"}
                assert json.loads(scales.pop()) == w.scales[f"{kind} zone {zone}"]
            styles = {json.dumps(r.render["style"], sort_keys=True) for r in rows if r.kind == kind}
            assert len(styles) == 1
        # objective values: EN signals have a deviation, PSDs take their signal's
        by = {(r.kind, r.section, r.configuration, r.channel.split("_")[-1]): r for r in fixed}
        for (kind, sec, cfg, pos), r in by.items():
            assert r.deviation is not None and r.deviation >= 0
            if kind == "ay_cb_psd":
                assert r.deviation == by[("ay_cb_time", sec, cfg, pos)].deviation
            if kind.endswith("_time"):
                assert r.sg_c is not None and r.sg_c >= 0


def test_zone_scaling_keeps_straight_track_readable(made, capsys, tmp_path):
    """The two consistent scalings on the same plots (S01 straight track, zone 1; S04 a
    300 m curve, zone 4): by zone, each kind's range covers only its zone's plots, so fewer
    plots are flat lines than with one range over the whole workshop; the preview and
    ``create --json`` agree; a workshop made before the choice reads as ``workshop``."""
    from railval.core.workshop import FLAT_SPAN, Extent, is_flat, nice_range, span_share

    db, summary, _ = made
    assert summary["scaling"] == "zone" and set(summary["flat_share"]) == set(KINDS)
    kinds = ["Y_time", "ay_cb_time"]
    preview = ws.scaling_preview(db, "demo", ["baseline"], ["S01", "S04"], kinds)
    assert preview["plots"] == 2 * (2 + 2) and preview["default"] == "zone"
    zone, whole = preview["scalings"]["zone"], preview["scalings"]["workshop"]
    assert {(r["kind"], r["zone"]) for r in zone["ranges"]} == {(k, z) for k in kinds for z in (1, 4)}
    assert {(r["kind"], r["zone"]) for r in whole["ranges"]} == {(k, None) for k in kinds}
    for r in zone["ranges"]:                 # a zone's range lies inside the workshop's
        w_r = next(x for x in whole["ranges"] if x["kind"] == r["kind"])
        assert w_r["y"][0] <= r["y"][0] and r["y"][1] <= w_r["y"][1] and r["plots"] == 2
    assert all(zone["flat_share"][k] <= whole["flat_share"][k] for k in kinds)
    # guiding force on straight track (±3 kN) is lost in the range a tight curve needs (±60 kN)
    import numpy as np
    from railval.core.types import SectionInfo

    x = np.linspace(0.0, 1000.0, 2001)
    infos = {"S": SectionInfo("S", 0.0, 0.0, 160.0, 1, 0.0, 1000.0),
             "T": SectionInfo("T", 300.0, 150.0, 75.0, 4, 0.0, 1000.0)}
    sig = {"S": 3.0 * np.sin(x / 50.0), "T": 58.0 * np.sin(x / 300.0)}
    facts = [{"kind": "Y_time", "section": sec} for sec in ("S", "T")]
    curves = [(ws._Curve(x, sig[sec]), ws._Curve(x, 0.9 * sig[sec])) for sec in ("S", "T")]
    for scaling, flat in (("workshop", 0.5), ("zone", 0.0)):
        keys, scales, groups = ws._scaled(facts, curves, infos, scaling)
        assert ws.flat_share(groups) == {"Y_time": flat}
    assert keys == ["Y_time zone 1", "Y_time zone 4"] and scales["Y_time zone 1"].y.hi == 4.0
    # the flat test by hand: −60…60 kN rounds to −75…75 (step 25); ±2 kN spans 4/150 < 10 %,
    # ±8 kN 16/150 > 10 %
    y = nice_range(-60, 60)
    assert (y.lo, y.hi) == (-75.0, 75.0)
    assert span_share(Extent(0, 1, -2, 2), y) == pytest.approx(4 / 150)
    assert is_flat(Extent(0, 1, -2, 2), y) and not is_flat(Extent(0, 1, -8, 8), y)
    assert FLAT_SPAN == 0.1
    capsys.readouterr()
    for name, extra, expect in (("WZ", [], "zone"), ("WW", ["--scaling", "workshop"], "workshop")):
        assert cli(["--db", db.url, "--as", "orga", "workshop", "create", name, "--campaign", "demo",
                    "--configurations", "baseline", "--sections", "S01", "S04", "--kinds", *kinds,
                    "--repeats", "0", *extra, "--json"]) == 0
        out = json.loads(capsys.readouterr().out)
        assert out["scaling"] == expect and out["flat_share"] == preview["scalings"][expect]["flat_share"]
    assert cli(["--db", db.url, "--as", "orga", "workshop", "create", "WX", "--campaign", "demo",
                "--scaling", "lane"]) == 2
    assert "scaling must be one of zone, workshop" in capsys.readouterr().err
    assert cli(["--db", db.url, "--as", "orga", "workshop", "create", "WX", "--campaign", "demo",
                "--twin-scaling", "zone"]) == 2
    assert "--twin-scaling must be auto or the scaling other than 'zone'" in capsys.readouterr().err
    # the presentation experiment pairs the two scalings on the same plot
    assert cli(["--db", db.url, "--as", "orga", "workshop", "create", "WT", "--campaign", "demo",
                "--configurations", "baseline", "--sections", "S01", "S04", "--kinds", *kinds,
                "--repeats", "0", "--auto-share", "0.5", "--twin-scaling", "workshop", "--json"]) == 0
    capsys.readouterr()
    with db.session() as s:
        whole_scales = wsdb.get_workshop(s, "WW").scales
        rows = wsdb.plots(s, wsdb.get_workshop(s, "WT"))
        twins = [r for r in rows if r.scaling == "workshop"]
        assert len(twins) == 4 and all(r.twin_id for r in twins)
        for r in twins:
            assert r.render["scale"] == whole_scales[r.kind] and r.render["scale_key"] == r.kind
        answers = [("tw", r.id, "yes", 2, "") for r in rows]
    wa.import_answers(db, "WT", _write(tmp_path / "wt.csv", answers))
    with db.session() as s:
        frame, _ = wa.analysis_frames(s, "WT")
    assert sorted(frame["scaling"].unique()) == ["auto", "fixed"]
    assert set(frame.loc[frame["scaling"] == "auto", "plot"]) == {r.twin_id for r in twins}
    assert wa.analyse(db, "WT")["scaling_effect"]["pairs"] == 4
    with db.session() as s:
        w = wsdb.get_workshop(s, "WW")
        assert set(w.scales) == set(kinds) and w.settings["scaling"] == "workshop"
        assert set(wsdb.get_workshop(s, "WZ").scales) == {f"{k} zone {z}" for k in kinds for z in (1, 4)}
        assert ws.workshop_scaling({k: v for k, v in w.settings.items() if k != "scaling"}) == "workshop"
        assert "WX" not in {x.name for x in wsdb.list_workshops(s)}
        assert ws.status_document(s, "WW")["scaling"] == "workshop"
        assert ws.status_document(s, "WZ")["scaling"] == "zone"


def test_rendering_is_deterministic(made):
    import numpy as np
    from railval.app.services.workshop_canvas import render_png
    from railval.core.workshop import Extent, kind_scale

    x = np.linspace(0, 100, 500)
    y = np.sin(x / 7)
    sc = kind_scale("time", [Extent(0, 100, -1, 1)])
    a = render_png(x, y, x, 0.9 * y, sc, title="t", x_label="x", y_label="y")
    b = render_png(x, y, x, 0.9 * y, sc, title="t", x_label="x", y_label="y")
    assert a == b and b"Software" not in a and b"Creation" not in a


def test_answers_are_idempotent_and_refused_when_closed(made):
    db, _, _ = made
    with db.session(write=True) as s:
        w = wsdb.get_workshop(s, "W")
        wsdb.invite(s, w, "idem", seed=5)
    with db.session(write=True) as s:
        r = s.scalar(select(WorkshopReviewer).join(AppUser).where(AppUser.username == "idem"))
        token = wsdb.invite(s, wsdb.get_workshop(s, "W"), "idem")
    with db.session(write=True) as s:
        ctx = wsdb.reviewer_by_token(s, token)
        assert ctx.reviewer_id == r.id and len(ctx.sequence) > 0
        assert wsdb.record_answer(s, ctx, 0, True, seconds=3.0, submission="a1") == "new"
        assert wsdb.record_answer(s, ctx, 0, True, seconds=3.0, submission="a1") == "repeated"
        assert wsdb.record_answer(s, ctx, 0, False, seconds=2.0, submission="a2") == "changed"
        with pytest.raises(InvalidParameter, match="outside"):
            wsdb.record_answer(s, ctx, 10_000, True, seconds=1.0)
    with db.session(write=True) as s:
        a = s.scalars(select(WorkshopAnswer).where(WorkshopAnswer.reviewer_id == r.id)).all()
        assert len(a) == 1 and a[0].answer is False and a[0].seconds == 5.0 and a[0].changes == 1
        wsdb.set_status(s, wsdb.get_workshop(s, "W"), "closed")
    with db.session(write=True) as s:
        ctx = wsdb.reviewer_by_token(s, token)
        with pytest.raises(wsdb.WorkshopClosed):
            wsdb.record_answer(s, ctx, 1, True, seconds=1.0)
        wsdb.set_status(s, wsdb.get_workshop(s, "W"), "open")
    with db.session() as s:
        assert wsdb.reviewer_by_token(s, "not-a-token-" + "x" * 30) is None


def _write(path, rows, header=("reviewer", "plot", "answer", "seconds", "comment")):
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return path


@pytest.mark.parametrize(("rows", "message"), [
    ([("imp1", "{p0}", "yes", "3", ""), ("imp1", "999999", "no", "2", "")],
     r"line 3, column plot: plot 999999 is not part of workshop"),
    ([("imp1", "{p0}", "yes", "3", ""), ("imp1", "{p1}", "maybe", "2", "")],
     r"line 3, column answer: 'maybe'; answer must be yes or no"),
    ([("imp1", "{p0}", "yes", "3", ""), ("imp2", "{p1}", "no", "2", ""), ("imp1", "{p0}", "no", "1", "")],
     r"line 4, column plot: duplicate row .* already on line 2"),
    ([("imp1", "{p0}", "yes", "-3", "")], r"line 2, column seconds"),
    ([("imp1", "abc", "yes", "3", "")], r"line 2, column plot: 'abc' is not a plot id"),
    ([("", "{p0}", "yes", "3", "")], r"line 2, column reviewer: empty"),
    ([("bad name!", "{p0}", "yes", "3", "")], r"line 2, column reviewer: .*user name"),
])
def test_import_bad_rows_store_nothing(made, tmp_path, rows, message):
    db, _, _ = made
    with db.session() as s:
        ids = [p.id for p in wsdb.plots(s, wsdb.get_workshop(s, "W"))]
    rows = [tuple(c.format(p0=ids[0], p1=ids[1]) for c in r) for r in rows]
    path = _write(tmp_path / "answers.csv", rows)
    before = (_count(db, WorkshopAnswer), _count(db, WorkshopReviewer), _count(db, AppUser))
    with pytest.raises(InvalidParameter, match=message):
        wa.import_answers(db, "W", path)
    assert (_count(db, WorkshopAnswer), _count(db, WorkshopReviewer), _count(db, AppUser)) == before


def test_import_bad_header_and_cli_error(made, tmp_path, capsys):
    db, _, _ = made
    path = _write(tmp_path / "a.csv", [("x", "1", "yes", "1")], header=("reviewer", "plot", "answer", "seconds"))
    with pytest.raises(InvalidParameter, match="line 1: missing column"):
        wa.import_answers(db, "W", path)
    assert cli(["--db", db.url, "--as", "orga", "workshop", "import-answers", "W", str(path)]) == 2
    assert "missing column(s) comment" in capsys.readouterr().err


def test_import_export_and_analyse_round_trip(made, tmp_path, capsys):
    db, _, _ = made
    from railval.core.review import simulate_answers  # noqa: F401 - the statistics core is present

    with db.session() as s:
        plots = [p for p in wsdb.plots(s, wsdb.get_workshop(s, "W")) if p.scaling == "fixed"]
    rows = []
    for i, name in enumerate(["paper1", "paper2", "paper3", "paper4"]):
        for p in plots:
            yes = (p.deviation or 0) < 0.3 + 0.3 * i
            rows.append((name, str(p.id), "yes" if yes else "no", f"{4 + i}", "on paper, \"quoted\""))
    path = _write(tmp_path / "paper.csv", rows)
    before_users = _count(db, AppUser)
    out = wa.import_answers(db, "W", path)
    assert out == {"answers": len(rows), "reviewers": 4, "new_users": 4}
    assert _count(db, AppUser) == before_users + 4
    with db.session() as s:
        u = s.scalar(select(AppUser).where(AppUser.username == "paper1"))
        assert u.password_hash is None and u.role_names == ["panelist"]
    # importing the same file again is refused (already answered), nothing stored
    n = _count(db, WorkshopAnswer)
    with pytest.raises(InvalidParameter, match="line 2, column plot: reviewer 'paper1' has already"):
        wa.import_answers(db, "W", path)
    assert _count(db, WorkshopAnswer) == n
    exp = tmp_path / "export.csv"
    assert cli(["--db", db.url, "--as", "orga", "workshop", "export", "W", str(exp)]) == 0
    got = list(csv.DictReader(exp.open(encoding="utf-8")))
    assert set(wa.EXPORT_COLUMNS) == set(got[0])
    paper = [r for r in got if r["reviewer"].startswith("paper")]
    assert len(paper) == len(rows)
    assert {(r["reviewer"], r["plot"], r["answer"], float(r["seconds"]), r["comment"]) for r in paper} == \
        {(a, b, c, float(d), e) for a, b, c, d, e in rows}
    assert all(r["answered_at"].endswith("Z") and r["repeat"] == "false" and r["scaling"] == "fixed"
               for r in paper)
    capsys.readouterr()
    assert cli(["--db", db.url, "--as", "orga", "workshop", "analyse", "W", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert {"table1", "reviewers", "agreement", "threshold", "scaling_effect"} <= set(doc)
    assert {r["kind"] for r in doc["table1"]} == set(KINDS)
    assert {"fleiss_kappa", "krippendorff_alpha", "gwet_ac1"} <= set(doc["agreement"])
    shares = {r["reviewer"]: r["yes_share"] for r in doc["reviewers"]}
    assert shares["paper1"] <= shares["paper2"] <= shares["paper3"] <= shares["paper4"]
    assert "deviation_at_50" in doc["threshold"] and "ci" in doc["threshold"]
    assert doc["threshold"]["method"].startswith("isotonic")
    assert {"chosen", "links", "relative_spread"} <= set(doc["threshold"]["link_sensitivity"])


def test_cli_create_dry_run_plots_invite_status(made, capsys):
    db, _, _ = made
    # a reviewer may not run organiser verbs
    assert cli(["--db", db.url, "--as", "cli-rev0", "workshop", "status", "W"]) == 2
    assert "no such user" in capsys.readouterr().err
    for verb in (["analyse", "W", "--json"], ["invite", "W", "--reviewer", "x"], ["close", "W"]):
        assert cli(["--db", db.url, "--as", "revx", "workshop", *verb]) == 2
        assert "revx (panelist) may not" in capsys.readouterr().err
    assert cli(["--db", db.url, "--as", "orga", "workshop", "create", "X", "--campaign", "demo", "--sections", "S01",
                "--configurations", "baseline", "--kinds", "Y_time", "ay_bg_time", "--dry-run", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    # the demo campaign records no bogie frame channels: only the 2 Y plots (w1L, w1R)
    assert doc["plots"] == 2 and doc["by_kind"] == {"Y_time": 2} and doc["stored"] is False
    assert cli(["--db", db.url, "--as", "orga", "workshop", "plots", "W", "--json"]) == 0
    plots = json.loads(capsys.readouterr().out)["plots"]
    assert all(PLOT_KINDS[p["kind"]] for p in plots)
    assert cli(["--db", db.url, "--as", "orga", "workshop", "invite", "W", "--reviewer", "cli-rev",
                "--base-url", "http://h:1"]) == 0
    link = capsys.readouterr().out.strip()
    assert link.startswith("http://h:1/review/") and len(link) > 40
    with db.session() as s:
        ctx = wsdb.reviewer_by_token(s, link.rsplit("/", 1)[1])
        assert ctx.username == "cli-rev"
    assert cli(["--db", db.url, "--as", "orga", "workshop", "status", "W", "--json"]) == 0
    st = json.loads(capsys.readouterr().out)
    assert "cli-rev" in {r["reviewer"] for r in st["reviewers"]}
    assert cli(["--db", db.url, "--as", "orga", "workshop", "plots", "nope", "--json"]) == 2
    assert "workshop 'nope' not found" in capsys.readouterr().err


def test_plot_cards_reuse_validate_and_metrics_and_show_both_groups(made, tmp_path, capsys):
    """Cards of two workshops over the same plots (partners, experts): EN values are the
    pairs `railval validate` evaluates, Sprague–Geers the numbers of `railval metrics`,
    each card shows both groups' shares of Yes (counted here by hand from the CSVs)."""
    from railval.app.services.validation import validate_configuration

    db, _, _ = made
    for name in ("CP", "CE"):
        ws.create(db, name, "demo", configurations=["baseline"], sections=["S01", "S04"],
                  kinds=["Y_time", "YQ_time", "ay_cb_psd"], repeats=0.0)
    with db.session() as s:
        plots = {n: {(p.kind, p.section, p.channel): p.id for p in wsdb.plots(s, wsdb.get_workshop(s, n))}
                 for n in ("CP", "CE")}
    keys = sorted(plots["CP"])
    # partners: 3 reviewers, Yes on every other plot for the first; experts: 2 reviewers, all No
    part = [(f"cp{r}", plots["CP"][k], "yes" if (r + i) % 2 == 0 else "no", 5, "")
            for r in range(3) for i, k in enumerate(keys)]
    expt = [(f"ce{r}", plots["CE"][k], "no", 4, "") for r in range(2) for k in keys]
    wa.import_answers(db, "CP", _write(tmp_path / "cp.csv", part))
    wa.import_answers(db, "CE", _write(tmp_path / "ce.csv", expt))
    capsys.readouterr()
    assert cli(["--db", db.url, "--as", "orga", "workshop", "cards", "CP", "--groups", "CE", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["groups"] == ["CP", "CE"] and len(doc["cards"]) == len(keys)
    with db.write_session(deferred=True) as s:
        pairs = validate_configuration(s, "demo", "baseline", n_boot=0).pairs
    capsys.readouterr()
    assert cli(["--db", db.url, "--as", "orga", "metrics", "demo", "--config", "baseline",
                "--section", "S01", "--section", "S04", "--json"]) == 0
    metrics = {(r["section"], r["channel"]): r for r in json.loads(capsys.readouterr().out)["rows"]}
    for c in doc["cards"]:
        assert {"plot", "kind", "section", "zone", "configuration", "en", "yes_share", "answers",
                "sg", "deviation"} <= set(c)
        assert c["zone"] == {"S01": 1, "S04": 4}[c["section"]]
        i = keys.index((c["kind"], c["section"], c["channel"]))
        assert c["answers"] == 3 and c["yes_share"] == pytest.approx(sum((r + i) % 2 == 0 for r in range(3)) / 3,
                                                                    abs=1e-4)
        assert c["groups"] == [{"workshop": "CP", "yes_share": c["yes_share"], "answers": 3},
                               {"workshop": "CE", "yes_share": 0.0, "answers": 2}]
        pos = c["channel"].split("_")[-1]
        want = pairs[(pairs["section"] == c["section"]) & (pairs["position"] == pos)
                     & pairs["quantity"].isin(PLOT_KINDS[c["kind"]].quantities)]
        assert len(c["en"]) == len(want) > 0
        for e in c["en"]:
            row = want[want["quantity"] == e["quantity"]].iloc[0]
            assert (e["measured"], e["simulated"]) == (row["M"], row["S"])
            assert e["abs_diff"] == pytest.approx(row["S"] - row["M"])
            assert e["rel_diff"] == pytest.approx((row["S"] - row["M"]) / abs(row["M"]))
        if c["kind"] == "YQ_time":
            assert c["sg"] is None              # Y/Q is not a recorded channel
        else:
            chan = PLOT_KINDS[c["kind"]].channel(pos)
            m = metrics[(c["section"], chan)]
            assert c["sg"] == {"M": pytest.approx(m["sg_M"]), "P": pytest.approx(m["sg_P"]),
                               "C": pytest.approx(m["sg_C"])}
    assert cli(["--db", db.url, "--as", "orga", "workshop", "cards", "CP", "--groups", "CP"]) == 2
    assert cli(["--db", db.url, "--as", "revx", "workshop", "cards", "CP"]) == 2


def test_chosen_cards_go_into_the_validation_report(made, tmp_path, capsys):
    """`railval report --workshop W --cards …`: the chosen cards of this configuration, with
    the reviewed image bytes and their SHA-256; a card of another configuration or an
    unknown plot is refused by name and no file is written; a reviewer may not."""
    import base64
    import re

    db, _, _ = made
    with db.session() as s:
        w = wsdb.get_workshop(s, "W")
        fixed = [p for p in wsdb.plots(s, w) if p.scaling == "fixed"]
        base = [p for p in fixed if p.configuration == "baseline"][:2]
        other = next(p for p in fixed if p.configuration != "baseline")
        img = wsdb.plot_image(s, w.id, base[0].id)
    out = tmp_path / "r.html"
    assert cli(["--db", db.url, "--as", "orga", "report", "demo", "--config", "baseline", "--out", str(out),
                "--worst", "0", "--workshop", "W", "--cards", str(base[0].id), str(base[1].id)]) == 0
    html = out.read_text(encoding="utf-8")
    assert "Expert review: plot cards" in html and html.count("class='card'") == 2
    assert img[1] in html and base64.b64encode(img[0]).decode() in html
    assert re.search(r"reviewer group</th>", html)
    capsys.readouterr()
    bad = tmp_path / "bad.html"
    assert cli(["--db", db.url, "--as", "orga", "report", "demo", "--config", "baseline", "--out", str(bad),
                "--workshop", "W", "--cards", str(other.id)]) == 2
    assert f"plot {other.id} of workshop 'W' shows configuration" in capsys.readouterr().err
    assert cli(["--db", db.url, "--as", "orga", "report", "demo", "--config", "baseline", "--out", str(bad),
                "--workshop", "W", "--cards", "999999"]) == 2
    assert "plot 999999 is not a plot of workshop 'W'" in capsys.readouterr().err
    assert not bad.exists()


def test_zone_scaling_and_cards_on_each_backend(database, tmp_path):
    """SQLite and PostgreSQL: the stored scaling and per-zone ranges read back as written,
    and the cards of a workshop with answers come from the stored rows."""
    from railval.db.importer import import_campaign
    from tests.factories import write_demo_campaign

    manifest = write_demo_campaign(tmp_path / "demo", n_sections=4, n_configs=1, name="demo")
    import_campaign(database, manifest.parent)
    out = ws.create(database, "PZ", "demo", sections=["S01", "S04"], kinds=["Y_time"], repeats=0.0)
    assert out["scaling"] == "zone" and set(out["scales"]) == {"Y_time zone 1", "Y_time zone 4"}
    with database.session() as s:
        w = wsdb.get_workshop(s, "PZ")
        assert w.settings["scaling"] == "zone" and w.scales == out["scales"]
        ids = [p.id for p in wsdb.plots(s, w)]
    wa.import_answers(database, "PZ", _write(tmp_path / "a.csv", [("pg1", i, "yes", 2, "") for i in ids]))
    doc = workshop_cards.cards(database, "PZ")
    assert [c["plot"] for c in doc["cards"]] == ids
    assert all(c["yes_share"] == 1.0 and c["answers"] == 1 and c["en"] and c["sg"]["C"] is not None
               for c in doc["cards"])


def test_report_page_offers_this_configurations_cards_and_embeds_the_chosen(made):
    """The Report page's state: the choice lists only fixed plots of workshops on the
    campaign showing this configuration, to users with workshop.results; the chosen cards
    are in the built report; an engineer without workshop.results is offered none."""
    from railval.app.state import AppState, ReportState
    from railval.app.state.backend import Backend
    from railval.core.roles import Principal

    db, _, _ = made
    app = AppState(Backend(db))
    app.configuration = "baseline"
    state = ReportState(app)
    choices = state.card_choices()
    with db.session() as s:
        want = {p.id for p in wsdb.plots(s, wsdb.get_workshop(s, "W"))
                if p.scaling == "fixed" and p.configuration == "baseline"}
    assert {pid for name, pid in choices.values() if name == "W"} == want
    picked = [label for label, (name, _) in choices.items() if name == "W"][:2]
    state.cards = picked
    state.worst_cases = 0
    html = state.build().html
    assert html.count("class='card'") == 2 and "Expert review: plot cards" in html
    engineer = AppState(Backend(db), principal=Principal("eng", frozenset({"engineer"})))
    engineer.configuration = "baseline"
    assert ReportState(engineer).card_choices() == {}
