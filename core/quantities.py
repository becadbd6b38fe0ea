"""The registry of the 12 validation quantities (Polach & Böttcher 2014 §5, Table 2; docs/design.md §3).

This is the ONE list of the quantities: the processing chain (:mod:`railval.core.en14363`), the
validation (:mod:`railval.core.validation`), the UI and the CLI all read :data:`QUANTITIES`.

Signal positions (the "signals" of a quantity; Polach & Böttcher 2014 §5 asks for ≥ 2 per quantity)
------------------------------------------------------------------------------------
=================================  ==========  ===========================================
quantities                         position    channels (vocabulary of :mod:`railval.core.types`)
=================================  ==========  ===========================================
``Y_qst``, ``Y_max``               wheel       ``Y_w{n}{L|R}``
``Q_qst``, ``Q_max``               wheel       ``Q_w{n}{L|R}``
``YQ_qst``, ``YQ_max``             wheel       ``Y_w{n}{L|R}`` and ``Q_w{n}{L|R}``
``SumY_qst``, ``SumY_max``         wheelset    ``Y_w{n}L`` and ``Y_w{n}R`` (position ``ws{n}``)
``ay_rms``, ``ay_max``             car body    ``ay_cb_{b1|b2}``
``az_rms``, ``az_max``             car body    ``az_cb_{b1|b2}``
=================================  ==========  ===========================================

Limits (Table 2): the std limit is tabulated; for ``Q_qst`` and ``Q_max`` it is
``4·(1 + 0.01·Q0)`` and ``6·(1 + 0.01·Q0)`` kN with Q0 the static vertical wheel force in kN.
The mean limit is 2/3 of the std limit. For freight vehicles or vehicles without secondary
suspension the acceleration limits (mean and std) are doubled.

References
----------
Polach, O. & Böttcher, A. (2014) A new approach to define criteria for rail vehicle model
validation, Vehicle System Dynamics 52:sup1, 125–141, §5 and Table 2 (Polach & Böttcher 2014).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from railval.core.errors import InvalidParameter
from railval.core.types import BODY_POSITIONS, EN_FILTER_LABELS, WHEEL_POSITIONS, channel_kind

SOURCE = "Polach & Böttcher 2014, §5, Table 2"

#: Processing kinds: "median" = 50 % value with sign; "maxabs" = larger magnitude of the
#: 0.15 % and 99.85 % values; "p99.85" = 99.85 % value; "rms" = root mean square.
PROCESSINGS = ("median", "maxabs", "p99.85", "rms")

WHEELSET_POSITIONS = tuple(f"ws{n}" for n in range(1, 5))
VEHICLE_KINDS = ("passenger", "freight")


@dataclass(frozen=True)
class Quantity:
    """One validation quantity of Table 2.

    ``signal``: the processed signal family (``Y``, ``Q``, ``YQ``, ``SumY``, ``ay``, ``az``);
    ``filter`` (derived from the channel registry): ``"lowpass"`` (20 Hz) or ``"bandpass"``
    (0.4–10 Hz), see :mod:`railval.core.filters`;
    ``sliding_mean``: True when the 2 m sliding mean (0.5 m step, along distance) precedes the
    statistic; ``level``: what one position is (wheel, wheelset, carbody);
    ``std_limit_base``: Table 2 std limit (for Q quantities the factor multiplying
    ``(1 + 0.01·Q0)``).
    """

    id: str
    name: str
    symbol: str
    unit: str
    signal: str
    processing: str
    sliding_mean: bool
    level: str
    std_limit_base: float
    q0_scaled: bool = False
    acceleration: bool = False
    source: str = SOURCE

    @property
    def filtering_text(self) -> str:
        if self.sliding_mean:
            return "low-pass 20 Hz, then sliding mean (2 m window, step 0.5 m)"
        return EN_FILTER_LABELS[self.filter]

    @property
    def filter(self) -> str:
        """The EN filter of the channels this quantity is formed from (the channel registry,
        :data:`railval.core.types.CHANNELS`): ``"lowpass"`` or ``"bandpass"``."""
        return channel_kind(self.channels(self.positions()[0])[0]).en_filter

    @property
    def processing_text(self) -> str:
        return {
            "median": "50 % value (median, with sign)",
            "maxabs": "larger magnitude of the 0.15 % / 99.85 % values",
            "p99.85": "99.85 % value",
            "rms": "rms value",
        }[self.processing]

    def positions(self) -> tuple[str, ...]:
        """All positions this quantity can have (wheel, wheelset or car body positions)."""
        return {"wheel": WHEEL_POSITIONS, "wheelset": WHEELSET_POSITIONS,
                "carbody": BODY_POSITIONS}[self.level]

    def channels(self, position: str) -> tuple[str, ...]:
        """Raw channel names that form this quantity at ``position``."""
        if position not in self.positions():
            raise InvalidParameter(
                f"position {position!r} is not a {self.level} position of quantity {self.id} "
                f"(expected one of {self.positions()})"
            )
        if self.signal in ("Y", "Q"):
            return (f"{self.signal}_{position}",)
        if self.signal == "YQ":
            return (f"Y_{position}", f"Q_{position}")
        if self.signal == "SumY":
            n = position[2:]
            return (f"Y_w{n}L", f"Y_w{n}R")
        return (f"{self.signal}_cb_{position}",)

    def available_positions(self, channel_names) -> list[str]:
        """Positions whose channels are all present in ``channel_names``."""
        names = set(channel_names)
        return [p for p in self.positions() if all(c in names for c in self.channels(p))]

    def std_limit(self, Q0_kN: float | None = None, vehicle_kind: str = "passenger",
                  secondary_suspension: bool = True) -> float:
        """Validation limit for the standard deviation of D_v (Table 2), unit of the quantity.

        ``Q0_kN``: static vertical wheel force in kN (needed for Q quantities);
        ``vehicle_kind``: ``passenger`` or ``freight``; accelerations doubled for freight or
        no secondary suspension (Polach & Böttcher 2014 §5).
        """
        if vehicle_kind not in VEHICLE_KINDS:
            raise InvalidParameter(
                f"vehicle kind must be one of {VEHICLE_KINDS}, got {vehicle_kind!r}")
        limit = self.std_limit_base
        if self.q0_scaled:
            if Q0_kN is None or not (Q0_kN > 0):
                raise InvalidParameter(
                    f"Q0_kN (static vertical wheel force, kN) must be > 0 for the {self.id} "
                    f"limit, got {Q0_kN!r}")
            limit = limit * (1.0 + 0.01 * float(Q0_kN))
        if self.acceleration and (vehicle_kind == "freight" or not secondary_suspension):
            limit *= 2.0
        return float(limit)

    def mean_limit(self, Q0_kN: float | None = None, vehicle_kind: str = "passenger",
                   secondary_suspension: bool = True) -> float:
        """Validation limit for |mean of D_v| = 2/3 of the std limit (Polach & Böttcher 2014 §5)."""
        return self.std_limit(Q0_kN, vehicle_kind, secondary_suspension) * 2.0 / 3.0

    def to_dict(self) -> dict:
        return {"id": self.id, "name": self.name, "symbol": self.symbol, "unit": self.unit,
                "filtering": self.filtering_text, "processing": self.processing_text,
                "level": self.level, "std_limit_base": self.std_limit_base,
                "q0_scaled": self.q0_scaled, "acceleration": self.acceleration,
                "source": self.source}


_Q = Quantity
QUANTITIES: dict[str, Quantity] = {q.id: q for q in (
    _Q("Y_qst", "quasi-static guiding force", "Y_qst", "kN", "Y", "median", False,
       "wheel", 5.0),
    _Q("Q_qst", "quasi-static vertical wheel force", "Q_qst", "kN", "Q", "median",
       False, "wheel", 4.0, q0_scaled=True),
    _Q("YQ_qst", "quasi-static ratio Y/Q", "(Y/Q)_qst", "-", "YQ", "median", False,
       "wheel", 0.07),
    _Q("SumY_qst", "quasi-static sum of guiding forces", "ΣY_qst", "kN", "SumY",
       "median", False, "wheelset", 6.0),
    _Q("Y_max", "guiding force, maximum", "Y_max", "kN", "Y", "maxabs", False,
       "wheel", 9.0),
    _Q("Q_max", "vertical wheel force, maximum", "Q_max", "kN", "Q", "p99.85",
       False, "wheel", 6.0, q0_scaled=True),
    _Q("YQ_max", "ratio Y/Q, maximum", "(Y/Q)_max", "-", "YQ", "maxabs", True,
       "wheel", 0.10),
    _Q("SumY_max", "sum of guiding forces, maximum", "ΣY_max", "kN", "SumY",
       "maxabs", True, "wheelset", 9.0),
    _Q("ay_rms", "car body lateral acceleration, rms", "ÿ*_rms", "m/s^2", "ay",
       "rms", False, "carbody", 0.15, acceleration=True),
    _Q("az_rms", "car body vertical acceleration, rms", "z̈*_rms", "m/s^2", "az",
       "rms", False, "carbody", 0.15, acceleration=True),
    _Q("ay_max", "car body lateral acceleration, maximum", "ÿ*_max", "m/s^2", "ay",
       "maxabs", False, "carbody", 0.40, acceleration=True),
    _Q("az_max", "car body vertical acceleration, maximum", "z̈*_max", "m/s^2", "az", "maxabs", False, "carbody", 0.40, acceleration=True),
)}

QUANTITY_IDS: tuple[str, ...] = tuple(QUANTITIES)


def get(quantity_id: str) -> Quantity:
    """Registry lookup raising :class:`InvalidParameter` for unknown ids."""
    try:
        return QUANTITIES[quantity_id]
    except KeyError:
        raise InvalidParameter(
            f"unknown quantity {quantity_id!r}; known: {', '.join(QUANTITY_IDS)}") from None


def limits(Q0_kN: float, vehicle_kind: str = "passenger",
           secondary_suspension: bool = True) -> dict[str, tuple[float, float]]:
    """``{quantity_id: (mean_limit, std_limit)}`` for a vehicle (Table 2 with its rules)."""
    return {qid: (q.mean_limit(Q0_kN, vehicle_kind, secondary_suspension),
                  q.std_limit(Q0_kN, vehicle_kind, secondary_suspension))
            for qid, q in QUANTITIES.items()}


def pairs_for_channels(channel_names) -> list[tuple[str, str]]:
    """Every (quantity_id, position) that the given raw channels allow, registry order."""
    names = list(channel_names)
    return [(qid, p) for qid, q in QUANTITIES.items() for p in q.available_positions(names)]


def channel_for(quantity: str | None, position: str | None, channels: Sequence[str]) -> str | None:
    """The raw channel to look at for a quantity at a position: Y/Q at w1L → ``Y_w1L``; ΣY at
    ws1 → ``Y_w1L``; ay_rms at b1 → ``ay_cb_b1``; the first of ``channels`` when the
    quantity/position forms none of them (None when ``channels`` is empty)."""
    if quantity in QUANTITIES and position and position in QUANTITIES[quantity].positions():
        for c in QUANTITIES[quantity].channels(position):
            if c in channels:
                return c
    return channels[0] if channels else None


#: signals formed from raw channels that the EN quantities are evaluated on (Table 2):
#: family → (quantity whose channels form it, how, unit)
DERIVED_SIGNALS: dict[str, tuple[str, str, str]] = {
    "YQ": ("YQ_qst", "ratio", "-"),    # Y/Q formed sample-wise from the low-pass filtered Y and Q
    "SumY": ("SumY_qst", "sum", "kN"),  # ΣY = Y_L + Y_R of a wheelset, low-pass filtered forces
}


def derived_signals(channel_names) -> dict[str, tuple[str, ...]]:
    """Derived signal name → the raw channels forming it, for the channels present:
    ``YQ_w1L`` → (``Y_w1L``, ``Q_w1L``), ``SumY_ws1`` → (``Y_w1L``, ``Y_w1R``)."""
    names = list(channel_names)
    out: dict[str, tuple[str, ...]] = {}
    for fam, (qid, _, _) in DERIVED_SIGNALS.items():
        q = QUANTITIES[qid]
        for p in q.available_positions(names):
            out[f"{fam}_{p}"] = tuple(q.channels(p))
    return out


def combine_derived(name: str, rows) -> np.ndarray:
    """The derived signal ``name`` (:func:`derived_signals`) from its component rows (in the
    order :func:`derived_signals` gives): Y/Q sample-wise or ΣY = Y_L + Y_R."""
    fam = name.split("_", 1)[0]
    how = DERIVED_SIGNALS[fam][1]
    return rows[0] / rows[1] if how == "ratio" else rows[0] + rows[1]
