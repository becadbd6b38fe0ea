"""Plot cards of a review workshop (Polach & Böttcher 2014 Figs. 3–5; docs/workshops.md
"Plot cards"): per plot the EN 14363 values of measurement and simulation (the pairs of
:func:`railval.app.services.validation.validate_configuration`, i.e. ``railval validate``),
the share of Yes of every reviewer group, the Sprague–Geers errors of
:func:`railval.app.services.metrics.metrics_for_configuration` (``railval metrics``) and the
deviation; the chosen cards for the validation report (their HTML:
:mod:`railval.app.workshop_web.cards`).
"""

from __future__ import annotations

import base64
import math
from collections.abc import Sequence
from typing import Any

from railval.app.services.workshop_answers import analysis_frames
from railval.core import lazy
from railval.core.errors import InvalidParameter
from railval.core.quantities import QUANTITIES
from railval.core.roles import Principal, require
from railval.core.workshop import PLOT_KINDS

#: deferred (railval.core.lazy): the database's workshop and campaign modules (SQLAlchemy and
#: the models) — bound like workshop_answers', loaded when a card is first read
wsdb = lazy.module("railval.db.workshops")
repo = lazy.module("railval.db.repo")
#: deferred (railval.core.lazy): the EN 14363 chain and the Sprague–Geers metric (scipy.signal,
#: numba, pandas), loaded only when cards are computed (not by `workshop report` choices)
validate_configuration = lazy.function("railval.app.services.validation", "validate_configuration")
metrics_for_configuration = lazy.function("railval.app.services.metrics", "metrics_for_configuration")


def _yes_shares(session, name: str) -> tuple[dict[tuple, dict[str, Any]], Any]:
    """Per fixed plot of workshop ``name`` (keyed by kind, section, configuration, channel)
    its share of Yes over the first answers and their number; and the workshop."""
    answers, _ = analysis_frames(session, name)
    first = answers[~answers["repeat"] & (answers["scaling"] == "fixed")]
    counts = first.groupby("plot")["answer"].agg(["sum", "count"])
    w = wsdb.get_workshop(session, name)
    out = {}
    for p in wsdb.plots(session, w):
        if p.scaling != "fixed":
            continue
        n = int(counts.loc[p.id, "count"]) if p.id in counts.index else 0
        out[(p.kind, p.section, p.configuration, p.channel)] = {
            "plot": p.id, "answers": n,
            "yes_share": round(float(counts.loc[p.id, "sum"]) / n, 4) if n else None}
    return out, w


def cards(database, name: str, *, groups: Sequence[str] = (), actor: Principal | str = "system"
          ) -> dict[str, Any]:
    """The plot cards of workshop ``name`` (Polach & Böttcher 2014 Figs. 3–5; the
    ``workshop cards NAME --json`` document): per plot its ``plot, kind, section, zone,
    configuration, channel``, the EN 14363 values of measurement and simulation of the
    kind's quantities at the plot's position in that section (``en``: ``quantity, measured,
    simulated, abs_diff`` = S − M, ``rel_diff`` = (S − M)/|M|) — the pairs
    :func:`railval.app.services.validation.validate_configuration` (``railval validate``)
    evaluates — the share of Yes and number of first answers, the Sprague–Geers
    ``sg`` ``{M, P, C}`` of :func:`railval.app.services.metrics.metrics_for_configuration`
    (``railval metrics``, whole section, raw) of the plot's channel (the PSD's signal for a
    PSD; none for Y/Q, not a recorded channel) and the objective ``deviation``.

    ``groups``: further workshops over the same plots (another reviewer group, e.g. the
    invited experts beside the partners); each card's ``groups`` lists every workshop's
    ``yes_share`` and ``answers`` on the plot with the same kind, section, configuration
    and channel (``null`` where that workshop lacks the plot)."""
    if isinstance(actor, Principal):
        require(actor, "workshop.results")
    # deferred: SQLite's write lock only at the final cache/run writes (docs/database.md)
    with database.write_session(deferred=True) as session:
        mine, w = _yes_shares(session, name)
        others = []
        for g in groups:
            if g == name:
                raise InvalidParameter(f"--groups: {g!r} is the workshop itself")
            shares, other = _yes_shares(session, g)
            if other.campaign_id != w.campaign_id:
                raise InvalidParameter(f"--groups: workshop {g!r} is on campaign {other.campaign.name!r}, "
                                       f"not {w.campaign.name!r}: not the same plots")
            others.append((g, shares))
        camp = w.campaign
        infos = {x.id: x for x in repo.section_infos(session, camp)}
        plots = [p for p in wsdb.plots(session, w) if p.scaling == "fixed"]
        configs = list(dict.fromkeys(p.configuration for p in plots))
        secs = sorted({p.section for p in plots}, key=list(infos).index)
        en, sg = {}, {}
        for cfg in configs:
            pairs = validate_configuration(session, camp.name, cfg, n_boot=0).pairs
            for r in pairs.itertuples(index=False):
                en[(cfg, r.section, r.position, r.quantity)] = (float(r.M), float(r.S))
            mine_cfg = [p for p in plots if p.configuration == cfg]
            chans = sorted({PLOT_KINDS[p.kind].channel(p.channel.split("_")[-1]) for p in mine_cfg
                            if PLOT_KINDS[p.kind].signal != "YQ"})
            if chans:
                df = metrics_for_configuration(session, camp.name, cfg, secs, chans,
                                               families=["sprague_geers"])
                for r in df.to_dict(orient="records"):
                    sg[(cfg, r["section"], r["channel"])] = {k: _finite(r.get(f"sg_{k}")) for k in "MPC"}
        out = []
        for p in plots:
            k = PLOT_KINDS[p.kind]
            position = p.channel.split("_")[-1]
            rows = []
            for q in k.quantities:
                if (p.configuration, p.section, position, q) not in en:
                    continue
                m, s_ = en[(p.configuration, p.section, position, q)]
                rows.append({"quantity": q, "measured": m, "simulated": s_, "abs_diff": s_ - m,
                             "rel_diff": (s_ - m) / abs(m) if m != 0 else None,
                             "unit": QUANTITIES[q].unit})
            key = (p.kind, p.section, p.configuration, p.channel)
            own = mine[key]
            card = {"plot": p.id, "kind": p.kind, "section": p.section, "zone": infos[p.section].zone,
                    "configuration": p.configuration, "channel": p.channel, "en": rows,
                    "yes_share": own["yes_share"], "answers": own["answers"],
                    "sg": None if k.signal == "YQ" else sg.get((p.configuration, p.section,
                                                                  k.channel(position))),
                    "deviation": p.deviation,
                    "groups": [{"workshop": name, "yes_share": own["yes_share"], "answers": own["answers"]}]
                    + [{"workshop": g, **({"yes_share": sh[key]["yes_share"], "answers": sh[key]["answers"]}
                                          if key in sh else {"yes_share": None, "answers": 0})}
                       for g, sh in others]}
            out.append(card)
    return {"workshop": name, "campaign": camp.name, "groups": [name, *groups], "cards": out}


def card_choices(database, campaign: str, config: str) -> dict[str, tuple[str, int]]:
    """Every fixed plot of the workshops on ``campaign`` that shows ``configuration``, as
    ``{label: (workshop, plot id)}`` for the report page's choice (labels such as
    ``"W · plot 12 · Y_time S01 Y_w1L"``); reads plot rows only, no image."""
    out: dict[str, tuple[str, int]] = {}
    with database.read_session() as session:
        for w in wsdb.list_workshops(session):
            if w.campaign.name != campaign:
                continue
            for p in wsdb.plots(session, w):
                if p.scaling == "fixed" and p.configuration == config:
                    out[f"{w.name} · plot {p.id} · {p.kind} {p.section} {p.channel}"] = (w.name, p.id)
    return out


def chosen_cards(database, config: str, chosen: Sequence[tuple[str, int]], *,
                 actor: Principal | str = "system") -> list[dict[str, Any]]:
    """:func:`report_cards` of (workshop, plot id) pairs from several workshops, in the
    order chosen."""
    by_workshop: dict[str, list[int]] = {}
    for name, pid in chosen:
        by_workshop.setdefault(name, []).append(int(pid))
    got = {(c["workshop"], c["plot"]): c
           for name, ids in by_workshop.items()
           for c in report_cards(database, name, config, ids, actor=actor)}
    return [got[(name, int(pid))] for name, pid in chosen]


def report_cards(database, name: str, config: str, plot_ids: Sequence[int], *,
                 groups: Sequence[str] = (), actor: Principal | str = "system") -> list[dict[str, Any]]:
    """The chosen cards of workshop ``name`` for the validation report of ``configuration``:
    each card of :func:`cards` with ``image_png`` (the stored, reviewed bytes) and
    ``image_sha256``. A plot id that is not a fixed plot of the workshop, or belongs to
    another configuration, is refused by name; nothing else is read then."""
    doc = cards(database, name, groups=groups, actor=actor)
    by_id = {c["plot"]: c for c in doc["cards"]}
    out = []
    with database.read_session() as session:
        w = wsdb.get_workshop(session, name)
        for pid in plot_ids:
            c = by_id.get(int(pid))
            if c is None:
                raise InvalidParameter(f"--cards: plot {pid} is not a plot of workshop {name!r} "
                                       f"(see `railval workshop cards {name} --json`)")
            if c["configuration"] != config:
                raise InvalidParameter(f"--cards: plot {pid} of workshop {name!r} shows configuration "
                                       f"{c['configuration']!r}, not {config!r}")
            data, sha = wsdb.plot_image(session, w.id, int(pid))
            out.append({**c, "workshop": name,
                        "image_png": base64.b64encode(data).decode(), "image_sha256": sha})
    return out


def _finite(x) -> float | None:
    return float(x) if x is not None and math.isfinite(float(x)) else None


__all__ = ["card_choices", "cards", "chosen_cards", "report_cards"]
