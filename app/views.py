"""What a validation looks like to a reader: one view model for the dashboard, the report and
the CLI's text output (docs/design.md §2, §8).

Every view reads the same core objects (:class:`railval.core.validation.ValidationResult`,
its :class:`~railval.core.validation.Coverage` and
:class:`~railval.core.validation.QuantityResult` records) through :class:`ValidationView`;
nothing guesses dictionary keys. Quantity rows are each quantity's
:meth:`QuantityResult.to_dict` — the very fields of ``railval validate --json`` — and the
drill-down carries core's normalised column ``D_norm`` (D_v / std limit) unchanged. A field
renamed in core therefore raises here (``KeyError``/``AttributeError``) instead of
emptying a table; ``tests/test_views.py`` holds that.

No UI library is imported: pages turn these rows into widgets, the report into HTML.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from railval.app.services.calibration_plan import start_text, tolerance_text
from railval.core.coverage import Coverage
from railval.core.en14363 import PROCESSING_VERSION
from railval.core.validation import STD_DEFINITION, QuantityResult, ValidationResult

if TYPE_CHECKING:  # the diagnosis package is imported by the services that run it
    from railval.core.diagnosis import DiagnosisResult, TrustedCandidate


@dataclass(frozen=True)
class InSample:
    """A verdict partly on the sections a fit of the lineage used — a calibration, or a
    diagnosis whose fitted parameters a configuration took — decided in one place,
    ``railval.app.services.validation.calibration_provenance``."""

    calibrated_in: tuple[str, ...]
    fit_sections: tuple[str, ...]
    held_out_sections: tuple[str, ...]
    fitted_by: tuple[tuple[str, str], ...] = ()
    held_out_check: str = ""

    @classmethod
    def of(cls, info: Mapping[str, Any]) -> InSample | None:
        """From a result's ``info``; None when the verdict is not in-sample (or the result
        was computed without provenance)."""
        if not info.get("in_sample"):
            return None
        return cls(tuple(info["calibrated_in"]), tuple(info["fit_sections"]),
                   tuple(info["held_out_sections"]),
                   tuple(sorted((info.get("fitted_by") or {}).items())),
                   str(info.get("held_out_check") or ""))

    def note(self) -> str:
        """"X was calibrated on n of these sections" (or "X's parameters were fitted by a
        diagnosis on n of these sections")."""
        by = dict(self.fitted_by)
        parts = [f"{c}'s parameters were fitted by a diagnosis" if by.get(c) == "diagnosis"
                 else f"{c} was calibrated" for c in self.calibrated_in]
        return f"{', '.join(parts)} on {len(self.fit_sections)} of these sections"

    def to_dict(self) -> dict[str, Any]:
        """The provenance as ``railval validate --json`` prints it (``in_sample_provenance``)."""
        return {"fitted_in": list(self.calibrated_in), "fitted_by": dict(self.fitted_by),
                "fit_sections": list(self.fit_sections),
                "held_out_sections": list(self.held_out_sections),
                "held_out_check": self.held_out_check, "note": self.note()}


@dataclass(frozen=True)
class ValidationView:
    """One configuration's validation as every view shows it."""

    result: ValidationResult

    @property
    def validated(self) -> bool:
        return bool(self.result.validated)

    @property
    def coverage(self) -> Coverage:
        return self.result.coverage

    @property
    def quantities(self) -> list[dict[str, Any]]:
        """One row per quantity: the fields of ``railval validate --json``."""
        return [q.to_dict() for q in self.result.quantities.values()]

    def quantity(self, qid: str) -> QuantityResult:
        return self.result.quantities[qid]

    @property
    def failing(self) -> list[str]:
        """Quantities outside their limits, registry order."""
        return [qid for qid, q in self.result.quantities.items() if not q.passed]

    @property
    def sensitive_quantities(self) -> list[str]:
        """Quantities whose pass/fail another reading of the open definitions flips."""
        return [qid for qid, q in self.result.quantities.items() if q.definition_sensitive]

    @property
    def verdict_sensitive(self) -> bool | None:
        """True when another reading flips the verdict; None without alternatives."""
        return self.result.definition_sensitive

    @property
    def in_sample(self) -> InSample | None:
        return InSample.of(self.result.info)

    @property
    def info(self) -> dict[str, Any]:
        return self.result.info

    @property
    def warnings(self) -> list[str]:
        return list(self.result.warnings)

    @property
    def processing_version(self) -> str:
        return PROCESSING_VERSION

    @property
    def std_definition(self) -> str:
        return STD_DEFINITION

    @property
    def pairs(self):
        """``ValidationResult.pairs`` (quantity, section, zone, position, M, S, D, D_norm)."""
        return self.result.pairs

    def drilldown(self, quantity: str, top: int | None = None) -> list[dict[str, Any]]:
        """Pairs of one quantity, largest |D_v| first: section, position, zone, M_v, S_v,
        D_v and ``norm`` = core's ``D_norm`` (D_v / std limit)."""
        pairs = self.result.pairs
        sub = pairs[pairs["quantity"] == quantity]
        rows = [{"quantity": quantity, "section": str(r.section), "position": str(r.position),
                 "zone": int(r.zone), "M_v": float(r.M), "S_v": float(r.S), "D_v": float(r.D),
                 "norm": float(r.D_norm)} for r in sub.itertuples(index=False)]
        rows.sort(key=lambda r: -abs(r["D_v"]))
        return rows if top is None else rows[:top]

    def definition_rows(self) -> list[dict[str, Any]]:
        """Per quantity that another reading of the open definitions can change (percentile
        method, sliding-window grid and mean; docs/validation.md): verdict, whether some
        reading flips it, which, and the range of mean/limit and std/limit over the readings."""
        out = []
        for qid, q in self.result.quantities.items():
            alts = q.alternatives or []
            if not alts:
                continue
            means = [a["mean_norm"] for a in alts if a["mean_norm"] is not None]
            stds = [a["std_norm"] for a in alts if a["std_norm"] is not None]
            flips = [a for a in alts if a["flips"]]
            mean_norm = q.to_dict()["mean_norm"]
            out.append({
                "quantity": qid,
                "verdict": "pass" if q.passed else "FAIL",
                "definition_sensitive": bool(q.definition_sensitive),
                "readings": len(alts),
                "mean/limit": mean_norm,
                "mean/limit other readings": (min(means), max(means)) if means else None,
                "std/limit other readings": (min(stds), max(stds)) if stds else None,
                "flipped by": "" if not flips else (
                    f"{'passes' if flips[0]['pass'] else 'fails'} with {flips[0]['label']}"
                    + (f" (and {len(flips) - 1} more of {len(alts)} readings)" if len(flips) > 1 else "")),
            })
        return out

    @property
    def definitions_available(self) -> bool:
        """False when the values carried no alternative readings (plain dictionaries)."""
        return self.verdict_sensitive is not None or bool(self.definition_rows())

    def supplementary_rows(self) -> list[dict[str, Any]]:
        """The supplementary results (bogie-frame and PSD-band quantities,
        :func:`railval.core.supplementary.supplementary_results`), one row each; they never
        change the verdict."""
        supp = self.result.supplementary
        return [dict(r) for r in supp["quantities"]] if supp else []


def view_of(result: ValidationResult) -> ValidationView:
    """The view model of a validation result."""
    if not isinstance(result, ValidationResult):
        raise TypeError(f"a ValidationResult is needed, got {type(result).__name__}")
    return ValidationView(result)


# -- the diagnosis ----------------------------------------------------------------------
# The dict-shaped parts of a DiagnosisResult (families, cause set, lineage, …) are read here,
# once, into typed rows: pages, state and CLI read the rows' fields, so a renamed key of the
# documented ``railval diagnose --json`` contract (docs/diagnosis.md) raises here.


@dataclass(frozen=True)
class Named:
    """A candidate named with a reason: skipped, left out of or passed over by the cause set."""

    name: str
    reason: str
    kind: str = ""

    @classmethod
    def of(cls, d: Mapping[str, Any]) -> Named:
        return cls(str(d["name"]), str(d["reason"]), str(d.get("kind") or ""))


@dataclass(frozen=True)
class Cause:
    """One member of the cause set: what adding it raised the held-out share by."""

    name: str
    kind: str
    parameter: str
    fitted: float | None
    held_out_share: float

    @classmethod
    def of(cls, d: Mapping[str, Any]) -> Cause:
        fitted = d.get("fitted")
        return cls(str(d["name"]), str(d["kind"]), str(d.get("parameter") or ""),
                   None if fitted is None else float(fitted), float(d["held_out_share"]))


@dataclass(frozen=True)
class CauseSet:
    """The cause set's joint held-out share and the candidates it left out or passed over."""

    held_out_explained: float
    left_out: tuple[Named, ...]
    passed_over: tuple[Named, ...]

    @classmethod
    def of(cls, d: Mapping[str, Any] | None) -> CauseSet:
        d = d or {}
        return cls(float(d.get("held_out_explained") or 0.0),
                   tuple(Named.of(x) for x in d.get("left_out") or []),
                   tuple(Named.of(x) for x in d.get("passed_over") or []))


@dataclass(frozen=True)
class FamilyRow:
    """One quantity family: its share of the residual, verdict, best candidate and whether
    the misfit is structural (no candidate of the library can remove it)."""

    title: str
    share: float
    verdict: str
    best: str | None
    best_held_out: float | None
    structural: bool
    structural_reason: str
    #: where the structural misfit lies (empty unless ``structural``)
    structural_quantities: tuple[str, ...] = ()
    structural_zones: tuple[int, ...] = ()

    @classmethod
    def of(cls, d: Mapping[str, Any]) -> FamilyRow:
        top = d["top"][0] if d["top"] else None
        return cls(str(d["title"]), float(d["share"]), str(d["verdict"]),
                   None if top is None else str(top["name"]),
                   None if top is None else float(top["held_out_explained"]),
                   bool(d["structural"]["flag"]), str(d["structural"]["reason"]),
                   tuple(str(q) for q in d["structural"].get("quantities") or ()),
                   tuple(d["structural"].get("zones") or ()))


@dataclass(frozen=True)
class Ancestor:
    """A configuration of the lineage with its newest diagnosis (None: not diagnosed)."""

    configuration: str
    diagnosis: int | None
    verdict: str | None
    top: str | None
    #: the share the top candidate explains on held-out sections (None: not diagnosed)
    held_out_explained: float | None = None
    created_at: str = ""

    @classmethod
    def of(cls, d: Mapping[str, Any]) -> Ancestor:
        held = d.get("held_out_explained")
        return cls(str(d["configuration"]), d["diagnosis"], d["verdict"], d["top"],
                   None if held is None else float(held), str(d.get("created_at") or ""))


@dataclass(frozen=True)
class StoredDiagnosis:
    """One stored diagnosis run as the Diagnose page lists it
    (:func:`railval.app.services.diagnosis.diagnosis_runs`, or the shown run's
    :func:`railval.app.services.stored_runs.run_info` without the ranking's fields)."""

    created_at: str
    seconds: float
    values_per_parameter: int | None
    #: the candidates chosen for the run; None: every candidate
    chosen: tuple[str, ...] | None
    reused: bool = False
    #: whether the signals and sections are unchanged since the run (None: not known)
    current: bool | None = None
    top: str = ""
    explained: float | None = None
    separable: bool = True
    verdict: str | None = None
    #: the candidates a screened run kept (``screen``, docs/diagnosis.md); None: not screened
    screened: int | None = None

    @classmethod
    def of(cls, d: Mapping[str, Any]) -> StoredDiagnosis:
        settings = d.get("settings") or {}
        screen = (settings.get("options") or {}).get("screen")
        chosen = settings.get("effects")
        values = settings.get("values_per_parameter")
        explained = d.get("explained")
        current = d.get("current")
        return cls(str(d.get("created_at") or ""), float(d.get("seconds") or 0.0),
                   None if values is None else int(values), None if chosen is None else tuple(chosen),
                   bool(d.get("reused")), None if current is None else bool(current), str(d.get("top") or ""),
                   None if explained is None else float(explained), bool(d.get("separable", True)),
                   d.get("verdict"), None if screen is None else int(screen))

    @property
    def candidates_text(self) -> str:
        """The candidates the run tried, as a reader sees them."""
        n = len(self.chosen or ())
        text = "every candidate" if self.chosen is None else f"{n} chosen candidate{'s' if n != 1 else ''}"
        return text + (f", screened to the {self.screened} best" if self.screened else "")


@dataclass(frozen=True)
class CalibrationOutcome:
    """The last calibration or re-simulation the Diagnose page started (``to_dict()`` of its
    result with ``kind``, ``effect``, ``configuration`` and ``parent`` added by the state):
    what the page's one-line summary reads."""

    kind: str
    configuration: str
    parent: str
    effect: str
    #: (name, value, unit) of every fitted parameter
    fitted: tuple[tuple[str, float, str], ...] = ()
    objective: float | None = None
    objective_start: float | None = None
    simulations: int = 0
    in_sample: bool = False
    held_out_sections: tuple[str, ...] = ()
    #: the largest normalised error on the held-out sections: (parent's, fitted configuration's)
    held_out_max_error: tuple[float, float] | None = None
    flags: tuple[str, ...] = ()
    #: the lines on the tolerance reached and where the fit started ('' when not known)
    tolerance: str = ""
    start: str = ""
    #: a re-simulation with values a stored diagnosis fitted: the parameters and sections
    diagnosis_parameters: tuple[str, ...] = ()
    diagnosis_sections: int = 0

    @classmethod
    def of(cls, d: Mapping[str, Any]) -> CalibrationOutcome:
        units = d.get("units") or {}
        fitted = tuple((str(k), float(v), str(units.get(k) or "")) for k, v in (d.get("parameters") or {}).items())
        held = ((d.get("lineage") or [{}])[-1] or {}).get("held_out") or {}
        pair = ((float(held["parent_max_error"]), float(held["max_error"]))
                if held.get("max_error") is not None and held.get("parent_max_error") is not None else None)
        fit = d.get("calibration") or {}
        by_diagnosis = fit.get("fitted_by") == "diagnosis"
        calibrated = d.get("kind") != "re-simulation"
        return cls(str(d.get("kind") or ""), str(d.get("configuration") or ""), str(d.get("parent") or ""),
                   str(d.get("effect") or ""), fitted,
                   None if d.get("objective") is None else float(d["objective"]),
                   None if d.get("objective_start") is None else float(d["objective_start"]),
                   int(d["simulations"] if d.get("simulations") is not None else (d.get("n_evaluations") or 0) + 2), bool(d.get("in_sample")),
                   tuple(str(x) for x in d.get("held_out_sections") or ()), pair,
                   tuple(str(f) for f in d.get("flags") or ()),
                   tolerance_text(d) if calibrated else "", start_text(d) if calibrated else "",
                   tuple(str(x) for x in fit.get("parameters") or ()) if by_diagnosis else (),
                   len(fit.get("fit_sections") or ()) if by_diagnosis else 0)


@dataclass(frozen=True)
class DiagnosisView:
    """One diagnosis as every view shows it: the typed fields of
    :class:`railval.core.diagnosis.DiagnosisResult` with its dict-shaped parts read into rows
    (:class:`Cause`, :class:`CauseSet`, :class:`FamilyRow`, :class:`Named`, :class:`Ancestor`)."""

    result: DiagnosisResult

    @property
    def verdict(self) -> str:
        return str(self.result.verdict)

    @property
    def note(self) -> str:
        return str(self.result.note)

    @property
    def noise_floor(self) -> float:
        return float(self.result.noise_floor)

    @property
    def candidates(self) -> list[TrustedCandidate]:
        """The ranked :class:`railval.core.diagnosis.TrustedCandidate` objects."""
        return list(self.result.candidates)

    def candidate_rows(self) -> list[dict[str, Any]]:
        """The candidates as the page's tables take them: each one's documented JSON fields
        with its fitted signature (``TrustedCandidate.to_dict(with_signatures=True)``)."""
        return [c.to_dict(with_signatures=True) for c in self.result.candidates]

    def residual_row(self) -> dict[str, Any]:
        """The residual as the page's plots take it: its norm, group norms, labels, values
        and components (the ``residual`` of ``DiagnosisResult.to_dict(with_signatures=True)``)."""
        residual = self.result.residual
        return {"norm": math.sqrt(residual.norm2()), "groups": residual.group_norms(),
                **residual.to_dict()}

    def candidate(self, name: str | None) -> TrustedCandidate | None:
        """The ranked candidate called ``name`` (None when there is none)."""
        return next((c for c in self.result.candidates if c.name == name), None)

    @property
    def causes(self) -> list[Cause]:
        return [Cause.of(c) for c in self.result.causes or []]

    @property
    def cause_set(self) -> CauseSet:
        return CauseSet.of(self.result.cause_set)

    @property
    def families(self) -> list[FamilyRow]:
        return [FamilyRow.of(f) for f in self.result.families or []]

    @property
    def skipped(self) -> list[Named]:
        return [Named.of(s) for s in self.result.skipped or []]

    @property
    def screened_out(self) -> list[Named]:
        """The candidates a screened diagnosis did not rank (``result.screen``), each with the
        share of the residual it explains on the screen sections (in-sample)."""
        return [Named(str(x["name"]), f"{100 * float(x['explained_on_screen']):.1f} % on the screen",
                      str(x.get("kind") or ""))
                for x in (self.result.screen or {}).get("screened_out") or []]

    @property
    def screen_sections(self) -> list[str]:
        """The sections every candidate of a screened diagnosis was simulated on."""
        return [str(s) for s in (self.result.screen or {}).get("sections") or []]

    @property
    def unexplained(self) -> list[tuple[str, float]]:
        """(component, residual) of what the best candidate leaves (largest first)."""
        return [(str(u["component"]), float(u["residual"])) for u in self.result.unexplained]

    @property
    def statements(self) -> list[tuple[str, str]]:
        """Input-side statements as (kind, text)."""
        return [(str(s["kind"]), str(s["text"])) for s in self.result.statements or []]

    @property
    def next_text(self) -> str:
        """The next step's sentence ('' when none)."""
        return str((self.result.next_step or {}).get("text") or "")

    @property
    def has_lineage(self) -> bool:
        """The configuration has a lineage to show (it was derived from another)."""
        return bool(self.result.lineage)

    @property
    def ancestors(self) -> list[Ancestor]:
        return [Ancestor.of(a) for a in (self.result.lineage or {}).get("ancestors") or []]

    @property
    def lineage_configuration(self) -> str:
        return str((self.result.lineage or {}).get("configuration") or "")

    @property
    def lineage_status(self) -> str:
        """The statement's status: within scatter, explained, uncertain or beyond library."""
        return str(((self.result.lineage or {}).get("statement") or {}).get("status") or "")

    @property
    def lineage_statement(self) -> str:
        """What is left after the calibration, read against the parent's diagnosis."""
        return str(((self.result.lineage or {}).get("statement") or {}).get("text") or "")


def diagnosis_view_of(result: DiagnosisResult) -> DiagnosisView:
    """The view model of a diagnosis result."""
    if not (hasattr(result, "candidates") and hasattr(result, "verdict")):
        raise TypeError(f"a DiagnosisResult is needed, got {type(result).__name__}")
    return DiagnosisView(result)
