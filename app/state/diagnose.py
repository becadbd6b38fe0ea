"""State of the Diagnose & model workshop page: ranked candidates, chosen effect,
calibrate/re-simulate job in a background thread with progress, lineage of the error."""

from __future__ import annotations

from typing import Any

import numpy as np
import param

from railval.app.services.calibration_plan import calibration_simulations
from railval.app.services.diagnosis import diagnosis_simulations
from railval.app.state.app import AppState
from railval.app.views import DiagnosisView, diagnosis_view_of
from railval.core.diagnosis import PatternGrid, pattern_grids
from railval.core.diagnosis.screen import SCREEN_KEEP
from railval.core.validation import normalised_errors


class DiagnoseState(param.Parameterized):
    effect = param.Selector(default=None, objects=[], allow_None=True)
    new_name = param.String(default="")
    name_edited = param.Boolean(default=False, doc=(
        "the user typed the new configuration's name; until then it follows the chosen effect"))
    candidates = param.List(default=[])
    view = param.ClassSelector(class_=DiagnosisView, default=None, allow_None=True, doc=(
        "the shown diagnosis as its view model (typed fields; None before a diagnosis)"))
    parameters = param.Dict(default={}, doc="manually set parameters of the chosen effect")
    last_new_configuration = param.String(default="")
    last_result = param.Dict(default={}, doc="to_dict() of the last calibration or re-simulation")
    diagnosis_run = param.Dict(default={}, doc="settings and simulation count of the last diagnosis")
    residual = param.Dict(default={}, doc="residual pattern of the diagnosed configuration (labels, values)")
    diagnosis_note = param.String(default="", doc="separability note of the diagnosis")
    separable = param.Boolean(default=True, doc="the two best candidates are told apart")
    stored_run = param.Dict(default={}, doc=(
        "the stored run the shown diagnosis comes from (time, settings, reused, current)"))
    runs = param.List(default=[], doc="stored diagnoses of the configuration, newest first")
    verdict = param.String(default="", doc="verdict of the last diagnosis: cause, uncertain or none")
    noise_floor = param.Number(default=None, allow_None=True, doc="noise floor of the last diagnosis")
    unexplained = param.List(default=[], doc="what the best candidate leaves unexplained (verdict none)")
    causes = param.List(default=[], doc="the cause set: name, kind, parameter, fitted, held_out_share")
    cause_set = param.Dict(default={}, doc="the cause set's held-out share, whether the rest is scatter, why it stopped")
    families = param.List(default=[], doc="per quantity family: verdict, top candidates, structural flag")
    lineage = param.Dict(default={}, doc=(
        "the diagnoses of the configuration's ancestors and what is left after its calibration"))
    skipped = param.List(default=[], doc=(
        "candidates left out because they cannot apply to the campaign: name, kind, one-line reason"))
    # diagnosis settings (app.services.diagnosis.diagnose)
    candidate_effects = param.ListSelector(default=[], objects=[], doc=(
        "effects the diagnosis tries; none chosen = every effect the configuration lacks"))
    values_per_parameter = param.Integer(default=3, bounds=(2, 9), doc=(
        "values of each effect parameter simulated over its bounds (plus its default)"))
    # calibration settings (app.services.diagnosis.calibrate → core.calibration.calibrate)
    fit_parameters = param.ListSelector(default=[], objects=[], doc=(
        "parameters of the chosen effect to fit; none chosen = all; the others keep the values set"))
    screened = param.Boolean(default=True, doc=(
        "screened diagnosis (the default): every candidate on a few sections first, the best SCREEN_KEEP "
        "on all (docs/diagnosis.md \"Screened diagnosis\"); off: every candidate on every section"))
    global_search = param.Boolean(default=False, doc=(
        "calibrate by a global search (differential evolution + local polish) instead of the local "
        "trust-region fit from the diagnosis's values; population, generations and polish apply to it only"))
    popsize = param.Integer(default=5, bounds=(2, 40), doc="differential evolution: population per parameter")
    maxiter = param.Integer(default=5, bounds=(1, 200), doc="differential evolution: generations at most")
    polish_maxfev = param.Integer(default=20, bounds=(0, 1000), doc="local polish: simulations at most")
    seed = param.Integer(default=0, bounds=(0, None), doc="random seed of the global search")
    split = param.Boolean(default=False, doc=(
        "fit on part of the sections and validate on the others (one section per zone and fold held "
        "out); otherwise the verdict on the campaign is in-sample"))

    def __init__(self, app: AppState, **params):
        super().__init__(**params)
        self.app = app
        self._naming = False
        self.app.param.watch(lambda e: self._reset(), ["campaign", "configuration"])
        self.param.watch(lambda e: self._effect_changed(), ["effect"])
        self.param.watch(self._name_typed, ["new_name"])
        self.load_stored()

    def load_stored(self) -> None:
        """Show the newest stored diagnosis of the configuration (a reload, a second tab or
        another user sees it) and list the earlier ones."""
        app = self.app
        if not app.campaign or not app.configuration:
            return
        self.runs = app.backend.diagnosis_runs(app.campaign, app.configuration)
        latest = app.backend.latest_diagnosis(app.campaign, app.configuration) if self.runs else None
        if latest is not None:
            self.show_diagnosis(latest)

    def _reset(self) -> None:
        self.candidates = []
        self.view = None
        self.verdict = ""
        self.skipped = []
        self.causes = []
        self.families = []
        self.lineage = {}
        self.residual = {}
        self.stored_run = {}
        self.diagnosis_run = {}
        self.runs = []
        if self.effect is not None and self.effect not in self.available_effects():
            self.effect = None  # already part of the newly selected configuration
        self.name_edited = False
        self._suggest_name()
        self.load_stored()

    def _name_typed(self, event) -> None:
        if not self._naming:  # a change that did not come from _suggest_name: the user typed it
            self.name_edited = bool(event.new.strip())

    def _suggest_name(self) -> None:
        """Let the name follow the chosen effect until the user edits it."""
        if self.name_edited:
            return
        self._naming = True
        try:
            self.new_name = self.suggested_name()
        finally:
            self._naming = False

    def where(self, effect: str | None = None) -> dict[str, PatternGrid]:
        """Where the configuration fails and what ``effect`` (a ranked candidate, default
        the selected effect) leaves: the residual pattern now and after adding the fitted
        candidate (residual − its signature), each as a quantity × zone grid and a PSD
        band grid (:func:`pattern_grids`). Empty before a diagnosis."""
        effect = effect or self.effect
        cand = self.view.candidate(effect) if self.view is not None else None
        residual = self.view.result.residual if self.view is not None else None
        if cand is None or residual is None or residual.components is None:
            return {}
        now = residual.values
        after = now - cand.signature.values
        return {"now": pattern_grids(residual.components, now),
                "after": pattern_grids(residual.components, after)}

    def _effect_changed(self) -> None:
        eff = next((e for e in self.effect_catalogue() if e["name"] == self.effect), None)
        names = [p["name"] for p in eff["parameters"]] if eff else []
        self.param.fit_parameters.objects = names
        self.fit_parameters = []
        self._suggest_name()

    def refresh_choices(self) -> None:
        """Candidate effects to choose from: those the configuration lacks (a choice no
        longer available is dropped)."""
        available = self.available_effects()
        self.param.candidate_effects.objects = available
        self.candidate_effects = [e for e in self.candidate_effects if e in available]

    def diagnosis_simulations(self) -> int:
        """Campaign simulations the diagnosis will run with the current settings (at most: the
        refinement of parameter candidates runs only where needed). Chosen candidate effects
        restrict the diagnosis to them; none chosen = every effect lacking and the template's
        parameters."""
        effects = self.candidate_effects or self.available_effects()
        ov = self.app.overview
        template = str(ov.vehicle.get("template") or "coach") if ov else None
        return diagnosis_simulations(effects, self.values_per_parameter, template,
                                     parameters=not self.candidate_effects)

    def calibration_method(self) -> str:
        """``local`` (the trust-region fit) or ``global`` (differential evolution + polish)."""
        return "global" if self.global_search else "local"

    def calibration_simulations(self) -> int:
        """Upper bound of the campaign simulations the page's calibration runs (the local fit,
        or the global search with the page's population, generations and polish):
        :func:`railval.app.services.calibration_plan.calibration_simulations`, the estimate
        the CLI announces too."""
        n = len(self.fit_parameters or self.param.fit_parameters.objects) or 1
        return calibration_simulations(n, self.calibration_method(), popsize=self.popsize,
                                       maxiter=self.maxiter, polish_maxfev=self.polish_maxfev)

    def effect_catalogue(self) -> list[dict[str, Any]]:
        return self.app.backend.effects()

    def available_effects(self) -> list[str]:
        """Effects not yet in the current configuration."""
        ov = self.app.overview
        present = set()
        for c in ov.configurations if ov else []:
            if c.name == self.app.configuration:
                present = set(c.effects)
        names = [e["name"] for e in self.effect_catalogue()]
        return [n for n in names if n not in present]

    def suggested_name(self) -> str:
        base = f"{self.app.configuration}+{self.effect}" if self.effect else f"{self.app.configuration}-new"
        existing = set(self.app.param.configuration.objects)
        name, i = base, 2
        while name in existing:
            name, i = f"{base}-{i}", i + 1
        return name

    def run_diagnosis(self, dispatch=None, background=True):
        app = self.app
        campaign, config = app.campaign, app.configuration

        settings = {"values_per_parameter": self.values_per_parameter,
                    "effects": list(self.candidate_effects) or None,
                    **({"screen": SCREEN_KEEP} if self.screened else {})}
        if not app.within_cost_cap("diagnosis", self.diagnosis_simulations()):
            return None

        def work(progress):
            return app.backend.diagnose_and_list(campaign, config, progress=progress, **settings)

        def done(outcome):
            result, self.runs = outcome  # the stored runs listed with it: before the view redraws
            self.show_diagnosis(result)
        return app.run_job("diagnosis", work, done, dispatch=dispatch, background=background,
                           action="diagnose")

    def show_diagnosis(self, result) -> None:
        """Show a diagnosis (computed now or stored, a
        :class:`railval.core.diagnosis.DiagnosisResult`): ranked candidates, residual, verdict,
        families, cause set, candidates left out — from the result's typed fields."""
        view = diagnosis_view_of(result)
        cands = view.candidate_rows()  # the page's tables (with each fitted signature)
        self.residual = view.residual_row()
        note = result.note
        if not result.separable and not note:
            note = "the two best candidates explain nearly the same; see the evidence"
        self.diagnosis_note = note
        self.separable = bool(result.separable)
        self.verdict = result.verdict
        self.noise_floor = result.noise_floor
        self.unexplained = list(result.unexplained)
        self.skipped = list(result.skipped or [])
        self.causes = list(result.causes or [])
        self.cause_set = dict(result.cause_set or {})
        self.families = list(result.families or [])
        self.lineage = dict(result.lineage or {})
        self.diagnosis_run = {"simulations": result.simulations, "values_per_parameter": result.values_per_parameter,
                              "configuration": result.configuration}
        self.stored_run = dict(result.run or {})
        names = self.available_effects() if cands else []
        ranked = [c.name for c in view.candidates]
        order = ranked + [n for n in names if n not in ranked]
        self.param.effect.objects = order
        if order:  # the top candidate chosen before the ranking is shown
            self.effect = order[0]
            self._suggest_name()
        self.view = view
        self.candidates = cands
        if not cands:  # a diagnosis with nothing to rank (every candidate left out): the page shows why
            self.param.trigger("candidates")

    def run_calibration(self, dispatch=None, background=True, calibrate: bool = True):
        """Add ``effect`` to the configuration, calibrate it (or use ``parameters``),
        re-simulate and store as ``new_name`` whose parent is the current configuration."""
        app = self.app
        if not app.guard("calibrate" if calibrate else "simulate"):
            return None
        campaign, config, effect = app.campaign, app.configuration, self.effect
        # a name the user did not type always names the effect that is added
        name = self.new_name if (self.name_edited and self.new_name.strip()) else self.suggested_name()
        params = dict(self.parameters)
        if effect is not None and effect.startswith("model."):  # a parameter candidate: start at its fitted value
            cand = self.view.candidate(effect) if self.view is not None else None
            params = ({effect[6:]: float(cand.fitted)} if cand is not None and np.isfinite(cand.fitted)
                      else {})
        if effect is None:
            app.set_status("choose an effect to add first", "warning")
            return None

        settings = {"popsize": self.popsize, "maxiter": self.maxiter, "polish_maxfev": self.polish_maxfev,
                    "seed": self.seed, "method": self.calibration_method(), **({"split": True} if self.split else {}),
                    "params": ([f"{effect}.{p}" for p in self.fit_parameters] or None)
                    if not (effect or "").startswith("model.") else None}
        if calibrate and not app.within_cost_cap("calibration", self.calibration_simulations()):
            return None

        def work(progress):
            if calibrate:
                return app.backend.calibrate(campaign, config, effect, name, progress=progress,
                                             start=params or None, **settings)
            return app.backend.simulate(campaign, config, {effect: params or {}}, name, progress=progress)

        def done(result):
            d = result.to_dict() if hasattr(result, "to_dict") else dict(result or {})
            self.last_result = {**d, "kind": "calibration" if calibrate else "re-simulation",
                                "effect": effect, "configuration": name, "parent": config}
            self.last_new_configuration = name
            app.reload_configurations(select=name)
        return app.run_job("calibration" if calibrate else "re-simulation", work, done,
                           dispatch=dispatch, background=background,
                           action="calibrate" if calibrate else "simulate", reserves=(campaign, name))

    def lineage_errors(self, config: str | None = None) -> list[dict[str, Any]]:
        """Along the lineage root → config: the largest normalised error ``max_norm``
        (:func:`railval.core.validation.normalised_errors`, NaN when none is finite) and whether
        the configuration is validated."""
        app = self.app
        config = config or app.configuration
        out = []
        for name in app.backend.lineage(app.campaign, config):
            err = normalised_errors(app.backend.validation(app.campaign, name))
            out.append({"configuration": name,
                        "max_norm": float("nan") if err["max_error"] is None else err["max_error"],
                        "validated": err["validated"]})
        return out
