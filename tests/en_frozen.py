"""Frozen EN 14363 results: the inputs of the identity check of the EN chain and a writer of
the values the chain gave for them.

The inputs are rebuilt deterministically: the ``railval bench en`` sections (17 × 20 channels ×
20 000 samples at 500 Hz, variable speed) and a synthetic campaign of the built-in simulator
(12 sections of unequal length, measured side and the baseline configuration, 24 channels
with bogie-frame accelerations, 200 Hz). ``python -m tests.en_frozen`` writes
``tests/data/en_frozen.json.gz`` from the current code: every value, every value under the
alternative readings and every supplementary value of every section. It was written before
the EN chain was restructured for throughput (filtering several channels in lockstep on both
cores, percentiles by partition); tests/test_en_throughput.py holds the chain to it.
"""

from __future__ import annotations

import gzip
import json
from pathlib import Path

FROZEN = Path(__file__).parent / "data" / "en_frozen.json.gz"


def bench_inputs():
    from railval.app.bench.bench_en import make_sections

    return make_sections(17, 20_000, 500.0)


def campaign_inputs():
    """The synthetic campaign's measured and baseline signal sets, simulated with the IEEE step
    (tests/sim_ieee.py): the frozen values were made from such runs, and the check holds the EN
    chain, not the simulator's last bits."""
    from railval.core.sim.synth import build_campaign
    from railval.core.types import SectionInfo
    from tests.sim_ieee import ieee_kernel

    with ieee_kernel():
        sc = build_campaign(n_sections=12)
    infos = []
    for s in sc.sections:
        rec = s.manifest_record()
        infos.append(SectionInfo(rec["id"], rec["radius_m"], rec["cant_mm"], rec["speed_kmh"],
                                 s.zone, rec["evaluated"]["start_m"], rec["evaluated"]["end_m"],
                                 rec["country"], rec["curve_direction"]))
    sets = [sc.measured[i.id] for i in infos] + [sc.baseline[i.id] for i in infos]
    return sets, infos + infos


def flatten(values) -> dict[str, float | None]:
    """``"kind|reading|quantity|position" → value`` of one SectionValues (None for NaN)."""
    out: dict[str, float | None] = {}
    for (q, p), v in values.items():
        out[f"value||{q}|{p}"] = float(v)
    for rid, vals in values.alternatives.items():
        for (q, p), v in vals.items():
            out[f"alt|{rid}|{q}|{p}"] = None if v != v else float(v)
    for (q, p), v in values.supplementary.items():
        out[f"supp||{q}|{p}"] = float(v)
    return out


def compute() -> dict[str, list[dict]]:
    from railval.core.en14363 import evaluate_batch

    out = {}
    for name, (sets, infos) in (("bench", bench_inputs()), ("campaign", campaign_inputs())):
        out[name] = [flatten(v) for v in evaluate_batch(sets, infos)]
    return out


def load() -> dict[str, list[dict]]:
    with gzip.open(FROZEN, "rt") as fh:
        return json.load(fh)


if __name__ == "__main__":  # pragma: no cover - writes the frozen file once
    FROZEN.parent.mkdir(exist_ok=True)
    with gzip.open(FROZEN, "wt") as fh:
        json.dump(compute(), fh)
    print(FROZEN, FROZEN.stat().st_size, "bytes")
