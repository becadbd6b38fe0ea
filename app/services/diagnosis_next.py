"""The next step a diagnosis proposes (docs/diagnosis.md "Diagnosis"): calibrate its cause or
causes into a child configuration (the ``railval calibrate`` command), check the measurement,
supply data, or say what stays unexplained. Read by
:func:`railval.app.services.diagnosis_ranking.rank_causes`.
"""

from __future__ import annotations

from typing import Any

from railval.core.diagnosis import DiagnosisResult

__all__ = ["next_step"]


def next_step(res: DiagnosisResult, campaign: str, config: str) -> dict[str, Any]:
    """What to do next: calibrate the cause into a child configuration (then diagnose the
    child), or, with no cause, what stays unexplained."""
    verdict = res.verdict
    if verdict == "none" or not res.candidates:
        return {"action": "none", "text": "no candidate explains the residual; look at what stays unexplained "
                                          "(quantities, zones, bands) — data, sensors or physics outside the library"}
    all_causes = res.causes or []
    sensors = [x for x in all_causes if x["kind"] == "measurement"]
    summary = {c.name: c.summary for c in res.candidates}
    check = ("; first check the measurement: " + "; ".join(
        f"{x['name'].removeprefix('offset ')} reads ≈ the true value {x['fitted']:+.3g}" if x["parameter"] == "offset"
        else summary.get(x["name"], x["name"]) if x["parameter"] in ("sign", "swap", "shift")
        else f"{x['name'].removeprefix('gain ')} reads ≈ {x['fitted']:.3g} × the true value" for x in sensors)
             ) if sensors else ""
    if res.statements:  # an input of the simulation differs: data, not a model change (core/diagnosis/inputs.py)
        return {"action": "supply data", "candidates": [n for x in res.statements for n in x["candidates"]],
                "text": "; ".join(x["text"] for x in res.statements)
                        + " — then diagnose again; no vehicle parameter is calibrated on an assumed input" + check}
    causes = [x for x in all_causes if x["kind"] != "measurement"]
    if sensors and not causes:
        return {"action": "check measurement", "candidates": [x["name"] for x in sensors],
                "text": "the measurement, not the model" + check + " (sensor calibration, amplifier gain) — "
                        "correct the channel and import the campaign again before touching the model"}
    if len(causes) > 1:  # a set of causes: calibrate them together
        byname = {c.name: c for c in res.candidates}
        eff = " ".join(f"--effect {x['name']}" for x in causes)
        start = " ".join(f"{x['name']}={x['fitted']:.4g}" if x["kind"] == "parameter" else
                         " ".join(f"{x['name']}.{k}={v:.4g}" for k, v in byname[x["name"]].parameters.items())
                         for x in causes)
        new = config + "".join(f"+{x['parameter'] if x['kind'] == 'parameter' else x['name']}" for x in causes)
        cmd = f"railval calibrate {campaign} --config {config} {eff} --as {new} --start {start}"
        return {"action": "calibrate", "candidates": [x["name"] for x in causes], "command": cmd,
                "text": f"calibrate the {len(causes)} causes together into a child configuration, then diagnose "
                        f"the child: {cmd}" + check}
    c = res.candidates[0]
    if c.kind == "measurement":
        return {"action": "check measurement", "candidate": c.name,
                "text": ("" if verdict == "cause" else "uncertain — ") + f"check the measurement first: {c.summary}"}
    if c.kind == "effect":
        start = " ".join(f"{c.name}.{k}={v:.4g}" for k, v in c.parameters.items())
        cmd = f"railval calibrate {campaign} --config {config} --effect {c.name} --as {config}+{c.name} --start {start}"
    else:
        cmd = (f"railval calibrate {campaign} --config {config} --effect {c.name} --as {config}+{c.parameter} "
               f"--start {c.name}={c.fitted:.4g}")
    text = ("calibrate the cause into a child configuration, then diagnose the child: " if verdict == "cause" else
            "uncertain — if you calibrate the best candidate, check its flags and held-out result: ")
    return {"action": "calibrate", "candidate": c.name, "command": cmd, "text": text + cmd + check}
