"""Review workshops: plan and build the plot set, render it once, the status documents
(docs/workshops.md).

* :func:`plan` — the plots a choice of configurations × sections × kinds gives (count shown
  before creating; no signal is read).
* :func:`create` — read the signals, low-pass 20 Hz, choose each kind's one scaling from
  the whole workshop's data (:func:`railval.core.workshop.kind_scale`), compute every plot's
  objective deviation (EN 14363 values through the validation service's result cache) and
  Sprague–Geers C, render each plot once (:mod:`railval.app.services.workshop_render`) and
  store everything in one transaction.
* :func:`scaling_preview` — the ranges of both scalings and the share of flat plots.

The answers' side — the CSV import and export and the analysis — is
:mod:`railval.app.services.workshop_answers`; the plot cards are
:mod:`railval.app.services.workshop_cards`; the rendering
:mod:`railval.app.services.workshop_render`.

The documents that read a stored workshop back (status, plot list, kinds, review link) are
:mod:`railval.app.services.workshop_documents` (their names stay importable from here).
"""

from __future__ import annotations

import contextlib
import math
import random
import textwrap
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy import select

from railval.app.services.workshop_documents import (
    describe_kinds,
    kind_labels,
    plots_document,
    review_link,
    status_document,
    workshop_scaling,
)
from railval.core import lazy
from railval.core.errors import InvalidParameter, InvalidSignal
from railval.core.quantities import QUANTITIES
from railval.core.roles import Principal, require
from railval.core.workshop import (
    DEFAULT_SCALING,
    LOWPASS_HZ,
    PLOT_KIND_IDS,
    PLOT_KINDS,
    PSD_MAX_HZ,
    PSD_SEGMENT_S,
    SCALINGS,
    TWIN_SCALINGS,
    Extent,
    Scale,
    check_scaling,
    dv_over_limit,
    get_kind,
    group_scales,
    is_flat,
    kind_scale,
    nice_range,
    plot_deviation,
    plots_for,
    scale_key,
)
from railval.db import workshops as wsdb
from railval.db.models import Workshop

# the filters, the PSD and the Sprague–Geers metric load numba, scipy.signal and pandas: bound
# here, imported when a plot is first rendered (not by `workshop analyse`, `status`, …)
filtfilt_rows = lazy.function("railval.core.filters", "filtfilt_rows")
common_grid = lazy.function("railval.core.metrics.grid", "common_grid")
sprague_geers = lazy.function("railval.core.metrics.sprague_geers", "sprague_geers")
#: deferred (railval.core.lazy): the campaign queries (railval.db.repo and what it imports),
#: read when a workshop is planned or created, not by the status and plot-list documents
repo = lazy.module("railval.db.repo")
#: deferred (railval.core.lazy): the validation service (the EN 14363 chain, its pools and
#: cache) is read only when a workshop's objective deviations are computed
source_values = lazy.function("railval.app.services.validation", "source_values")
#: deferred (railval.core.lazy): Matplotlib and the render pool, loaded when plots are rendered
#: (not by `workshop plan`, `status`, `analyse`, …)
workshop_render = lazy.module("railval.app.services.workshop_render")
welch_psd = lazy.function("railval.core.psd", "welch_psd")

DEFAULT_REPEATS = 0.1
_POSITION_TEXT = {"w1L": "wheelset 1 left wheel", "w1R": "wheelset 1 right wheel",
                  "w3L": "wheelset 3 left wheel", "w3R": "wheelset 3 right wheel",
                  "b1": "above bogie 1", "b2": "above bogie 2"}


@dataclass(frozen=True)
class PlannedPlot:
    configuration: str
    section: str
    kind: str
    position: str

    @property
    def channel(self) -> str:
        return PLOT_KINDS[self.kind].channel(self.position)


def _check_choice(label: str, chosen: Sequence[str] | None, known: Sequence[str]) -> list[str]:
    if not chosen:
        return list(known)
    unknown = [c for c in chosen if c not in known]
    if unknown:
        raise InvalidParameter(f"unknown {label} {', '.join(map(repr, unknown))}; "
                               f"known: {', '.join(known) or '(none)'}")
    return [k for k in known if k in set(chosen)]


def plan(session, campaign: str, configurations: Sequence[str] | None = None,
         sections: Sequence[str] | None = None,
         kinds: Sequence[str] | None = None) -> list[PlannedPlot]:
    """Every plot of the choice (default: all configurations, sections and kinds), in
    configuration → section → kind → position order. Reads channel names only."""
    camp = repo.get_campaign(session, campaign)
    configs = _check_choice("configuration(s)", configurations,
                            [c.name for c in repo.list_configurations(session, camp)])
    secs = _check_choice("section(s)", sections, [s.id for s in repo.section_infos(session, camp)])
    kinds = _check_choice("plot kind(s)", kinds, list(PLOT_KIND_IDS))
    measured = repo.signal_hashes(session, camp, None)
    out = []
    for cname in configs:
        simulated = repo.signal_hashes(session, camp, cname)
        for sid in secs:
            both = set(measured.get(sid, {})) & set(simulated.get(sid, {}))
            out += [PlannedPlot(cname, sid, k, p) for k, p in plots_for(kinds, both)]
    return out


def count_by_kind(planned: Sequence[PlannedPlot]) -> dict[str, int]:
    out: dict[str, int] = {}
    for p in planned:
        out[p.kind] = out.get(p.kind, 0) + 1
    return out


# ------------------------------------------------------------------------- signals
@dataclass
class _Curve:
    """One side of one plot: x (distance in m or frequency in Hz) and y."""

    x: np.ndarray
    y: np.ndarray


def _filtered(ss, names: set[str]) -> dict[str, np.ndarray]:
    names = sorted(n for n in names if n in ss.channels)
    if not names:
        return {}
    rows = filtfilt_rows([ss.channels[n] for n in names], ss.fs, "lowpass")
    return dict(zip(names, rows, strict=True))


def _signal(kind, position: str, filt: dict[str, np.ndarray]) -> np.ndarray:
    if kind.signal == "YQ":
        y, q = filt[f"Y_{position}"], filt[f"Q_{position}"]
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(np.abs(q) > 1e-9, y / q, np.nan)
        return r
    return filt[kind.channel(position)]


def _curve(kind, sig: np.ndarray, ss) -> _Curve:
    if kind.domain == "psd":
        psd = welch_psd(np.nan_to_num(sig), ss.fs, PSD_SEGMENT_S)
        keep = psd.frequency_hz <= PSD_MAX_HZ
        return _Curve(psd.frequency_hz[keep], psd.density[keep])
    dist = ss.distance_m - ss.distance_m[0]
    return _Curve(dist, sig)


def _extent(kind, c: _Curve) -> Extent:
    y = c.y[np.isfinite(c.y)]
    if kind.domain == "psd":
        pos = y[(y > 0) & (c.x > 0)] if y.size == c.x.size else y[y > 0]
        return Extent(0.0, PSD_MAX_HZ, float(pos.min()) if pos.size else 0.0,
                      float(y.max()) if y.size else 1.0)
    return Extent(float(np.nanmin(c.x)), float(np.nanmax(c.x)),
                  float(y.min()) if y.size else 0.0, float(y.max()) if y.size else 1.0)


def _sg_c(m_sig: np.ndarray, m_ss, s_sig: np.ndarray, s_ss) -> float | None:
    """Sprague–Geers C (Polach & Böttcher 2014 eq. 3) of the low-passed signals on one grid."""
    try:
        g = common_grid(np.nan_to_num(m_sig), np.nan_to_num(s_sig), m_ss.fs, s_ss.fs,
                        t0_measured=float(m_ss.time_s[0]), t0_simulated=float(s_ss.time_s[0]))
        c = sprague_geers(g.measured, g.simulated).C
    except (InvalidSignal, InvalidParameter):
        return None
    return float(c) if math.isfinite(c) else None


#: characters of a review plot's title line (≈ 9.3 px a character of the 13 pt title: the
#: 860 px above the axes hold about 95)
TITLE_LINE_CHARS = 88


def _title(kind, position: str, *, blind: bool, vehicle: str, config: str,
           section: str) -> str:
    """The plot's title: what is shown, and unless blind the section, vehicle and
    configuration on up to two more lines (wrapped at :data:`TITLE_LINE_CHARS`; a longer
    vehicle and configuration name ends in "…" — the plot list and the cards carry it whole)."""
    what = f"{kind.label[:1].upper()}{kind.label[1:]}, {_POSITION_TEXT.get(position, position)}"
    if blind:
        return what
    rest = textwrap.wrap(f"{vehicle}, configuration {config}", TITLE_LINE_CHARS, max_lines=2, placeholder=" …")
    return "\n".join([f"{what} — section {section}", *rest])


# ------------------------------------------------------------------------- create
def _collect(session, camp, planned: Sequence[PlannedPlot], infos, *, objective: bool,
             std_limits=None, progress=None) -> tuple[list[dict[str, Any]], list[tuple[_Curve, _Curve]]]:
    """Read and low-pass every planned plot's signals: per plot its facts (kind, section,
    zone, configuration, channel, position and — with ``objective`` — deviation and
    Sprague–Geers C) and its two curves."""
    used_secs = sorted({p.section for p in planned}, key=list(infos).index)
    used_cfgs = list(dict.fromkeys(p.configuration for p in planned))
    if objective:
        sec_list = [infos[s] for s in used_secs]
        en_meas = source_values(session, camp, None, sec_list)
        en_sim = {c: source_values(session, camp, c, sec_list) for c in used_cfgs}
    curves: list[tuple[_Curve, _Curve]] = []
    facts: list[dict[str, Any]] = []
    for si, sid in enumerate(used_secs):
        todo = [p for p in planned if p.section == sid]
        need = {c for p in todo for c in PLOT_KINDS[p.kind].source_channels(p.position)}
        m_ss = repo.load_signalsets(session, camp, None, sections=[sid], channels=sorted(need))[sid]
        m_filt = _filtered(m_ss, need)
        for cname in used_cfgs:
            mine = [p for p in todo if p.configuration == cname]
            if not mine:
                continue
            s_need = {c for p in mine for c in PLOT_KINDS[p.kind].source_channels(p.position)}
            s_ss = repo.load_signalsets(session, camp, cname, sections=[sid], channels=sorted(s_need))[sid]
            s_filt = _filtered(s_ss, s_need)
            dv = (dv_over_limit(en_meas.get(sid, {}), en_sim[cname].get(sid, {}), std_limits)
                  if objective else {})
            for p in mine:
                k = PLOT_KINDS[p.kind]
                m_sig, s_sig = _signal(k, p.position, m_filt), _signal(k, p.position, s_filt)
                curves.append((_curve(k, m_sig, m_ss), _curve(k, s_sig, s_ss)))
                fact = {"kind": p.kind, "section": sid, "configuration": cname,
                        "channel": p.channel, "position": p.position}
                if objective:
                    fact["deviation"] = plot_deviation(k, p.position, dv)
                    fact["sg_c"] = _sg_c(m_sig, m_ss, s_sig, s_ss)
                facts.append(fact)
        if progress is not None:
            progress("reading and filtering signals", 0.5 * (si + 1) / len(used_secs), {})
    return facts, curves


def _plot_extent(kind, cm: _Curve, cs: _Curve) -> Extent:
    """The extent of one plot: both curves together."""
    a, b = _extent(kind, cm), _extent(kind, cs)
    return Extent(min(a.x_lo, b.x_lo), max(a.x_hi, b.x_hi), min(a.y_lo, b.y_lo), max(a.y_hi, b.y_hi))


def _scaled(facts, curves, infos, scaling: str) -> tuple[list[str], dict[str, Scale], dict[str, dict[str, Any]]]:
    """Per plot its scale key, the scale of every key (:func:`railval.core.workshop.
    group_scales`) and per key its summary: kind, zone (``None`` for workshop scaling),
    ranges, number of plots and of flat plots."""
    keys, ext, domains = [], [], {}
    for f, (cm, cs) in zip(facts, curves, strict=True):
        k = PLOT_KINDS[f["kind"]]
        key = scale_key(k.id, infos[f["section"]].zone, scaling)
        keys.append(key)
        domains[key] = k.domain
        ext.append((key, _extent(k, cm)))
        ext.append((key, _extent(k, cs)))
    scales = group_scales(domains, ext)
    groups: dict[str, dict[str, Any]] = {}
    for key, f, (cm, cs) in zip(keys, facts, curves, strict=True):
        k = PLOT_KINDS[f["kind"]]
        g = groups.setdefault(key, {"kind": k.id, "zone": None if scaling == "workshop"
                                    else infos[f["section"]].zone,
                                    "x": [scales[key].x.lo, scales[key].x.hi],
                                    "y": [scales[key].y.lo, scales[key].y.hi],
                                    "log": scales[key].y.log, "y_label": k.y_label,
                                    "x_label": k.x_label, "plots": 0, "flat": 0})
        g["plots"] += 1
        g["flat"] += bool(is_flat(_plot_extent(k, cm, cs), scales[key].y))
    return keys, scales, groups


def flat_share(groups: dict[str, dict[str, Any]]) -> dict[str, float]:
    """Per kind the share of plots whose filtered signal spans less than 10 % of its y range
    (:func:`railval.core.workshop.is_flat`)."""
    n: dict[str, list[int]] = {}
    for g in groups.values():
        c = n.setdefault(g["kind"], [0, 0])
        c[0] += g["flat"]
        c[1] += g["plots"]
    return {k: round(f / t, 4) for k, (f, t) in n.items()}


def scaling_preview(database, campaign: str, configurations: Sequence[str] | None = None,
                    sections: Sequence[str] | None = None, kinds: Sequence[str] | None = None,
                    *, actor: Principal | str = "system") -> dict[str, Any]:
    """What each scaling would give, before anything is rendered: per scaling the ranges per
    kind (and zone) and the share of flat plots per kind (the organiser's form)."""
    if isinstance(actor, Principal):
        require(actor, "workshop.run")
    with database.write_session(deferred=True) as session:  # may fill the result cache
        camp = repo.get_campaign(session, campaign)
        planned = plan(session, camp.name, configurations, sections, kinds)
        if not planned:
            return {"plots": 0, "scalings": {}}
        infos = {s.id: s for s in repo.section_infos(session, camp)}
        facts, curves = _collect(session, camp, planned, infos, objective=False)
    out = {}
    for scaling in SCALINGS:
        _, _, groups = _scaled(facts, curves, infos, scaling)
        out[scaling] = {"ranges": list(groups.values()), "flat_share": flat_share(groups)}
    return {"plots": len(facts), "default": DEFAULT_SCALING, "scalings": out}


def _check_options(name: str, scaling: str, twin_scaling: str, repeats: float, auto_share: float,
                   actor: Principal | str) -> None:
    """Refuse a workshop's options before anything is read (:class:`InvalidParameter`)."""
    if isinstance(actor, Principal):
        require(actor, "workshop.run")
    wsdb.check_name(name)
    check_scaling(scaling)
    if twin_scaling not in TWIN_SCALINGS or twin_scaling == scaling:
        raise InvalidParameter(f"--twin-scaling must be auto or the scaling other than {scaling!r}, "
                               f"got {twin_scaling!r}")
    if not (0.0 <= repeats <= 0.5):
        raise InvalidParameter(f"--repeats must be between 0 and 0.5, got {repeats!r}")
    if not (0.0 <= auto_share <= 1.0):
        raise InvalidParameter(f"automatic-scaling share must be between 0 and 1, got {auto_share!r}")


def _refuse_existing(session, name: str) -> None:
    if session.scalar(_exists_query(name)) is not None:
        raise InvalidParameter(f"workshop {name!r} already exists; choose another name")


@dataclass
class _Gathered:
    """What a new workshop is drawn from: its campaign, sections, vehicle and the plot facts
    with their measured and simulated curves."""

    campaign: str
    campaign_id: int
    infos: dict[str, Any]
    vehicle: dict[str, Any]
    facts: list[dict[str, Any]]
    curves: list[tuple[_Curve, _Curve]]


def _gather(session, name: str, campaign: str, configurations, sections, kinds,
            progress: Callable[..., None] | None) -> _Gathered:
    """Read and filter the signals of the planned plots (step 1 of :func:`create`)."""
    _refuse_existing(session, name)
    camp = repo.get_campaign(session, campaign)
    planned = plan(session, camp.name, configurations, sections, kinds)
    if not planned:
        raise InvalidParameter("this choice of configurations, sections and kinds gives no plot "
                               "(no section has the channels of the chosen kinds on both sides)")
    infos = {s.id: s for s in repo.section_infos(session, camp)}
    vehicle = repo.vehicle_info(session, camp)
    std_limits = {q: QUANTITIES[q].std_limit(vehicle["Q0_kN"], vehicle["kind"],
                                             vehicle["secondary_suspension"])
                  for q in QUANTITIES}
    facts, curves = _collect(session, camp, planned, infos, objective=True,
                             std_limits=std_limits, progress=progress)
    return _Gathered(camp.name, camp.id, infos, vehicle, facts, curves)


def _own_scale(k, cm: _Curve, cs: _Curve) -> Scale:
    """The per-plot automatic scaling of the presentation experiment."""
    own = kind_scale(k.domain, [_extent(k, cm), _extent(k, cs)])
    if k.domain == "time":
        own = Scale(nice_range(min(cm.x.min(), cs.x.min()), max(cm.x.max(), cs.x.max())), own.y)
    return own


def _render_rows(g: _Gathered, jobs: list[tuple[int, str]], fixed: tuple[list[str], dict[str, Scale]],
                 twin: tuple[list[str], dict[str, Scale]] | None, *, blind: bool,
                 progress: Callable[..., None] | None, pool=None) -> list[dict[str, Any]]:
    """Render every plot once at its scaling (step 2 of :func:`create`): ``jobs`` are
    (fact index, ``fixed`` | ``auto`` | the twin's scaling); the PNGs on the render pool
    (:func:`railval.app.services.workshop_render.render_many`), progress as plots rendered
    n of N."""
    rows: list[dict[str, Any]] = []
    specs: list[workshop_render.PlotSpec] = []
    for i, plot_scaling in jobs:
        f, (cm, cs) = g.facts[i], g.curves[i]
        k = PLOT_KINDS[f["kind"]]
        if plot_scaling == "fixed":
            key, scale = fixed[0][i], fixed[1][fixed[0][i]]
        elif plot_scaling != "auto":
            key, scale = twin[0][i], twin[1][twin[0][i]]
        else:
            key, scale = None, _own_scale(k, cm, cs)
        title = _title(k, f["position"], blind=blind, vehicle=g.vehicle["name"] or g.campaign,
                       config=f["configuration"], section=f["section"])
        specs.append(workshop_render.PlotSpec(cm.x, cm.y, cs.x, cs.y, scale, title, k.x_label, k.y_label))
        params = workshop_render.render_parameters(k.to_dict(), scale, scaling=plot_scaling, title=title,
                                   x_label=k.x_label, y_label=k.y_label,
                                   extra={"lowpass_hz": LOWPASS_HZ,
                                          "psd_segment_s": PSD_SEGMENT_S if k.domain == "psd" else None,
                                          "blind": bool(blind), "scale_key": key,
                                          "zone": g.infos[f["section"]].zone})
        rows.append({**f, "scaling": plot_scaling, "render": params,
                     "twin": i if plot_scaling != "fixed" else None})

    def rendered(done: int, total: int) -> None:
        if progress is not None:
            progress("rendering plots", 0.5 + 0.5 * done / max(1, total),
                     {"done": done, "total": total})
    for row, image in zip(rows, workshop_render.render_many(specs, rendered, pool=pool), strict=True):
        row["image"] = image
    return rows


def create(database, name: str, campaign: str, *, configurations: Sequence[str] | None = None,
           sections: Sequence[str] | None = None, kinds: Sequence[str] | None = None,
           blind: bool = False, repeats: float = DEFAULT_REPEATS, auto_share: float = 0.0,
           seed: int = 0, scaling: str = DEFAULT_SCALING, twin_scaling: str = "auto",
           actor: Principal | str = "system",
           progress: Callable[..., None] | None = None,
           planned_plots: int | None = None) -> dict[str, Any]:
    """Build, render and store a workshop; returns its summary (``name, plots, by_kind,
    scaling, scales, flat_share``). ``scaling``: ``zone`` (one range per kind within each
    EN 14363 test zone, the default) or ``workshop`` (one range per kind over the whole
    workshop); ``auto_share``: share of the fixed plots also rendered with per-plot
    automatic scaling (the presentation experiment), chosen with ``seed``; ``twin_scaling``:
    how those twins are scaled — ``auto`` (per-plot ranges) or the other consistent scaling
    (``workshop`` beside ``zone`` or the reverse: the two scalings paired on the same plot;
    the twin's ``scaling`` is then that name). ``planned_plots``: the number of plots the
    caller has planned (:func:`plan`); given, the render workers start before the signals
    are read (:func:`railval.app.services.workshop_render.early_pool`).

    Steps: gather the signals (a read unit of work), scale and render (no database), store
    (one ``session(write=True)``, so the write lock is held only while storing: a failure
    before leaves nothing stored). ``progress(stage, fraction, info)`` is called as the work
    advances; while rendering, ``info`` is ``{"done": n, "total": N}`` (plots rendered)."""
    _check_options(name, scaling, twin_scaling, repeats, auto_share, actor)
    early = (workshop_render.early_pool(planned_plots + round(auto_share * planned_plots))
             if planned_plots else contextlib.nullcontext())
    with early as pool:
        with database.write_session(deferred=True) as session:  # may fill the result cache
            g = _gather(session, name, campaign, configurations, sections, kinds, progress)
        facts = g.facts
        keys, scales, groups = _scaled(facts, g.curves, g.infos, scaling)
        twin = None
        if twin_scaling != "auto":
            twin_keys, twin_scales, _ = _scaled(facts, g.curves, g.infos, twin_scaling)
            twin = (twin_keys, twin_scales)
        rng = random.Random(seed)
        n_auto = round(auto_share * len(facts))
        auto_idx = sorted(rng.sample(range(len(facts)), n_auto)) if n_auto else []
        jobs = [(i, "fixed") for i in range(len(facts))] + [(i, twin_scaling) for i in auto_idx]
        rows = _render_rows(g, jobs, (keys, scales), twin, blind=blind, progress=progress, pool=pool)
    settings = {"campaign": g.campaign,
                "configurations": list(dict.fromkeys(f["configuration"] for f in facts)),
                "sections": list(dict.fromkeys(f["section"] for f in facts)),
                "kinds": sorted({f["kind"] for f in facts}, key=PLOT_KIND_IDS.index),
                "lowpass_hz": LOWPASS_HZ, "seed": seed, "blind": bool(blind),
                "repeats": repeats, "auto_share": auto_share, "scaling": scaling,
                "twin_scaling": twin_scaling,
                "objective": "largest |D_v| / std limit (Polach & Böttcher 2014 eq. 4, Table 2)"}
    with database.session(write=True) as session:
        _refuse_existing(session, name)
        w = wsdb.create_workshop(session, name, g.campaign_id, blind=blind, repeat_share=repeats,
                                 auto_share=auto_share, settings=settings,
                                 scales={k: s.to_dict() for k, s in scales.items()},
                                 plots=rows, actor=actor)
        stored_name = w.name
    return {"name": stored_name, "campaign": g.campaign, "plots": len(rows),
            "fixed_plots": len(facts), "auto_plots": len(auto_idx),
            "by_kind": count_by_kind([PlannedPlot(f["configuration"], f["section"], f["kind"],
                                                  f["position"]) for f in facts]),
            "blind": bool(blind), "repeats": repeats, "scaling": scaling,
            "flat_share": flat_share(groups),
            "scales": {k: s.to_dict() for k, s in scales.items()},
            "ranges": list(groups.values())}


def _exists_query(name: str):
    return select(Workshop.id).where(Workshop.name == name)


__all__ = ["PlannedPlot", "count_by_kind", "create", "describe_kinds", "flat_share", "get_kind",
           "kind_labels", "plan", "plots_document", "review_link", "scaling_preview", "status_document",
           "workshop_scaling"]
