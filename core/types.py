"""Small data contracts shared by core, db and app.

Channel vocabulary (the raw measured/simulated signals; docs/design.md §3, Polach & Böttcher 2014 Table 2)
----------------------------------------------------------------------------------
A channel is named ``f"{kind}_{position}"``.

=========  =====  ==========================================================  ============
kind       unit   meaning                                                      positions
=========  =====  ==========================================================  ============
``Y``      kN     lateral wheel–rail (guiding) force of one wheel              ``w1L`` … ``w4R``
``Q``      kN     vertical wheel–rail force of one wheel                       ``w1L`` … ``w4R``
``ay_cb``  m/s²   car body lateral acceleration above bogie / end 1 or 2       ``b1``, ``b2``
``az_cb``  m/s²   car body vertical acceleration above bogie / end 1 or 2      ``b1``, ``b2``
``ay_bg``  m/s²   bogie frame lateral acceleration (coach only)                ``b1``, ``b2``
``az_bg``  m/s²   bogie frame vertical acceleration (coach only)               ``b1``, ``b2``
=========  =====  ==========================================================  ============

Wheel positions ``w{n}{L|R}``: wheelset ``n`` counted from the leading end in running
direction, ``L``/``R`` the left/right wheel in running direction. All lateral forces are
expressed along one track-fixed lateral axis ``y`` pointing to the *left* in running
direction, so ΣY of wheelset n is ``Y_w{n}L + Y_w{n}R`` and Y/Q of a wheel is ``Y/Q`` with
the same sign convention.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

WHEEL_POSITIONS = tuple(f"w{n}{s}" for n in range(1, 5) for s in "LR")
BODY_POSITIONS = ("b1", "b2")


@dataclass(frozen=True)
class ChannelKind:
    """One kind of raw channel: its canonical unit and the EN 14363 processing filter it gets.

    ``en_filter`` is a filter kind of :mod:`railval.core.filters` (EN 14363:2005 on-track
    tests: wheel–rail forces low-pass 20 Hz, car body accelerations band-pass 0.4–10 Hz; the
    bogie frame accelerations, supplementary quantities of :mod:`railval.core.supplementary`,
    the same band-pass).
    """

    kind: str
    unit: str
    en_filter: str
    meaning: str
    positions: tuple[str, ...]

    @property
    def filter_label(self) -> str:
        """The EN filter as shown to a reader (``"low-pass 20 Hz"``)."""
        return EN_FILTER_LABELS[self.en_filter]


#: filter kind of :mod:`railval.core.filters` → how a reader sees it
EN_FILTER_LABELS: dict[str, str] = {"lowpass": "low-pass 20 Hz", "bandpass": "band-pass 0.4–10 Hz"}

#: THE channel registry (kind → unit, EN filter, meaning); every layer reads this one.
CHANNELS: dict[str, ChannelKind] = {c.kind: c for c in (
    ChannelKind("Y", "kN", "lowpass", "lateral wheel–rail (guiding) force of one wheel", WHEEL_POSITIONS),
    ChannelKind("Q", "kN", "lowpass", "vertical wheel–rail force of one wheel", WHEEL_POSITIONS),
    ChannelKind("ay_cb", "m/s^2", "bandpass", "car body lateral acceleration", BODY_POSITIONS),
    ChannelKind("az_cb", "m/s^2", "bandpass", "car body vertical acceleration", BODY_POSITIONS),
    ChannelKind("ay_bg", "m/s^2", "bandpass", "bogie frame lateral acceleration", BODY_POSITIONS),
    ChannelKind("az_bg", "m/s^2", "bandpass", "bogie frame vertical acceleration", BODY_POSITIONS),
)}

#: channel kind → canonical unit (a view of :data:`CHANNELS`)
CHANNEL_KINDS: dict[str, str] = {k: c.unit for k, c in CHANNELS.items()}


def channel_kind(name: str) -> ChannelKind | None:
    """The registry entry of a channel name (``"ay_cb_b1"`` → ay_cb), None for an unknown kind."""
    return CHANNELS.get(split_channel(name)[0])


ZONES = (1, 2, 3, 4)


def channel_name(kind: str, position: str) -> str:
    return f"{kind}_{position}"


def split_channel(name: str) -> tuple[str, str]:
    """``"ay_cb_b1" -> ("ay_cb", "b1")``; ``"Y_w1L" -> ("Y", "w1L")``."""
    kind, _, position = name.rpartition("_")
    return kind, position


@dataclass(frozen=True)
class SectionInfo:
    """One test section (a part of track, Polach & Böttcher 2014 §2).

    radius_m: curve radius of the constant-curvature part in m (``inf`` or 0 → straight);
    cant_mm: cant in mm; speed_kmh: nominal speed; zone: EN 14363 test zone (1–4) after any
    override; eval_start_m/eval_end_m: the evaluated (constant-curvature) range on the
    distance axis in m.
    """

    id: str
    radius_m: float
    cant_mm: float
    speed_kmh: float
    zone: int
    eval_start_m: float
    eval_end_m: float
    country: str = ""
    curve_direction: int = 1  # +1 left-hand curve, -1 right-hand curve


@dataclass
class SignalSet:
    """All channels of one section from one source (measurement or a configuration).

    Samples are equally spaced in time at ``fs`` Hz; ``distance_m`` gives the travelled
    distance of every sample (monotonic, m) so distance-based processing (2 m sliding mean)
    handles variable speed. ``channels`` maps channel name → 1-D float array of the same
    length as ``time_s``.
    """

    fs: float
    time_s: np.ndarray
    distance_m: np.ndarray
    channels: dict[str, np.ndarray] = field(default_factory=dict)
    #: channel name → SHA-256 content hash of its stored samples (filled by ``db``)
    hashes: dict[str, str] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.time_s.shape[0])
