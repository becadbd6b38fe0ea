"""Diagnose & model workshop (docs/design.md §6–§7).

Ranked candidate effects with their explanation and signature; add an effect, set or
calibrate its parameters, re-simulate in a background thread with a progress bar; then the
new configuration's dashboard beside its parent's, and the error along the lineage.
"""

from __future__ import annotations

import html
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd
import panel as pn

from railval.app import plots
from railval.app.pages._common import (
    PageBase,
    bounded_input,
    make_dispatch,
    message,
    table,
    where_map,
)
from railval.app.pages.dashboard import validation_view
from railval.app.security import plain_message
from railval.app.state import AppState, DashboardState, DiagnoseState, unit_label
from railval.app.svg_charts import svg_paired_hbars
from railval.app.views import Ancestor, CalibrationOutcome, StoredDiagnosis
from railval.core.diagnosis.screen import SCREEN_KEEP, SCREEN_SECTIONS
from railval.core.quantities import QUANTITY_IDS

#: the signature chart's value axis: what the residual is, and that it has no unit
SIGNATURE_AXIS = ("residual rms, normalised: D_v / std limit (PSD groups: log2 PSD ratio) "
                  "— dimensionless")


def signature_chart(name: str, group_change: Mapping[str, tuple[float, float]]) -> str:
    """Residual RMS per quantity group before/after adding candidate ``name``
    (``TrustedCandidate.group_change``: its signature on the residual pattern) as a grouped
    horizontal bar chart (inline SVG, :func:`railval.app.svg_charts.svg_paired_hbars`): one
    before/after pair per quantity, EN quantity order then PSD groups, labels horizontal, a
    fixed height per group."""
    order = {q: i for i, q in enumerate(QUANTITY_IDS)}  # the quantities in EN order, then PSD groups
    groups = sorted(group_change.items(), key=lambda kv: (order.get(kv[0], 99), kv[0]))
    return svg_paired_hbars([g for g, _ in groups], [float(before) for _, (before, _after) in groups],
                            [float(after) for _, (_before, after) in groups],
                            title=f"Signature of {name}: residual before → after",
                            xlabel=SIGNATURE_AXIS, names=("before", "after (fitted)"),
                            colors=(plots.FAIL_COLOR, plots.PASS_COLOR))


class DiagnosePage(PageBase):
    name_ = "diagnose"

    def __init__(self, app: AppState, **params):
        super().__init__(app, **params)
        self.state = DiagnoseState(app)
        self.dash = DashboardState(app)
        self.diagnose_btn = pn.widgets.Button(label="Run diagnosis", color="primary", width=160)
        self.diagnose_btn.on_click(lambda e: self.state.run_diagnosis(dispatch=make_dispatch()))
        self.effect_select = pn.widgets.Select.from_param(self.state.param.effect, name="Effect to add", width=240,
                                                          css_classes=["rv-effect"])
        self.name_input = pn.widgets.TextInput.from_param(self.state.param.new_name, name="New configuration",
                                                          width=260, css_classes=["rv-new-name"])
        self.calibrate_btn = pn.widgets.Button(label="Add, calibrate & re-simulate", color="success",
                                               width=240)
        self.calibrate_btn.on_click(lambda e: self._start(calibrate=True))
        self.simulate_btn = pn.widgets.Button(label="Add with these parameters & re-simulate", width=300)
        self.simulate_btn.on_click(lambda e: self._start(calibrate=False))
        st = self.state
        self.diag_estimate = pn.pane.Markdown("", margin=(0, 10), styles={"color": "#555"})
        self.cal_estimate = pn.pane.Markdown("", margin=(0, 10), styles={"color": "#555"})
        self.diag_settings = pn.Card(
            pn.Row(pn.widgets.MultiChoice.from_param(st.param.candidate_effects,
                                                     name="Candidate effects (none chosen: every missing effect)",
                                                     width=480, css_classes=["rv-candidate-effects"]),
                   bounded_input(st.param.values_per_parameter, "Scan values per parameter", app, width=200)),
            pn.widgets.Checkbox.from_param(st.param.screened, name=(
                f"Screened: every candidate on {SCREEN_SECTIONS} sections first, only the {SCREEN_KEEP} best there "
                "on all (about half the simulation; the others are listed, not ranked)"), width=700,
                css_classes=["rv-screened"]),
            self.diag_estimate, title="Diagnosis settings", collapsed=True, sizing_mode="stretch_width",
            css_classes=["rv-diag-settings"])
        # population, generations, polish and seed drive the global search only: editable when it is chosen
        self.global_inputs = [
            bounded_input(st.param.popsize, "Population per parameter", app, width=170, disabled=True),
            bounded_input(st.param.maxiter, "Generations (at most)", app, width=170, disabled=True),
            bounded_input(st.param.polish_maxfev, "Polish simulations (at most)", app, width=190, disabled=True),
            bounded_input(st.param.seed, "Seed", app, width=110, disabled=True)]
        self.cal_settings = pn.Card(
            pn.FlexBox(
                pn.widgets.MultiChoice.from_param(st.param.fit_parameters,
                                                  name="Parameters to fit (none chosen: all; others keep the values set)",
                                                  width=420),
                pn.widgets.Checkbox.from_param(st.param.global_search, name="Global search (differential "
                                               "evolution + local polish) instead of the local fit", width=420),
                *self.global_inputs,
                pn.widgets.Checkbox.from_param(st.param.split, name="Hold out one section per zone "
                                               "(judge the fit on sections it has not seen)", width=420)),
            self.cal_estimate, title="Calibration settings (local trust-region fit; global search optional)",
            collapsed=True, sizing_mode="stretch_width", css_classes=["rv-cal-settings"])
        st.param.watch(lambda e: self._show_estimates(), ["candidate_effects", "values_per_parameter", "screened",
                                                          "fit_parameters", "popsize", "maxiter",
                                                          "polish_maxfev", "effect", "global_search"])
        st.param.watch(self._method_changed, ["global_search"])
        self._method_changed()
        self.param_box = pn.Column(sizing_mode="stretch_width")
        self.explain = pn.pane.Markdown("", sizing_mode="stretch_width")
        self.candidates_box = pn.Column(sizing_mode="stretch_width")
        self.candidate_box = pn.Column(sizing_mode="stretch_width", css_classes=["rv-candidate"])
        self.result_box = pn.Column(sizing_mode="stretch_width")
        self._param_widgets: dict[str, pn.widgets.FloatInput] = {}
        self.state.param.watch(lambda e: (self._show_candidates(), self._show_effect()), ["candidates"])
        self.state.param.watch(lambda e: (self._show_effect(), self._show_candidate()), ["effect"])
        app.param.watch(self._busy_changed, ["busy"])
        self._busy_changed()  # the page may be opened while another page's job runs

    def _busy_changed(self, *_) -> None:
        for b in (self.diagnose_btn, self.calibrate_btn, self.simulate_btn):
            b.disabled = bool(self.app.busy)

    def _start(self, calibrate: bool) -> None:
        # manual values: the parameters to simulate with, or the calibration's start point
        self.state.parameters = {k: float(w.value) for k, w in self._param_widgets.items()
                                 if w.value is not None}
        self.state.run_calibration(dispatch=make_dispatch(), calibrate=calibrate)

    def refresh(self) -> None:
        try:
            catalogue = {e["name"]: e for e in self.state.effect_catalogue()}
            available = self.state.available_effects()
        except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
            catalogue, available = {}, []
            self.app.set_status(plain_message(exc, "diagnose"), "warning")
        self._catalogue = catalogue
        ranked = [c.name for c in self.state.view.candidates] if self.state.view is not None else []
        self.state.param.effect.objects = ranked + [e for e in available if e not in ranked]
        if self.state.effect not in self.state.param.effect.objects:
            self.state.effect = (self.state.param.effect.objects or [None])[0]
        if self.state.new_name in self.app.param.configuration.objects:
            self.state.name_edited = False  # a stored name cannot be reused: suggest again
        self.state._suggest_name()
        if catalogue:
            self.state.refresh_choices()
            self._show_estimates()
        self._show_candidates()
        self._show_effect()
        self._show_results()
        self.body.objects = [
            pn.pane.Markdown(f"Configuration under study: **{html.escape(str(self.app.configuration))}**. "
                             "Diagnosis compares its residual pattern with the signature of every "
                             "effect it lacks and of each vehicle-model parameter set differently.", sizing_mode="stretch_width"),
            self.diagnose_btn, self.diag_settings, self.candidates_box,
            pn.pane.Markdown("#### Add an effect"),
            pn.Row(self.effect_select, self.name_input),
            self.explain, self.param_box, self.cal_settings,
            pn.Row(self.calibrate_btn, self.simulate_btn),
            self.result_box,
        ]

    def _method_changed(self, *_: Any) -> None:
        """The global search's inputs are editable only while the global search is chosen."""
        for widget in self.global_inputs:
            widget.disabled = not self.state.global_search

    def _show_estimates(self) -> None:
        """The cost of the next diagnosis and calibration, in campaign simulations."""
        try:
            n_diag = self.state.diagnosis_simulations()
            n_cal = self.state.calibration_simulations()
        except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
            self.diag_estimate.object = f"cost not known: {html.escape(plain_message(exc, 'cost'))}"
            return
        self.diag_estimate.object = (f"**Run diagnosis** simulates the campaign {n_diag} times at most "
                                     "(each candidate effect parameter over its bounds, one linearised "
                                     "simulation per model parameter, a few refinements)"
                                     + ("; screened, every candidate on 4 sections and only the best "
                                        f"{SCREEN_KEEP} on the others: about half of it." if self.state.screened
                                        else "."))
        how = ("population × generations of differential evolution, the local polish and the final run"
               if self.state.global_search else
               "scan, start point, trust-region steps with their Jacobians, final run; it usually stops "
               "far earlier at its tolerance")
        self.cal_estimate.object = f"**Calibrate** simulates the campaign at most {n_cal} times ({how})."

    def _show_candidates(self) -> None:
        view = self.state.view  # the diagnosis's typed fields (railval.app.views.DiagnosisView)
        cands = view.candidates if view is not None else []
        if not cands and not self.state.verdict:
            self.candidates_box.objects = [pn.pane.Markdown("*No diagnosis yet — press **Run diagnosis**.*")]
            return
        df = pd.DataFrame([{
            "#": i + 1, "candidate": c.name, "kind": c.kind,
            "held-out": round(100 * float(c.held_out_explained), 1),
            "in-sample": round(100 * float(c.explained), 1),
            "plausible": "yes" if c.plausible else "no", "flags": len(c.flags),
            "fitted parameters": ", ".join(f"{k} = {v:.4g}" for k, v in c.parameters.items()),
        } for i, c in enumerate(cands)])
        extra = []
        note = self.state.diagnosis_note
        verdict = self.state.verdict
        if verdict:
            nf = self.state.noise_floor
            head = {"cause": "Cause found", "uncertain": "Uncertain",
                    "none": "No candidate explains the residual"}.get(verdict, verdict)
            text = f"{head}: {note}" + (f" (noise floor {nf:.2f})" if nf is not None and "noise floor" not in note else "")
            extra.append(message(text, {"cause": "success", "uncertain": "warning"}.get(verdict, "danger")))
            if verdict == "none" and view is not None and view.unexplained:
                extra.append(message("Unexplained: " + "; ".join(
                    f"{component} {residual:+.2f}" for component, residual in view.unexplained), "info"))
        elif note:
            extra.append(message(note, "info" if self.state.separable else "warning"))
        extra += self._cause_set(view) + self._lineage() + self._families(view)
        skipped = view.skipped if view is not None else []
        in_config = [s for s in skipped if s.kind == "configuration"]
        candidates = [s for s in skipped if s.kind != "configuration"]
        if in_config:
            extra.append(message("Configuration simulated without (cannot apply to this campaign): " + "; ".join(
                f"{s.name} — {s.reason}" for s in in_config), "warning"))
        if candidates:
            extra.append(message("Left out (cannot apply to this campaign): " + "; ".join(
                f"{s.name} — {s.reason}" for s in candidates), "info"))
        screened = view.screened_out if view is not None else []
        if screened:
            extra.append(message(f"Screened out (simulated on {', '.join(view.screen_sections)} only, not ranked, "
                                 "counted in the noise floor; share of the residual each explains there; untick "
                                 "Screened for every candidate on every section): " + "; ".join(
                                     f"{s.name} {s.reason.split(' on ')[0]}" for s in screened), "info"))
        # the verdict first: a reader must not scroll past 20 candidates to learn how sure it is
        # 890 px in all: fits the main area at 1280 px (what it fixes and worsens: below, per candidate);
        # "#" beside its sort arrow and "measurement" in the kind column shown whole (browser test)
        widths = {"#": 50, "candidate": 165, "kind": 106, "held-out": 92, "in-sample": 104,
                  "plausible": 98, "flags": 68, "fitted parameters": 207}
        # each heading directly above what it names: the candidates' heading and the caption of
        # their shares over their table, after the verdict, the cause set and the families
        ranked_table = [
            pn.pane.Markdown("#### Ranked candidates (effects and model parameters), by the share "
                             "explained on held-out sections"),
            pn.pane.Markdown("Shares of the residual explained, in %: on held-out sections (the "
                             "ranking) and in-sample (all sections).", sizing_mode="stretch_width"),
            table(df, height=40 + 32 * len(df), css_classes=["rv-candidates"], widths=widths,
                  layout="fit_columns")] if cands else []
        self.candidates_box.objects = [
            pn.pane.Markdown("#### Verdict and causes"), *self._run_line(), *extra, *ranked_table,
            *self._earlier_runs(), self.candidate_box,
        ]
        ranked = [c.name for c in cands]
        rest = [e for e in self.state.param.effect.objects if e not in ranked]
        self.state.param.effect.objects = ranked + rest
        self._show_candidate()

    @staticmethod
    def _cause_set(view) -> list:
        """The cause set (each member's added held-out share, the joint share) and the
        candidates it left out, from the diagnosis's view model."""
        if view is None:
            return []
        out, causes, cause_set = [], view.causes, view.cause_set
        if causes:
            out.append(message(
                f"Causes found together ({len(causes)}; share of the residual each adds on held-out "
                "sections): " + ", ".join(f"{c.name} {100 * c.held_out_share:.0f} %" for c in causes)
                + f"; together {100 * cause_set.held_out_explained:.0f} %",
                "success" if len(causes) > 1 else "info"))
        if cause_set.left_out:
            out.append(message("Not in the cause set: " + "; ".join(
                f"{x.name} — {x.reason}" for x in cause_set.left_out), "warning"))
        return out

    @staticmethod
    def _families(view) -> list:
        """Per quantity family: its share of the residual, verdict, best candidate and whether
        its behaviour differs structurally (docs/diagnosis.md "Per family")."""
        fams = view.families if view is not None else []
        if not fams:
            return []
        df = pd.DataFrame([{
            "family": f.title, "share of residual (%)": round(100 * f.share, 1),
            "verdict": f.verdict + (" (structural)" if f.structural else ""),
            "best candidate": f.best or "",
            "held-out (%)": round(100 * f.best_held_out, 1) if f.best_held_out is not None else None,
            # an empty cell would read as missing data: "no" when no structural difference was found
            "structural": ("yes: " + ", ".join(f.structural_quantities) + "; zones "
                           + ", ".join(map(str, f.structural_zones))) if f.structural else "no",
        } for f in fams])
        notes = [message(f"{f.title}: {f.structural_reason}", "warning") for f in fams if f.structural]
        return [pn.pane.Markdown("#### Per quantity family"),
                table(df, height=40 + 32 * len(df), css_classes=["rv-families"]), *notes]

    def _lineage(self) -> list:
        """The diagnoses of the configuration's ancestors (root first: verdict, top cause) and
        what is left of the parent's residual after the calibration (docs/diagnosis.md "Lineage")."""
        view = self.state.view
        if view is None or not view.has_lineage:
            return []
        top = view.candidates[0] if view.candidates else None
        rows = [*view.ancestors, Ancestor(
            view.lineage_configuration, self.state.stored_run.get("id"), view.verdict,
            top.name if top else None, top.held_out_explained if top else None, "this diagnosis")]
        df = pd.DataFrame([{
            "configuration": a.configuration,
            "diagnosis": f"#{a.diagnosis}" if a.diagnosis else a.created_at or "not diagnosed",
            "verdict": a.verdict or "-", "top cause": a.top or "-",
            "held-out (%)": round(100 * a.held_out_explained, 1)
            if a.held_out_explained is not None else None} for a in rows])
        out = [pn.pane.Markdown("#### Lineage of diagnoses (root first)"),
               table(df, height=40 + 32 * len(df), css_classes=["rv-diagnosis-lineage"])]
        if view.lineage_statement:
            level = {"within scatter": "success", "explained": "info", "uncertain": "warning",
                     "beyond library": "danger"}.get(view.lineage_status, "info")
            out.insert(0, message("After calibration: " + view.lineage_statement, level))
        return out

    def _run_line(self) -> list:
        """Which stored run is shown: when, with which settings, how long it took."""
        if not self.state.stored_run:
            return []
        run = StoredDiagnosis.of(self.state.stored_run)
        text = (f"Stored diagnosis of {run.created_at.replace('T', ' ')} UTC "
                f"({run.values_per_parameter} values per parameter, "
                f"{run.candidates_text}; computed in {run.seconds:.0f} s"
                f"{', reused without simulating' if run.reused else ''}).")
        if run.current is False:
            return [message(text + " The signals or sections changed since: run the diagnosis again.", "warning")]
        return [pn.pane.Markdown(html.escape(text), css_classes=["rv-stored-run"])]

    def _earlier_runs(self) -> list:
        """Every stored diagnosis of the configuration (newest first)."""
        rows = [StoredDiagnosis.of(r) for r in self.state.runs]
        if len(rows) < 2:
            return []
        df = pd.DataFrame([{
            "time (UTC)": r.created_at.replace("T", " "),
            "values per parameter": r.values_per_parameter,
            "candidates": r.candidates_text,
            "top candidate": r.top,
            "explained (%)": round(100 * r.explained, 1) if r.explained is not None else None,
            "separable": "yes" if r.separable else "no",
            "data current": "yes" if r.current else "no (signals changed)",
            "seconds": round(r.seconds, 1)} for r in rows])
        return [pn.pane.Markdown("#### Earlier diagnoses of this configuration"),
                table(df, height=40 + 32 * min(len(df), 8), css_classes=["rv-diagnosis-runs"])]

    def _show_candidate(self) -> None:
        """The chosen effect (the top candidate unless another is chosen): why, its signature
        per quantity group, and where the residual lies now and after adding it."""
        view = self.state.view
        cands = view.candidates if view is not None else []
        cand = view.candidate(self.state.effect) if view is not None else None
        if cand is None and cands:
            cand = cands[0]  # the top candidate unless another is chosen
        if cand is None:
            self.candidate_box.objects = []
            return
        rank = cands.index(cand) + 1
        items: list[Any] = [
            pn.pane.Markdown(f"#### Candidate {rank}: {html.escape(cand.name)} — explains "
                             f"{100 * float(cand.explained):.1f} % of the residual"),
            pn.pane.Markdown(f"**Why {html.escape(cand.name)}?** {html.escape(cand.explanation)}",
                             sizing_mode="stretch_width"),
            *([pn.pane.Markdown(f"**Fitted value** {cand.fitted:.4g} (interval: bootstrap over sections 5–95 %, widened to the values fitted on "
                                f"each held-out fold: "
                                f"{cand.fitted_ci[0]:.4g}–{cand.fitted_ci[1]:.4g})"
                                + (f"; the model's value {cand.reference:.4g}" if cand.reference else ""),
                                sizing_mode="stretch_width")]
              if all(np.isfinite(cand.fitted_ci)) else []),
            pn.pane.Markdown(f"**Fixes** (quantity groups whose residual falls by a fifth or more): "
                             f"{html.escape(', '.join(cand.fixes) or 'none')}. **Worsens**: "
                             f"{html.escape(', '.join(cand.worsens) or 'none')}.",
                             sizing_mode="stretch_width"),
            *[message(str(f), "warning") for f in cand.flags],
            pn.pane.HTML(signature_chart(cand.name, cand.group_change), css_classes=["rv-signature"],
                         styles={"overflow-x": "auto"}, sizing_mode="stretch_width"),
        ]
        where = self.state.where(cand.name)
        if where:
            (q_now, p_now), (q_after, p_after) = where["now"], where["after"]
            after = f"with {cand.name} (fitted)"
            items += [
                pn.pane.Markdown("**Where the model fails, and what is left with the candidate** — mean "
                                 "normalised D_v per quantity and EN 14363 zone (positions averaged); the "
                                 "colour scale is fixed (±2, as on the dashboard): red = simulation above "
                                 "the measurement, blue = below.", sizing_mode="stretch_width"),
                pn.Row(where_map(q_now, f"{self.app.configuration} now"), where_map(q_after, after),
                       sizing_mode="stretch_width", css_classes=["rv-where"]),
            ]
            if p_now.rows:
                items += [
                    pn.pane.Markdown("Car body accelerations per frequency band: log2 of the PSD ratio "
                                     "simulation / measurement (+1 = twice the power; scale fixed at ±1).",
                                     sizing_mode="stretch_width"),
                    pn.Row(where_map(p_now, "car body PSD bands now", psd=True, height=200),
                           where_map(p_after, after, psd=True, height=200), sizing_mode="stretch_width"),
                ]
        self.candidate_box.objects = items

    def _show_effect(self) -> None:
        eff = getattr(self, "_catalogue", {}).get(self.state.effect)
        self._param_widgets = {}
        if eff is None:
            self.explain.object = ""
            self.param_box.objects = []
            return
        self.explain.object = f"**{html.escape(str(eff['title']))}** — {html.escape(str(eff['explanation']))}"
        chosen = self.state.view.candidate(eff["name"]) if self.state.view is not None else None
        fitted = chosen.parameters if chosen is not None else {}
        widgets = []
        for p in eff["parameters"]:
            lo, hi = p["bounds"]
            value = fitted.get(p["name"], p["default"])
            w = pn.widgets.FloatInput(name=f"{p['name']} ({p['unit']})" if p["unit"] else p["name"],
                                      value=None if value is None else float(value),
                                      start=lo, end=hi, width=200)
            self._param_widgets[p["name"]] = w
            widgets.append(w)
        self.param_box.objects = [pn.FlexBox(*widgets)] if widgets else []

    def _show_results(self) -> None:
        """Parent vs current configuration dashboards and the lineage chart."""
        config = self.app.configuration
        ov = self.app.overview
        parent = next((c.parent for c in (ov.configurations if ov else []) if c.name == config), None)
        try:
            lineage = self.state.lineage_errors(config)
        except Exception as exc:  # noqa: BLE001 - UI boundary: shown in the status area
            self.result_box.objects = [message(f"lineage not available: {plain_message(exc, 'lineage')}", "danger")]
            return
        items: list[Any] = []
        summary = self._last_result_text(config)
        if summary:
            items.append(message(summary, "success"))
        items.append(pn.pane.HoloViews(plots.lineage_chart(lineage), sizing_mode="stretch_width"))
        if parent is not None:
            left, _, _ = validation_view(self.dash, parent, height=260, compact=True)
            right, _, _ = validation_view(self.dash, config, height=260, compact=True)
            items += [pn.pane.Markdown(f"#### Parent {html.escape(parent)} beside {html.escape(config)}"),
                      pn.Row(pn.Column(pn.pane.Markdown(f"**{html.escape(parent)}** (parent)"), left,
                                       sizing_mode="stretch_width"),
                             pn.Column(pn.pane.Markdown(f"**{html.escape(config)}**"), right,
                                       sizing_mode="stretch_width"),
                             sizing_mode="stretch_width")]
        self.result_box.objects = items

    def _last_result_text(self, config: str) -> str:
        """One line on the job that made ``config``: fitted values, objective, simulations."""
        if not self.state.last_result:
            return ""
        r = CalibrationOutcome.of(self.state.last_result)
        if r.configuration != config:
            return ""
        if r.kind == "re-simulation":
            text = f"{config}: {r.parent} + {r.effect} re-simulated with the parameters set."
            if r.diagnosis_parameters:
                text += (f" Its verdict is in-sample: {', '.join(r.diagnosis_parameters)} took the values the "
                         f"diagnosis fitted on all {r.diagnosis_sections} sections, so no held-out "
                         "check is possible for it; for one, tick 'Hold out one section per zone' in the "
                         "calibration settings and press 'Add, calibrate & re-simulate'.")
            return text
        fitted = ", ".join(f"{k.split('.', 1)[-1]} = {v:.4g}{' ' + unit_label(unit) if unit else ''}"
                           for k, v, unit in r.fitted)
        objective = f"{r.objective:.3g}" if r.objective is not None else "?"
        obj = (f"at the start values {r.objective_start:.3g}, fitted {objective}" if r.objective_start is not None
               else f"fitted {objective}")
        text = (f"{config}: {r.effect} calibrated from {r.parent}: {fitted}. Objective (Σ over "
                f"quantities of the squared worst normalised error) {obj}; "
                f"{r.simulations} campaign simulations. "
                + "".join(f"{line[0].upper()}{line[1:]}. " for line in (r.tolerance, r.start) if line)
                ).rstrip()
        if r.in_sample:
            text += " Its verdict is in-sample (fitted on all sections)."
        elif r.held_out_sections:
            text += f" Fitted without sections {', '.join(r.held_out_sections)} (held out)."
            if r.held_out_max_error is not None:
                text += (f" On the held-out sections the largest normalised error went from "
                         f"{r.held_out_max_error[0]:.2f} to {r.held_out_max_error[1]:.2f}.")
        for f in r.flags:
            if f.startswith("note:"):
                text += f" Note: {f[5:].strip()}."
            elif not f.startswith("in-sample"):
                text += f" Warning: {f}."
        return text + f" Next: diagnose {config} — press **Run diagnosis**."
