"""The workshop analysis page in Chromium: the 50 % figure, its n, "too few answers" (issue 39).

A served railval app (real SQLite database holding the demo campaign) with two closed-style
workshops whose answers are imported from CSV: ``BIG`` — three reviewers on 24 plots, whose
50 % deviation is estimated — and ``ONE`` — one panelist, 12 answers, the case of the issue.
The page must show the figure that equals the crossing of the plotted curve (recomputed here
from the JSON the chart is drawn from), the n behind every figure, Table 1 counts, and for
``ONE`` "too few answers to estimate" and a strictness that cannot be estimated. The CLI's
``workshop analyse`` says the same. Screenshots go to ``test-artifacts/``.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest

from tests.browser_support import VIEWPORT, require_browser, screenshot, served_app, sign_in

pytestmark = [pytest.mark.browser]
TIMEOUT_MS = 120_000


def _crossing(values: list[float], yes: list[float]) -> float:
    """Where the straight segments of the plotted curve cross ½ (recomputed here)."""
    for i in range(len(values) - 1):
        if yes[i] > 0.5 > yes[i + 1]:
            return values[i] + (values[i + 1] - values[i]) * (yes[i] - 0.5) / (yes[i] - yes[i + 1])
    raise AssertionError("the plotted curve does not cross 50 %")


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    require_browser()
    from railval.app.services import workshop_answers as wa
    from railval.app.services import workshops as ws
    from railval.db import users
    from railval.db import workshops as wsdb

    from tests.browser_support import demo_database

    folder = tmp_path_factory.mktemp("wsanalysis")
    db = demo_database(folder, n_configs=1)
    sections = [f"S{i:02d}" for i in range(1, 13)]
    ws.create(db, "BIG", "demo", sections=sections, kinds=["Y_time", "Q_time"], repeats=0.0)
    ws.create(db, "ONE", "demo", sections=sections[:3], kinds=["Y_time", "Q_time"], repeats=0.0)
    with db.session(write=True) as s:
        big = [(p.id, p.deviation) for p in wsdb.plots(s, wsdb.get_workshop(s, "BIG"))]
        one = [(p.id, p.deviation) for p in wsdb.plots(s, wsdb.get_workshop(s, "ONE"))]
        users.create_user(s, "orga", password="organiser-pass", roles=["organiser"])
    # reviewers who say Yes below their own cut in the deviation (strict, typical, lenient)
    devs = sorted(d for _, d in big if d is not None)
    cuts = {"rev1": devs[8], "rev2": devs[12], "rev3": devs[16]}
    rows = [f"{r},{pid},{'yes' if d is not None and d < cut else 'no'},4,"
            for r, cut in cuts.items() for pid, d in big]
    (folder / "big.csv").write_text("reviewer,plot,answer,seconds,comment\n" + "\n".join(rows) + "\n")
    wa.import_answers(db, "BIG", folder / "big.csv")
    odevs = sorted(d for _, d in one if d is not None)
    rows = [f"solo,{pid},{'yes' if d is not None and d < odevs[6] else 'no'},4," for pid, d in one]
    (folder / "one.csv").write_text("reviewer,plot,answer,seconds,comment\n" + "\n".join(rows) + "\n")
    wa.import_answers(db, "ONE", folder / "one.csv")
    with served_app(db) as url:
        yield {"db": db, "base": url.rsplit("/app", 1)[0], "big": len(big), "one": len(one)}
    db.dispose()


def _analysis_page(browser, env, name: str):
    ctx = browser.new_context(viewport=VIEWPORT)
    page = ctx.new_page()
    sign_in(page, env["base"], "orga", "organiser-pass")
    page.goto(f"{env['base']}/workshops/{name}/analysis")
    page.get_by_text("Table 1").wait_for(timeout=TIMEOUT_MS)
    return ctx, page


def test_figure_is_the_plotted_crossing_and_carries_its_n(browser, env):
    from railval.app.services.workshop_answers import analyse

    doc = analyse(env["db"], "BIG")
    thr = doc["threshold"]
    assert thr["deviation_at_50_status"] == "estimated"
    curve = thr["deviation_curve"]
    at50 = _crossing(curve["value"], curve["yes"])
    assert thr["deviation_at_50"] == pytest.approx(at50, rel=1e-12)
    n = thr["deviation_n"]
    assert n["reviewers"] == 3 and n["plots"] >= 20 and n["answers"] == 3 * n["plots"]
    ctx, page = _analysis_page(browser, env, "BIG")
    sentence = page.locator("p.at50").first.inner_text()
    assert sentence.startswith("Deviation at which a typical reviewer says Yes half of the time: "
                               f"{at50:.2f} (")
    assert f"from {n['answers']} answers by 3 reviewers on {n['plots']} plots" in sentence
    assert "too few answers" not in page.content()
    # Table 1: each share with the Yes count and the answers it rests on
    t1 = page.locator("table").first
    assert t1.locator("th").all_inner_texts()[:4] == ["plot kind", "plots", "answers", "reviewers"]
    cells = t1.locator("tr").nth(1).locator("td").all_inner_texts()
    assert re.fullmatch(r"\d+\.\d % \(\d+ of \d+\)", cells[4]) and re.fullmatch(r"\d+\.\d % \(\d+ of \d+\)", cells[5])
    # agreement figures with the plots and reviewers they rest on
    agreement = page.locator("h3:text('Agreement') + table")
    assert agreement.locator("th").all_inner_texts() == ["statistic", "value", "interval", "plots", "reviewers"]
    # the chart says its n in its title (the image is drawn from the same JSON)
    assert page.locator("img[alt='answers against the normalised deviation']").is_visible()
    screenshot(page, "workshop-analysis-n")
    ctx.close()


def test_one_panelist_twelve_answers_says_too_few(browser, env):
    ctx, page = _analysis_page(browser, env, "ONE")
    text = page.locator("body").inner_text()
    sentence = page.locator("p.at50").first.inner_text()
    assert "Deviation at which a typical reviewer says Yes half of the time: too few answers to estimate" in sentence
    assert env["one"] == 12 and "12 answers by 1 reviewer on 12 plots" in sentence
    assert re.search(r"at least \d+ answers on \d+ plots", sentence)
    assert "Link sensitivity" not in text            # no parametric numbers where the page says none
    assert "cannot be estimated with one reviewer" in text
    assert "0.00 … 0.00" not in text
    assert re.search(r"\d+\.\d % \(\d+ of 6\)", text)          # 3 sections × 2 wheels per kind
    screenshot(page, "workshop-analysis-too-few")
    ctx.close()


def test_cli_analyse_says_the_same(env):
    """``railval workshop analyse ONE`` (text and ``--json``) in a child process."""
    cmd = [sys.executable, "-m", "railval.app", "--db", env["db"].url, "--as", "orga", "workshop", "analyse", "ONE"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=300, check=True).stdout
    assert "too few answers to estimate (12 answers by 1 reviewer(s) on 12 plots" in out
    assert re.search(r"\d+\.\d % \(\d+ of 6\)", out)
    doc = json.loads(subprocess.run(cmd + ["--json"], capture_output=True, text=True, timeout=300,
                                    check=True).stdout)
    thr = doc["threshold"]
    assert thr["deviation_at_50"] is None and thr["deviation_at_50_status"] == "too few answers to estimate"
    assert thr["deviation_n"] == {"answers": 12, "reviewers": 1, "plots": 12}
    assert {"min_yes", "max_yes", "answers", "min_yes_answers", "max_yes_answers"} <= set(doc["table1"][0])
