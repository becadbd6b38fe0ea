"""Class (p) of the diagnosis trust bench (:mod:`railval.app.bench.bench_diagnosis_trust`):
measured profiles that differ from the model's linear conicity. The truth runs on a nonlinear
rolling-radius difference table (template parameter ``contact_geometry``,
:mod:`railval.core.sim.profiles`) while every candidate model uses the template's conicity 0.15;
the right answer is the contact-geometry statement (docs/diagnosis.md "Contact geometry"), never
a single conicity as the ``cause``."""

from __future__ import annotations

from typing import Any


def profile_table(cone: float, rise_at_mm: float, *, jump_mm: float = 0.0, jump_at_mm: float = 0.0,
                  worn_cone: float | None = None, label: str = "") -> dict[str, Any]:
    """A Δr(y) table (template parameter ``contact_geometry``, y 0–12 mm, mirrored): a tread cone
    ``cone`` (Δr = 2·cone·y), a jump of ``jump_mm`` at ``jump_at_mm`` (over 0.1 mm; a worn
    hollow tread's contact jump) after which the slope is ``worn_cone``, and a steep rise
    towards the flange from ``rise_at_mm`` (slope 0.8, then 3 beyond 1.5 mm more)."""
    ys = sorted({0.0, rise_at_mm, rise_at_mm + 1.5, 12.0} | ({jump_at_mm, jump_at_mm + 0.1} if jump_mm else set()))
    out = []
    after = worn_cone if worn_cone is not None else cone
    for y in ys:
        dr = 2.0 * cone * min(y, jump_at_mm) if jump_mm else 2.0 * cone * min(y, rise_at_mm)
        if jump_mm and y > jump_at_mm:
            dr += jump_mm * min(1.0, (y - jump_at_mm) / 0.1)
            dr += 2.0 * after * max(0.0, min(y, rise_at_mm) - jump_at_mm - 0.1)
        dr += 0.8 * max(0.0, min(y, rise_at_mm + 1.5) - rise_at_mm) + 3.0 * max(0.0, y - rise_at_mm - 1.5)
        out.append(round(dr, 6))
    return {"y_mm": ys, "delta_r_mm": out, "source": label}


# (p) the measured profiles differ (a nonlinear Δr(y) table in the truth) while the candidate
# models use the template's linear conicity 0.15: a reference-like new pair (tread cone ≈ 0.12,
# steep rise towards the flange) and worn pairs (tread cone ≈ 0.025 with a 2 mm jump at 2.5 mm);
# right answer: the contact geometry (statement), never a single conicity as the cause
def profile_cases(polach: dict[str, float]) -> list[tuple[str, dict[str, Any], str]]:
    """The cases of class (p); ``polach``: the truth parameters of the other creep law (class f)."""
    new = profile_table(0.12, 5.0, label="new, cone 0.12")
    worn = profile_table(0.025, 6.0, jump_mm=2.0, jump_at_mm=2.5, worn_cone=0.04,
                         label="worn, cone 0.025, 2 mm jump at 2.5 mm")
    return [
        ("new profiles: cone 0.12, flange rise from 5 mm", {"truth_parameters": {"contact_geometry": new}}, "conicity"),
        ("worn profiles: cone 0.025, 2 mm jump at 2.5 mm", {"truth_parameters": {"contact_geometry": worn}}, "conicity"),
        ("worn profiles: cone 0.03, 1.5 mm jump at 3 mm",
         {"truth_parameters": {"contact_geometry": profile_table(0.03, 6.0, jump_mm=1.5, jump_at_mm=3.0, worn_cone=0.05,
                                                                 label="worn, cone 0.03, 1.5 mm jump at 3 mm")}},
         "conicity"),
        ("new profiles: cone 0.10, flange rise from 4 mm, seed 5",
         {"seed": 5, "truth_parameters": {"contact_geometry": profile_table(0.10, 4.0, label="new, cone 0.10")}},
         "conicity"),
        ("worn profiles (2 mm jump at 2.5 mm), creep law differs",
         {"truth_parameters": {**polach, "contact_geometry": worn}}, "conicity"),
        ("worn profiles (2 mm jump at 2.5 mm), seed 7", {"seed": 7, "truth_parameters": {"contact_geometry": worn}},
         "conicity"),
    ]
