"""The screened diagnosis against the whole one on the diagnosis trust bench
(:mod:`railval.app.bench.bench_diagnosis_trust` ``--screen K --against-whole``; docs/diagnosis.md
"Screened diagnosis"): per case the whole diagnosis's verdict, top, cause set and noise floor
beside the screened one's, and over the cases how often they agree and how far the floor moved."""

from __future__ import annotations

from typing import Any


def _causes(d: dict) -> list[str]:
    return sorted(c["name"] for c in d.get("causes") or [])


def _top(d: dict) -> str | None:
    return d["candidates"][0]["name"] if d["candidates"] else None


def whole_of(screened: dict, whole: dict, seconds: float) -> dict[str, Any]:
    """The whole diagnosis of a case (``to_dict`` documents) beside its screened one: verdict,
    top, cause set, noise floor, seconds, whether verdict, top and cause set are the same
    (``same``) and how far the noise floor moved (``floor_change`` = screened − whole)."""
    return {"verdict": whole["verdict"], "top": _top(whole), "causes": _causes(whole),
            "noise_floor": whole["noise_floor"], "diagnose_s": round(seconds, 1),
            "same": (screened["verdict"], _top(screened), _causes(screened)) == (whole["verdict"], _top(whole),
                                                                                  _causes(whole)),
            "floor_change": round(screened["noise_floor"] - whole["noise_floor"], 4)}


def against_whole_summary(records: list[dict]) -> dict[str, Any]:
    """``{"against_whole": {cases, same_verdict_top_causes, floor_lower, floor_higher,
    floor_change_min, floor_change_max}}`` over the records that carry a ``whole``; ``{}``
    when none does."""
    paired = [r["whole"] for r in records if r.get("whole")]
    if not paired:
        return {}
    ch = [w["floor_change"] for w in paired]
    return {"against_whole": {"cases": len(paired), "same_verdict_top_causes": sum(w["same"] for w in paired),
                              "floor_lower": sum(c < -1e-9 for c in ch), "floor_higher": sum(c > 1e-9 for c in ch),
                              "floor_change_min": min(ch), "floor_change_max": max(ch)}}


def against_whole_lines(records: list[dict], summary: dict) -> list[str]:
    """The report's lines: the agreement and the floor's movement, then every case that differs."""
    if "against_whole" not in summary:
        return []
    a = summary["against_whole"]
    head = (f"screened against whole: verdict, top and cause set the same in {a['same_verdict_top_causes']} of "
            f"{a['cases']}; noise floor lower in {a['floor_lower']}, higher in {a['floor_higher']} "
            f"(change {a['floor_change_min']:+.3f} … {a['floor_change_max']:+.3f})")
    return [head] + [(f"  differs: ({r['class']}) {r['case']}: screened {r['verdict']} {r['top']} {r.get('causes')}, "
                      f"whole {r['whole']['verdict']} {r['whole']['top']} {r['whole']['causes']}")
                     for r in records if r.get("whole") and not r["whole"]["same"]]
