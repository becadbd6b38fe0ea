"""Residual patterns of a diagnosis (docs/design.md §7, docs/diagnosis.md): what each
component measures and how a configuration's differences to the measurement become one
dimensionless vector.

A :class:`Pattern` is a vector of dimensionless components with labels and groups:

* per quantity × test zone × signal position: the mean over the sections of the normalised
  difference D_v / std-limit (D_v = (S_v − M_v)·sign(M_v), Polach & Böttcher 2014 §5; the limit from Table 2
  via the validation), label ``"Y_qst zone 4 w1L"``, group the quantity id — built by
  :func:`pattern_from_pairs`;
* per car body acceleration channel × frequency band: log-ratio of the band powers of
  simulation and measurement (Welch PSD, :func:`railval.core.psd.welch_psd`), ln(P_sim/P_meas)/ln 2,
  so a factor-2 power error counts 1 — the same order as a normalised D_v at its limit;
  label ``"psd az_cb_b1 5-10 Hz"``, group ``"psd az"`` — built by :func:`psd_band_pattern`.

"Whitened": every component is dimensionless (value/limit or log₂ ratio) and each group gets
the weight 1/√(number of its components), so every quantity carries the same total weight
whatever its number of positions and zones (Y has eight wheels, ay two sensors).

References: Polach & Böttcher 2014, §5 (D_v, limits, zones); Welch 1967 (PSD estimate, via
:mod:`railval.core.psd`).
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from railval.core.errors import InvalidSignal
from railval.core.psd import welch_psd

#: Frequency bands (Hz) of the car body acceleration log-PSD ratios: body modes (0.4–2),
#: bogie/suspension range (2–5), upper band of the EN filter (5–10).
DEFAULT_BANDS_HZ: tuple[tuple[float, float], ...] = ((0.4, 1.0), (1.0, 2.0), (2.0, 5.0), (5.0, 10.0))


@dataclass(frozen=True)
class Component:
    """What one pattern component measures, as fields: a validation pair aggregate
    (``kind="pair"``: ``quantity``, EN 14363 ``zone``, ``position``), a band-power ratio
    (``kind="psd"``: acceleration ``channel``, ``band`` in Hz) or a supplementary quantity
    (``kind="supplementary"``: ``quantity``, ``position``, ``channel`` = its channel kind,
    :mod:`railval.core.supplementary`)."""

    kind: str
    quantity: str = ""
    zone: int = 0
    position: str = ""
    channel: str = ""
    band: tuple[float, float] = (0.0, 0.0)

    @classmethod
    def pair(cls, quantity: str, zone: int, position: str) -> Component:
        return cls("pair", quantity=quantity, zone=int(zone), position=position)

    @classmethod
    def psd(cls, channel: str, band: tuple[float, float]) -> Component:
        return cls("psd", channel=channel, band=(float(band[0]), float(band[1])))

    @classmethod
    def supplementary(cls, quantity: str, position: str, channel_kind: str) -> Component:
        return cls("supplementary", quantity=quantity, position=position, channel=channel_kind)

    @property
    def direction(self) -> str:
        """Of a band-power or supplementary component: the acceleration direction (``"ay"``, ``"az"``)."""
        return self.channel.split("_")[0]

    @property
    def band_label(self) -> str:
        return f"{self.band[0]:g}-{self.band[1]:g} Hz"

    @property
    def label(self) -> str:
        """As shown to a reader: ``"Y_qst zone 4 w1L"``, ``"psd az_cb_b1 5-10 Hz"``."""
        if self.kind == "psd":
            return f"psd {self.channel} {self.band_label}"
        if self.kind == "supplementary":
            return f"supp {self.quantity} {self.position}"
        return f"{self.quantity} zone {self.zone} {self.position}"

    @property
    def group(self) -> str:
        """The weighting group: the quantity id, ``"psd ay"``/``"psd az"`` or ``"bogie ay"``/``"bogie az"``."""
        if self.kind == "psd":
            return f"psd {self.direction}"
        return f"bogie {self.direction}" if self.kind == "supplementary" else self.quantity

    def to_dict(self) -> dict[str, Any]:
        if self.kind == "psd":
            return {"kind": "psd", "channel": self.channel, "band": list(self.band)}
        if self.kind == "supplementary":
            return {"kind": "supplementary", "quantity": self.quantity, "position": self.position,
                    "channel": self.channel}
        return {"kind": "pair", "quantity": self.quantity, "zone": self.zone, "position": self.position}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Component:
        if d["kind"] == "psd":
            return cls.psd(d["channel"], tuple(d["band"]))
        if d["kind"] == "supplementary":
            return cls.supplementary(d["quantity"], d["position"], d["channel"])
        return cls.pair(d["quantity"], d["zone"], d["position"])


@dataclass
class Pattern:
    """Labelled dimensionless residual vector; ``groups[i]`` names the quantity of component i;
    ``components[i]`` (when built from data) says what component i measures, as fields."""

    labels: list[str]
    groups: list[str]
    values: np.ndarray
    components: list[Component] | None = None

    def __post_init__(self) -> None:
        self.values = np.asarray(self.values, dtype=float)
        if not (len(self.labels) == len(self.groups) == self.values.size):
            raise InvalidSignal(
                f"pattern needs equal numbers of labels ({len(self.labels)}), groups ({len(self.groups)}) "
                f"and values ({self.values.size})")
        if self.components is not None and len(self.components) != len(self.labels):
            raise InvalidSignal(f"pattern has {len(self.components)} components for {len(self.labels)} labels")

    @classmethod
    def of(cls, components: Sequence[Component], values) -> Pattern:
        """A pattern of structured components (labels and groups from them)."""
        comps = list(components)
        return cls([c.label for c in comps], [c.group for c in comps], values, comps)

    def weights(self) -> np.ndarray:
        """Per-component weight 1/√n_group (each group's total weight is 1)."""
        count: dict[str, int] = defaultdict(int)
        for g in self.groups:
            count[g] += 1
        return np.array([1.0 / math.sqrt(count[g]) for g in self.groups])

    def norm2(self, values: np.ndarray | None = None) -> float:
        v = self.values if values is None else values
        w = self.weights()
        return float(np.sum((w * v) ** 2))

    def aligned(self, labels: Sequence[str], groups: Sequence[str]) -> Pattern:
        """This pattern on another label set (missing components are 0 — nothing to explain)."""
        idx = {lab: k for k, lab in enumerate(self.labels)}
        vals = np.array([self.values[idx[lab]] if lab in idx else 0.0 for lab in labels])
        return Pattern(list(labels), list(groups), vals)

    def group_norms(self, values: np.ndarray | None = None) -> dict[str, float]:
        v = self.values if values is None else values
        out: dict[str, float] = defaultdict(float)
        for g, x in zip(self.groups, v, strict=True):
            out[g] += float(x) ** 2
        cnt: dict[str, int] = defaultdict(int)
        for g in self.groups:
            cnt[g] += 1
        return {g: math.sqrt(out[g] / cnt[g]) for g in out}

    @staticmethod
    def concat(*patterns: Pattern) -> Pattern:
        labels: list[str] = []
        groups: list[str] = []
        vals: list[np.ndarray] = []
        for p in patterns:
            labels += p.labels
            groups += p.groups
            vals.append(p.values)
        comps = (None if any(p.components is None for p in patterns)
                 else [c for p in patterns for c in p.components])
        return Pattern(labels, groups, np.concatenate(vals) if vals else np.zeros(0), comps)

    def with_values(self, values) -> Pattern:
        """The same components with other values."""
        return Pattern(self.labels, self.groups, values, self.components)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"labels": list(self.labels), "groups": list(self.groups),
                             "values": self.values.tolist()}
        if self.components is not None:
            d["components"] = [c.to_dict() for c in self.components]
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Pattern:
        """Inverse of :meth:`to_dict` (a stored run read back)."""
        comps = d.get("components")
        return cls(list(d["labels"]), list(d["groups"]), np.asarray(d["values"], dtype=float),
                   None if comps is None else [Component.from_dict(c) for c in comps])


def pattern_from_pairs(pairs: Iterable[Mapping[str, Any]], *, value_key: str = "norm") -> Pattern:
    """Aggregate per-pair normalised differences into the quantity × zone × position pattern.

    Each record needs ``quantity``, ``zone``, ``position`` and ``value_key`` (D_v divided by
    the quantity's std limit, dimensionless); the component is the mean over the sections of
    that (quantity, zone, position). Non-finite values are skipped. Components are ordered by
    quantity, zone, position.
    """
    acc: dict[tuple[str, int, str], list[float]] = defaultdict(list)
    for r in pairs:
        v = float(r[value_key])
        if math.isfinite(v):
            acc[(str(r["quantity"]), int(r["zone"]), str(r["position"]))].append(v)
    if not acc:
        raise InvalidSignal(f"no finite '{value_key}' values in the validation pairs")
    keys = sorted(acc)
    return Pattern.of([Component.pair(q, z, p) for q, z, p in keys],
                      np.array([float(np.mean(acc[k])) for k in keys]))


def difference_pairs(measured: Mapping[str, Mapping[tuple[str, str], float]],
                     simulated: Mapping[str, Mapping[tuple[str, str], float]],
                     zones: Mapping[str, int], std_limits: Mapping[str, float]) -> list[dict[str, Any]]:
    """Normalised differences of every (section, quantity, position) present in both sources.

    ``measured[section][(quantity, position)]`` = M_v, ``simulated[…]`` = S_v (EN 14363
    section values, e.g. :func:`railval.core.en14363.evaluate_batch`); D_v = (S_v − M_v)·M_v/|M_v|, and
    D_v = S_v where M_v = 0 (Polach & Böttcher 2014 §5, docs/design.md §3); ``norm`` = D_v / std limit of the
    quantity (Table 2). Records: ``section, zone, quantity, position, D_v, norm``.
    """
    out = []
    for sid, mv in measured.items():
        sv = simulated.get(sid)
        if sv is None:
            continue
        for key, m in mv.items():
            if key not in sv:
                continue
            q, pos = key
            s = float(sv[key])
            m = float(m)
            d = (s - m) * math.copysign(1.0, m) if m != 0 else s
            out.append({"section": sid, "zone": int(zones[sid]), "quantity": q, "position": pos,
                        "D_v": d, "norm": d / float(std_limits[q])})
    return out


def band_powers(x: np.ndarray, fs: float, bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ,
                segment_s: float = 10.0) -> np.ndarray:
    """Power of ``x`` (unit²) in each band [lo, hi) Hz: the Welch PSD (:func:`railval.core.psd.welch_psd`,
    ``segment_s`` segments) summed over the band's bins times the bin width."""
    psd = welch_psd(np.asarray(x, float), fs, segment_s=segment_s)
    f, d = np.asarray(psd.frequency_hz), np.asarray(psd.density)
    df = f[1] - f[0]
    return np.array([float(np.sum(d[(f >= lo) & (f < hi)]) * df) for lo, hi in bands])


def section_band_powers(channels: Mapping[str, np.ndarray], fs: float,
                        bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ,
                        segment_s: float = 10.0) -> dict[str, np.ndarray]:
    """:func:`band_powers` of every channel of one section (equal lengths, e.g. the car body
    acceleration channels of a :class:`railval.core.types.SignalSet`) from one Welch call over
    all of them (:func:`railval.core.psd.welch_rows`, the settings of
    :func:`railval.core.psd.welch_psd`): channel → power per band (unit²), equal to
    :func:`band_powers` of each channel alone (tests/test_diagnosis_speed.py)."""
    from railval.core.psd import welch_rows

    names = list(channels)
    if not names:
        return {}
    rows = [np.asarray(channels[n], dtype=float) for n in names]
    if len({r.shape for r in rows}) != 1 or rows[0].ndim != 1:
        raise InvalidSignal(f"section_band_powers: channels {names} must be 1-D arrays of one length, "
                            f"got shapes {[r.shape for r in rows]}")
    for n, r in zip(names, rows, strict=True):
        if r.size < 8 or not np.all(np.isfinite(r)):
            raise InvalidSignal(f"section_band_powers: channel {n!r} has fewer than 8 samples or NaN/inf")
    f, d, _ = welch_rows(np.stack(rows), fs, segment_s)
    df = f[1] - f[0]
    masks = [(f >= lo) & (f < hi) for lo, hi in bands]
    return {n: np.array([float(np.sum(d[k][m]) * df) for m in masks]) for k, n in enumerate(names)}


def sections_band_powers(sections: Mapping[str, Mapping[str, np.ndarray]], fs: Mapping[str, float],
                         bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ,
                         segment_s: float = 10.0) -> dict[str, dict[str, np.ndarray]]:
    """:func:`section_band_powers` of many sections at once: ``sections[sid]`` the channels
    of one section (equal lengths within it), ``fs[sid]`` its rate in Hz; section id →
    channel → power per band (unit²), every number equal (same float bits) to
    :func:`section_band_powers` of that section alone. The Welch estimates of all sections go
    through one :func:`railval.core.psd.welch_blocks` call (one block per section, its rows in
    the section's channel order), which holds each block equal to
    :func:`railval.core.psd.welch_rows` of it (tests/test_supp_exact.py); the band sums are the
    same expression. A section with a bad channel raises as :func:`section_band_powers`
    (the first such section, in order)."""
    from railval.core.psd import welch_blocks

    ids = [sid for sid, chans in sections.items() if chans]
    blocks, names = [], []
    for sid in ids:
        chans = sections[sid]
        rows = [np.asarray(chans[n], dtype=float) for n in chans]
        if len({r.shape for r in rows}) != 1 or rows[0].ndim != 1 or any(
                r.size < 8 or not np.all(np.isfinite(r)) for r in rows):
            section_band_powers(chans, fs[sid], bands, segment_s)  # raises its precise error
        blocks.append(np.stack(rows))
        names.append(list(chans))
    out: dict[str, dict[str, np.ndarray]] = {sid: {} for sid, chans in sections.items() if not chans}
    for sid, chans, (f, d) in zip(ids, names, welch_blocks(blocks, [fs[sid] for sid in ids], segment_s),
                                  strict=True):
        df = f[1] - f[0]
        masks = [(f >= lo) & (f < hi) for lo, hi in bands]
        out[sid] = {n: np.array([float(np.sum(d[k][m]) * df) for m in masks]) for k, n in enumerate(chans)}
    return {sid: out[sid] for sid in sections}


def band_ratio_pattern(simulated: Mapping[str, np.ndarray], measured: Mapping[str, np.ndarray],
                       bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ) -> Pattern:
    """Log₂ ratio of band powers simulated/measured per acceleration channel and band.

    ``simulated[channel]``/``measured[channel]``: band powers (one per band, e.g. summed over
    the sections with :func:`band_powers`). Value ln(P_sim/P_meas)/ln 2 (dimensionless;
    1 = twice the power). Label ``"psd az_cb_b1 5-10 Hz"``, group ``"psd ay"``/``"psd az"``
    from the channel kind. A band without power on either side is skipped.
    """
    comps, vals = [], []
    for ch in sorted(set(simulated) & set(measured)):
        for band, a, b in zip(bands, np.atleast_1d(simulated[ch]), np.atleast_1d(measured[ch]), strict=True):
            if b > 0 and a > 0:
                comps.append(Component.psd(ch, band))
                vals.append(math.log(a / b) / math.log(2.0))
    return Pattern.of(comps, np.array(vals))


def psd_band_pattern(simulated: Mapping[str, Sequence[np.ndarray]], measured: Mapping[str, Sequence[np.ndarray]],
                     fs: float, *, bands: Sequence[tuple[float, float]] = DEFAULT_BANDS_HZ,
                     segment_s: float = 10.0) -> Pattern:
    """:func:`band_ratio_pattern` of signals: ``simulated[channel]`` and ``measured[channel]``
    are lists of signals (one per section, m/s², sampled at ``fs`` Hz) whose band powers are
    summed over the sections before the ratio."""
    def total(sets):
        return {ch: sum(band_powers(x, fs, bands, segment_s) for x in xs) for ch, xs in sets.items()}

    return band_ratio_pattern(total(simulated), total(measured), bands)



def component_parts(label: str, group: str) -> dict[str, Any]:
    """Structured view of a pattern component: ``quantity``, ``zone``, ``position`` for a
    quantity × zone × position component (label ``"Y_qst zone 4 w1L"``), ``quantity`` (the
    group, ``"psd az"``), ``channel`` and ``band`` for a band-power component
    (``"psd az_cb_b1 5-10 Hz"``)."""
    words = label.split()
    if group.startswith("psd") and len(words) >= 3:
        return {"quantity": group, "channel": words[1], "band": " ".join(words[2:]), "zone": None,
                "position": None}
    if len(words) >= 4 and words[1] == "zone":
        return {"quantity": words[0], "zone": int(words[2]), "position": " ".join(words[3:]),
                "channel": None, "band": None}
    return {"quantity": group, "zone": None, "position": None, "channel": None, "band": None}
