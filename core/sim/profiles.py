"""Wheel–rail contact geometry as data: the rolling-radius difference function Δr(y) of a
measured wheel and rail profile pair, tabulated over the wheelset's lateral displacement y as
EN 15302 computes it, with an optional contact-angle difference Δγ(y) (docs/simulator.md
"Contact geometry as data").

Convention (docs/simulator.md): y is the wheelset's lateral displacement towards the left rail
(the simulator's +y), Δr = r_left − r_right, Δγ = γ_left − γ_right. A cone of conicity λ has
Δr = 2·λ·y. A table whose y starts at 0 is the positive half of a symmetric profile pair and is
mirrored as an odd function (Δr(−y) = −Δr(y)).

The table is carried by a configuration as the template parameter ``contact_geometry``
(:class:`railval.core.sim.vehicles.VehicleModel`): ``{"y_mm": [...], "delta_r_mm": [...],
"delta_gamma_rad": [...] (optional), "source": "file name"}``; the simulator interpolates it
linearly (:mod:`railval.core.sim.kernel`) instead of the linear conicity.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from railval.core.errors import InvalidParameter

#: columns of the CSV file: required, then optional
REQUIRED_COLUMNS = ("y_mm", "delta_r_mm")
OPTIONAL_COLUMNS = ("delta_gamma_rad",)
#: bounds of the values (a flange contact lies within ≈ ±10 mm of the centred position; a flange
#: rise of real profiles reaches ≈ 10–20 mm of rolling radius; contact angles stay below 90°)
Y_LIMIT_MM = 30.0
DR_LIMIT_MM = 40.0
DGAMMA_LIMIT_RAD = 1.6
MIN_ROWS = 3
#: the amplitude at which EN 15302 states the equivalent conicity
REFERENCE_AMPLITUDE_MM = 3.0


@dataclass(frozen=True)
class ContactTable:
    """A checked Δr(y) table (y strictly increasing, covering y = 0), values in mm / rad."""

    y_mm: tuple[float, ...]
    delta_r_mm: tuple[float, ...]
    delta_gamma_rad: tuple[float, ...] | None = None
    source: str = ""

    def to_dict(self) -> dict:
        d = {"y_mm": list(self.y_mm), "delta_r_mm": list(self.delta_r_mm), "source": self.source}
        if self.delta_gamma_rad is not None:
            d["delta_gamma_rad"] = list(self.delta_gamma_rad)
        return d

    def kernel_array(self) -> np.ndarray:
        """(n, 3) float array for :func:`railval.core.sim.kernel.run_kernel`: y (m), Δr (m),
        Δγ (rad; zeros without the column)."""
        y = np.asarray(self.y_mm) * 1e-3
        dr = np.asarray(self.delta_r_mm) * 1e-3
        dg = np.asarray(self.delta_gamma_rad) if self.delta_gamma_rad is not None else np.zeros_like(y)
        return np.ascontiguousarray(np.column_stack([y, dr, dg]))

    def delta_r(self, y_mm: np.ndarray | float) -> np.ndarray:
        """Δr (mm) at ``y_mm``, linear interpolation, the end segments extended (as the kernel)."""
        return _interp(np.asarray(self.y_mm), np.asarray(self.delta_r_mm), np.asarray(y_mm, float))


def _interp(x: np.ndarray, f: np.ndarray, at: np.ndarray) -> np.ndarray:
    i = np.clip(np.searchsorted(x, at, side="right") - 1, 0, len(x) - 2)
    w = (at - x[i]) / (x[i + 1] - x[i])
    return f[i] + w * (f[i + 1] - f[i])


def _fail(source: str, line: int | None, msg: str) -> InvalidParameter:
    where = f"contact geometry file {source!r}" + (f", line {line}" if line is not None else "")
    return InvalidParameter(f"{where}: {msg}")


def parse_csv(text: str, source: str = "<table>") -> ContactTable:
    """Parse a rolling-radius difference file (docs/simulator.md "Contact geometry as data"):
    a header ``y_mm,delta_r_mm[,delta_gamma_rad]`` (any order; lines starting with ``#`` and
    blank lines are skipped), one row per lateral displacement. Raises
    :class:`InvalidParameter` naming the file, the line and the field: missing or unknown
    column, a value that is no finite number or is outside its bounds, y not strictly
    increasing, fewer than 3 rows, y = 0 not covered."""
    lines = [(n, ln) for n, ln in enumerate(text.splitlines(), 1) if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise _fail(source, None, "no header line (expected y_mm,delta_r_mm[,delta_gamma_rad])")
    hline, header = lines[0]
    cols = [c.strip() for c in next(csv.reader(io.StringIO(header)))]
    for c in REQUIRED_COLUMNS:
        if c not in cols:
            raise _fail(source, hline, f"missing column {c!r} (header: {','.join(cols)}; expected "
                                       "y_mm,delta_r_mm[,delta_gamma_rad])")
    unknown = [c for c in cols if c not in REQUIRED_COLUMNS + OPTIONAL_COLUMNS]
    if unknown or len(set(cols)) != len(cols):
        raise _fail(source, hline, f"unknown or repeated column(s) {unknown or cols}; allowed: "
                                   f"{', '.join(REQUIRED_COLUMNS + OPTIONAL_COLUMNS)}")
    values: dict[str, list[float]] = {c: [] for c in cols}
    for n, ln in lines[1:]:
        row = [x.strip() for x in next(csv.reader(io.StringIO(ln)))]
        if len(row) != len(cols):
            raise _fail(source, n, f"{len(row)} fields, the header has {len(cols)}")
        for c, x in zip(cols, row, strict=True):
            try:
                v = float(x)
            except ValueError:
                raise _fail(source, n, f"field {c!r}: {x!r} is not a number") from None
            values[c].append(v)
    lines_of_rows = [n for n, _ in lines[1:]]
    return check_table(values, source, lines_of_rows)


def check_table(data: Mapping, source: str = "<table>", lines: list[int] | None = None) -> ContactTable:
    """A :class:`ContactTable` from ``{"y_mm", "delta_r_mm"[, "delta_gamma_rad"][, "source"]}``
    (a parsed file or a stored configuration's ``contact_geometry``), checked as
    :func:`parse_csv` says; ``lines`` maps row i to its line in the file for the messages."""
    if not isinstance(data, Mapping):
        raise _fail(source, None, f"expected a table {{y_mm, delta_r_mm}}, got {type(data).__name__}")
    source = str(data.get("source") or source)
    for c in REQUIRED_COLUMNS:
        if c not in data:
            raise _fail(source, None, f"missing column {c!r}")
    at = (lambda i: lines[i]) if lines is not None else (lambda i: None)
    row = (lambda i: "") if lines is not None else (lambda i: f"row {i + 1}: ")
    cols = {c: data[c] for c in REQUIRED_COLUMNS + OPTIONAL_COLUMNS if data.get(c) is not None}
    n = len(cols["y_mm"])
    limits = {"y_mm": (Y_LIMIT_MM, "mm"), "delta_r_mm": (DR_LIMIT_MM, "mm"), "delta_gamma_rad": (DGAMMA_LIMIT_RAD, "rad")}
    for c, vals in cols.items():
        if len(vals) != n:
            raise _fail(source, None, f"column {c!r} has {len(vals)} values, y_mm has {n}")
        lim, unit = limits[c]
        for i, v in enumerate(vals):
            if not isinstance(v, int | float) or not math.isfinite(v) or abs(v) > lim:
                raise _fail(source, at(i), f"{row(i)}field {c!r} = {v!r} is outside [−{lim:g}, {lim:g}] {unit} "
                                           "or not a finite number")
    if n < MIN_ROWS:
        raise _fail(source, None, f"{n} rows; at least {MIN_ROWS} are needed")
    y = cols["y_mm"]
    for i in range(1, n):
        if not y[i] > y[i - 1]:
            raise _fail(source, at(i), f"{row(i)}y_mm = {y[i]:g} does not increase (previous row {y[i - 1]:g}); "
                                       "y must be strictly increasing")
    if y[0] > 0.0 or y[-1] <= 0.0:
        raise _fail(source, None, f"y_mm spans [{y[0]:g}, {y[-1]:g}] mm; it must cover y = 0 "
                                  "(or start at 0 for a symmetric pair)")
    return _mirrored(ContactTable(tuple(float(v) for v in y), tuple(float(v) for v in cols["delta_r_mm"]),
                                  tuple(float(v) for v in cols["delta_gamma_rad"]) if "delta_gamma_rad" in cols else None,
                                  source))


def _mirrored(t: ContactTable) -> ContactTable:
    """A table starting at y = 0 extended to negative y as an odd function (module docstring)."""
    if t.y_mm[0] < 0.0:
        return t
    k = 1  # y = 0 is not repeated
    y = tuple(-v for v in reversed(t.y_mm[k:])) + t.y_mm
    dr = tuple(-v for v in reversed(t.delta_r_mm[k:])) + t.delta_r_mm
    dg = (tuple(-v for v in reversed(t.delta_gamma_rad[k:])) + t.delta_gamma_rad
          if t.delta_gamma_rad is not None else None)
    return ContactTable(y, dr, dg, t.source)


def linear_table(conicity: float, y_max_mm: float = 12.0, *, root_onset_mm: float | None = None,
                 root_slope: float = 0.0, source: str = "linear") -> ContactTable:
    """The table of the simulator's own contact law: Δr = 2·λ·y, plus (with ``root_onset_mm``)
    the flange-root term ``root_slope``·(|y| − onset) beyond the onset (the flange-side wheel's
    radius only grows)
    (:mod:`railval.core.sim.model`, "Wheel–rail contact") — to check that the table path
    reproduces the conicity path."""
    knots = [0.0, y_max_mm] if root_onset_mm is None else [0.0, root_onset_mm, y_max_mm]
    dr = [2.0 * conicity * y + (root_slope * (y - root_onset_mm) if root_onset_mm is not None and
                                y > root_onset_mm else 0.0) for y in knots]
    return _mirrored(ContactTable(tuple(knots), tuple(dr), None, source))


def equivalent_conicity(table: ContactTable, amplitude_mm: float = REFERENCE_AMPLITUDE_MM, n: int = 4096) -> float:
    """Equivalent conicity λe of ``table`` at the wheelset amplitude ``amplitude_mm`` by
    harmonic linearisation (EN 15302, the method that linearises the Δr function for a
    sinusoidal wheelset motion y = ŷ·sin φ): the first Fourier coefficient of Δr(ŷ·sin φ)
    divided by 2ŷ, λe = (1/(2πŷ))·∫₀^{2π} Δr(ŷ·sin φ)·sin φ dφ (describing function of the
    nonlinearity: Gelb & Vander Velde, *Multiple-input describing functions and nonlinear
    system design*, 1968, ch. 2). A cone Δr = 2λy gives λ at every amplitude. Midpoint rule
    over ``n`` points (exact for the trigonometric polynomial of a cone; the error of a
    piecewise-linear table falls as 1/n²)."""
    a = float(amplitude_mm)
    if not (a > 0.0):
        raise InvalidParameter(f"equivalent conicity: amplitude must be > 0 mm, got {amplitude_mm!r}")
    phi = (np.arange(n) + 0.5) * (2.0 * math.pi / n)
    s = np.sin(phi)
    dr = table.delta_r(a * s)
    return float(np.sum(dr * s) * (2.0 * math.pi / n) / (2.0 * math.pi * a))
