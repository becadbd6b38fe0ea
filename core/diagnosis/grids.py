"""Residual patterns arranged for heat maps on the Diagnose page and in reports: quantity ×
EN 14363 test zone of the normalised differences D_v / std limit (Polach & Böttcher 2014 §5),
and car body acceleration direction × frequency band of the log₂ PSD ratios (docs/app.md).
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from railval.core.diagnosis.patterns import Component


@dataclass
class PatternGrid:
    """Components of a residual pattern arranged for a heat map: ``rows`` × ``cols`` with
    ``values[i][j]`` the mean over positions (NaN where nothing was evaluated)."""

    rows: list[str]
    cols: list[str]
    values: np.ndarray


ZONE_COLUMNS = tuple(f"zone {z}" for z in (1, 2, 3, 4))


def _grid(rows: Sequence[str], cols: Sequence[str], acc: Mapping[tuple[str, str], list[float]]) -> PatternGrid:
    m = np.full((len(rows), len(cols)), np.nan)
    for i, r in enumerate(rows):
        for j, c in enumerate(cols):
            if (r, c) in acc:
                m[i, j] = float(np.mean(acc[(r, c)]))
    return PatternGrid(list(rows), list(cols), m)


def _quantity_zone_grid(acc: Mapping[tuple[str, str], list[float]]) -> PatternGrid:
    from railval.core.quantities import QUANTITY_IDS

    quantities = [q for q in QUANTITY_IDS if any((q, z) in acc for z in ZONE_COLUMNS)]
    return _grid(quantities, ZONE_COLUMNS, acc)


def where_grid(pairs: Mapping[str, Sequence]) -> PatternGrid:
    """Where a configuration fails: the mean of D_v / std limit (Polach & Böttcher 2014 §5)
    over the sections and positions of each quantity × EN 14363 test zone. ``pairs`` has the
    columns ``quantity``, ``zone`` and ``D_norm`` (``railval.core.validation.ValidationResult.pairs``).
    Quantities in the order of :mod:`railval.core.quantities`."""
    acc: dict[tuple[str, str], list[float]] = defaultdict(list)
    for q, z, v in zip(pairs["quantity"], pairs["zone"], np.asarray(pairs["D_norm"], float), strict=True):
        if math.isfinite(v):
            acc[(str(q), f"zone {int(z)}")].append(float(v))
    return _quantity_zone_grid(acc)


def pattern_grids(components: Sequence[Component], values) -> tuple[PatternGrid, PatternGrid]:
    """Arrange a diagnosis pattern (its :class:`Component` s and values: mean normalised D_v
    of a quantity in a zone at a position, and log₂ PSD ratio simulation/measurement of an
    acceleration channel in a band) into (quantity × zone, car body acceleration direction ×
    band) grids, averaging over positions and channels; supplementary components are on
    neither grid."""
    q_acc: dict[tuple[str, str], list[float]] = defaultdict(list)
    p_acc: dict[tuple[str, str], list[float]] = defaultdict(list)
    bands: dict[str, float] = {}
    for c, v in zip(components, np.asarray(values, float), strict=True):
        if not math.isfinite(v):
            continue
        if c.kind == "psd":
            bands[c.band_label] = c.band[0]
            p_acc[(c.direction, c.band_label)].append(v)
        elif c.kind == "pair":
            q_acc[(c.quantity, f"zone {c.zone}")].append(v)
    cols = sorted(bands, key=bands.__getitem__)
    kinds = [k for k in ("ay", "az") if any((k, b) in p_acc for b in cols)]
    return _quantity_zone_grid(q_acc), _grid(kinds, cols, p_acc)
