"""Track sections for the built-in simulator: layout (straight / clothoid transition with linear
cant ramp / constant radius / transition / straight), speed and irregularities.

Irregularities (vertical level, alignment, cross level, gauge) are either given ("measured")
arrays on a distance grid, or generated from the ORE B176 / ERRI B176 one-sided spectra
(ERRI B176 RP1, 1989; as used in Claus H., Schiehlen W., *Modeling and simulation of railway
bogie structural vibrations*, VSD 29 suppl., 1998, and in the Manchester Benchmarks):

    S_v(Ω) = A_v Ω_c² / ((Ω² + Ω_r²)(Ω² + Ω_c²))                 vertical level   [m²/(rad/m)]
    S_a(Ω) = A_a Ω_c² / ((Ω² + Ω_r²)(Ω² + Ω_c²))                 alignment        [m²/(rad/m)]
    S_c(Ω) = (A_v/b²) Ω_c² Ω² / ((Ω² + Ω_r²)(Ω² + Ω_c²)(Ω² + Ω_s²))  cross level angle [rad²/(rad/m)]
    S_g(Ω) = A_g Ω_c² Ω² / ((Ω² + Ω_r²)(Ω² + Ω_c²)(Ω² + Ω_s²))   gauge            [m²/(rad/m)]

Ω_c = 0.8246, Ω_r = 0.0206, Ω_s = 0.4380 rad/m, b = 0.75 m; low level A_v = 4.032e-7,
A_a = 2.119e-7 rad·m; high level A_v = 1.080e-6, A_a = 6.125e-7 rad·m. ERRI B176 gives no gauge
spectrum of this form; we take A_g = A_a, i.e. the cross-level shape with the alignment
amplitude (a documented assumption of this simulator). The cross
level is returned as the height difference of the rails, left minus right, 2b·angle (m).
Generation: random phases, amplitudes sqrt(2·S(Ω_k)·ΔΩ) restricted to the wavelength band
[lambda_min, lambda_max] (default 3–70 m, EN 13848-1 D1+D2), on a 0.5 m grid, with a 50 m
cosine taper at the start so a simulation starts from rest.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from railval.core.errors import InvalidParameter

G = 9.81
GAUGE_HALF_BASE = 0.75  # m, b in the ORE spectra (half the rail spacing)
S_TRACK = 1.5  # m, rail centre spacing used for cant: angle = h / s (standard-gauge rail centre spacing, s = 1500 mm)
DS = 0.5  # m, irregularity grid spacing
OMEGA_C, OMEGA_R, OMEGA_S = 0.8246, 0.0206, 0.4380
ORE_LEVELS = {"low": (4.032e-7, 2.119e-7), "high": (1.080e-6, 6.125e-7)}
IRREGULARITY_KEYS = ("vertical", "alignment", "cross_level", "gauge")


def ore_b176_psd(omega: np.ndarray, kind: str, level: str = "low") -> np.ndarray:
    """One-sided ORE B176 PSD at spatial angular frequency ``omega`` (rad/m).

    ``kind`` one of ``vertical``, ``alignment`` (m²/(rad/m)), ``cross_level`` (height difference
    of the rails, m²/(rad/m)), ``gauge`` (m²/(rad/m)). See the module docstring for the source.

    Parameters
    ----------
    omega : numpy.ndarray
        Spatial angular frequency in rad/m, any shape.
    kind : str
        ``"vertical"``, ``"alignment"``, ``"cross_level"`` or ``"gauge"``.
    level : str
        ``"low"`` or ``"high"``.

    Returns
    -------
    numpy.ndarray
        PSD in m²/(rad/m), shape of ``omega``.

    Raises
    ------
    InvalidParameter
        An unknown level.
    """
    if level not in ORE_LEVELS:
        raise InvalidParameter(f"irregularity level {level!r} unknown; known: {sorted(ORE_LEVELS)}")
    a_v, a_a = ORE_LEVELS[level]
    w2 = np.asarray(omega, dtype=float) ** 2
    base = OMEGA_C**2 / ((w2 + OMEGA_R**2) * (w2 + OMEGA_C**2))
    if kind == "vertical":
        return a_v * base
    if kind == "alignment":
        return a_a * base
    shape = base * w2 / (w2 + OMEGA_S**2)
    b = GAUGE_HALF_BASE
    if kind == "cross_level":
        return (a_v / b**2) * shape * (2 * b) ** 2
    if kind == "gauge":
        return a_a * shape
    raise InvalidParameter(f"irregularity kind {kind!r} unknown; known: {IRREGULARITY_KEYS}")


def generate_irregularities(length_m: float, *, level: str = "low", seed: int = 0,
                            lambda_min: float = 3.0, lambda_max: float = 70.0, s0: float = 0.0,
                            taper_m: float = 50.0, scale: float = 1.0) -> dict[str, np.ndarray]:
    """Random irregularities (m) on the grid ``s0 + k·DS`` covering ``length_m``, with the ORE
    B176 spectra of ``level`` between wavelengths ``lambda_min`` and ``lambda_max`` (m).

    Returns ``{"s": grid, "vertical", "alignment", "cross_level", "gauge"}``.

    Parameters
    ----------
    length_m : float
        Length to cover in m.
    level : str
        ORE B176 level, ``"low"`` or ``"high"``.
    seed : int
        Random seed (same seed, same irregularities).
    lambda_min, lambda_max : float
        Wavelength band in m.
    s0 : float
        Grid start in m.
    taper_m : float
        Length in m of the cosine taper at the start (a simulation starts from rest).
    scale : float
        Factor on all amplitudes.

    Returns
    -------
    dict of str to numpy.ndarray
        Grid ``s`` in m and the four irregularities in m, all of shape (K,).
    """
    if not (0 < lambda_min < lambda_max):
        raise InvalidParameter(f"irregularity band must satisfy 0 < lambda_min < lambda_max, got "
                               f"[{lambda_min}, {lambda_max}] m")
    n = math.ceil(length_m / DS) + 1
    nfft = 1 << math.ceil(math.log2(max(2 * n, 256)))
    rng = np.random.default_rng(seed)
    omega = 2 * np.pi * np.fft.rfftfreq(nfft, DS)
    dom = omega[1] - omega[0]
    band = (omega >= 2 * np.pi / lambda_max) & (omega <= 2 * np.pi / lambda_min)
    s = s0 + DS * np.arange(n)
    taper = np.clip((s - s0) / max(taper_m, 1e-9), 0.0, 1.0)
    taper = 0.5 - 0.5 * np.cos(np.pi * taper)
    out = {"s": s}
    for kind in IRREGULARITY_KEYS:
        amp = np.zeros_like(omega)
        amp[band] = np.sqrt(2.0 * ore_b176_psd(omega[band], kind, level) * dom)
        phase = rng.uniform(0, 2 * np.pi, omega.size)
        spec = amp * np.exp(1j * phase) * (nfft / 2)
        x = np.fft.irfft(spec, nfft)[:n]
        out[kind] = scale * x * taper
    return out


@dataclass
class TrackSection:
    """One test section.

    Layout lengths in m (straight in, clothoid + linear cant ramp in, constant radius, out);
    ``radius_m`` (0/inf = straight), ``cant_mm``, ``curve_direction`` (+1 left, −1 right),
    ``speed_kmh``. ``irregularities``: ``{"s", "vertical", "alignment", "cross_level", "gauge"}``
    in m on a uniform grid (measured), or ``None`` to generate from ``irregularity_level`` with
    ``seed``.
    """

    id: str
    speed_kmh: float
    radius_m: float = 0.0
    cant_mm: float = 0.0
    curve_direction: int = 1
    straight_in_m: float = 300.0
    transition_in_m: float = 0.0
    curve_m: float = 400.0
    transition_out_m: float = 0.0
    straight_out_m: float = 300.0
    irregularities: dict | None = None
    irregularity_level: str = "low"
    seed: int = 0
    extra: dict = field(default_factory=dict)

    def __post_init__(self):
        if not (self.speed_kmh > 0):
            raise InvalidParameter(f"section {self.id}: speed_kmh must be > 0, got {self.speed_kmh}")
        for name in ("straight_in_m", "transition_in_m", "curve_m", "transition_out_m", "straight_out_m"):
            if getattr(self, name) < 0:
                raise InvalidParameter(f"section {self.id}: layout {name} must be >= 0 m, got {getattr(self, name)}")
        if self.curve_direction not in (1, -1):
            raise InvalidParameter(f"section {self.id}: curve_direction must be 1 or -1, got {self.curve_direction}")
        if self.is_curve and abs(self.radius_m) < 100:
            raise InvalidParameter(f"section {self.id}: radius_m must be >= 100 m, got {self.radius_m}")

    @property
    def is_curve(self) -> bool:
        return bool(self.radius_m) and math.isfinite(self.radius_m)

    @property
    def length_m(self) -> float:
        return (self.straight_in_m + self.transition_in_m + self.curve_m + self.transition_out_m
                + self.straight_out_m)

    @property
    def speed_ms(self) -> float:
        return self.speed_kmh / 3.6

    @property
    def eval_range(self) -> tuple[float, float]:
        """Constant-curvature range on the distance axis (m)."""
        a = self.straight_in_m + self.transition_in_m
        return a, a + self.curve_m

    def cant_deficiency_acc(self) -> float:
        """Quasi-static lateral acceleration in the track plane a_q = v²/R − g·h/s (m/s², s =
        1500 mm) in the constant curve (EN 14363 / docs/design.md §6)."""
        if not self.is_curve:
            return 0.0
        return self.speed_ms**2 / abs(self.radius_m) - G * self.cant_mm / 1000.0 / S_TRACK

    def geometry(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed curvature (1/m, + = left) and cant angle (rad, h/s, + raises the right rail for a
        left curve) at distances ``s`` (m): 0 on the straights, linear on the transitions (clothoid,
        linear cant ramp), constant in the curve."""
        s = np.asarray(s, dtype=float)
        if not self.is_curve:
            z = np.zeros_like(s)
            return z, z.copy()
        a0 = self.straight_in_m
        a1 = a0 + self.transition_in_m
        a2 = a1 + self.curve_m
        a3 = a2 + self.transition_out_m
        ramp = np.interp(s, [a0, a1, a2, a3], [0.0, 1.0, 1.0, 0.0], left=0.0, right=0.0)
        if self.transition_in_m == 0:
            ramp = np.where((s >= a0) & (s <= a2), 1.0, ramp)
        if self.transition_out_m == 0:
            ramp = np.where((s >= a1) & (s <= a2), 1.0, ramp)
        d = float(self.curve_direction)
        return d * ramp / abs(self.radius_m), d * ramp * (self.cant_mm / 1000.0) / S_TRACK

    def irregularity_arrays(self, s0: float, s1: float, scale: float = 1.0,
                            use_measured: bool = True) -> dict[str, np.ndarray]:
        """Irregularities (m) on the grid from ``s0`` to ``s1``: the measured ones when present
        and ``use_measured``, else generated (ORE B176 ``irregularity_level``, ``seed``)."""
        if use_measured and self.irregularities is not None:
            src = self.irregularities
            grid = s0 + DS * np.arange(math.ceil((s1 - s0) / DS) + 1)
            out = {"s": grid}
            for k in IRREGULARITY_KEYS:
                out[k] = scale * np.interp(grid, np.asarray(src["s"], float), np.asarray(src[k], float),
                                           left=0.0, right=0.0)
            return out
        return generate_irregularities(s1 - s0, level=self.irregularity_level, seed=self.seed,
                                       s0=s0, scale=scale)

    @classmethod
    def from_info(cls, info, layout: dict | None = None, **kw) -> TrackSection:
        """Build from a :class:`railval.core.types.SectionInfo` and its optional ``layout`` record (see
        docs/simulator.md). Without a layout the evaluated range is the constant curve, preceded
        by a transition of min(6 s·v, 150 m, half the run-in) and followed by ≈ 10 s of track."""
        lay = dict(layout or {})
        radius = float(info.radius_m or 0.0)
        if not math.isfinite(radius):
            radius = 0.0
        v = float(info.speed_kmh) / 3.6
        if {"straight_in_m", "curve_m"} <= set(lay):
            geom = {k: float(lay.get(k, 0.0)) for k in
                    ("straight_in_m", "transition_in_m", "curve_m", "transition_out_m", "straight_out_m")}
        else:
            # no layout: the constant curve is the evaluated range; transitions of up to
            # min(6 s·v, 150 m) end where it starts; ≈ 10 s of run-out after it
            start = max(float(info.eval_start_m), 0.0)
            run = max(10.0 * v, 100.0)
            trans = min(6.0 * v, 150.0, 0.5 * start) if radius else 0.0
            geom = {"straight_in_m": start - trans, "transition_in_m": trans,
                    "curve_m": float(info.eval_end_m - info.eval_start_m),
                    "transition_out_m": trans, "straight_out_m": max(run - trans, 50.0)}
        irr = lay.get("irregularities")
        irr_arr = None
        if irr:
            n = len(irr["vertical_mm"])
            s = float(irr.get("s0_m", 0.0)) + float(irr.get("ds_m", DS)) * np.arange(n)
            irr_arr = {"s": s}
            for k in IRREGULARITY_KEYS:
                irr_arr[k] = np.asarray(irr[f"{k}_mm"], dtype=float) / 1000.0
        seed = int(lay.get("seed", _stable_seed(info.id)))
        return cls(id=info.id, speed_kmh=float(info.speed_kmh), radius_m=radius,
                   cant_mm=float(info.cant_mm or 0.0), curve_direction=int(info.curve_direction or 1),
                   irregularities=irr_arr, irregularity_level=str(lay.get("irregularity_level", "low")),
                   seed=seed, **geom, **kw)


def _stable_seed(text: str) -> int:
    """A seed from a section id that is the same in every process (unlike ``hash``)."""
    h = 2166136261
    for ch in text.encode():
        h = ((h ^ ch) * 16777619) & 0xFFFFFFFF
    return h


def irregularities_to_layout(irr: dict[str, np.ndarray]) -> dict:
    """Measured irregularities as the JSON ``layout["irregularities"]`` record (mm, 0.01 mm)."""
    s = np.asarray(irr["s"], float)
    out = {"ds_m": float(s[1] - s[0]), "s0_m": float(s[0])}
    for k in IRREGULARITY_KEYS:
        out[f"{k}_mm"] = [round(float(x) * 1000.0, 2) for x in irr[k]]
    return out
