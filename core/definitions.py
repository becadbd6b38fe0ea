"""The open choices of the EN 14363 statistics and their alternative readings (docs/validation.md).

Polach & Böttcher 2014 §5 (Table 2) prescribes "0.15 %/50 %/99.85 % values calculated from the
cumulative curve as described in EN 14363" and, for (Y/Q)_max and ΣY_max, a "sliding mean
(2 m window, step 0.5 m)". Neither text fixes three details that an independent
implementation has to choose:

``percentile``
    how a p-value is read from the cumulative curve of n samples:

    * ``inverted_cdf`` (railval's reading) — the smallest sample x with F_n(x) ≥ p, i.e. the
      sample of rank ⌈n·p⌉ (Hyndman & Fan 1996 type 1, ``numpy.quantile(method="inverted_cdf")``):
      a value read off the step-shaped cumulative curve, never one that was not measured;
    * ``linear`` — linear interpolation between order statistics at h = (n − 1)·p
      (Hyndman & Fan type 7, numpy's default ``method="linear"``).

``grid``
    where the 0.5 m grid of window centres starts:

    * ``section_start`` (railval) — centres at eval_start + 1 m + k·0.5 m: the grid is tied to
      the section's evaluated range, identical for measurement and simulation whatever their
      sampling;
    * ``first_sample`` — centres at d₀ + 1 m + k·0.5 m with d₀ the distance of the first
      evaluated sample (a sample-driven implementation).

``window``
    what "mean over 2 m" means:

    * ``interpolant`` (railval) — distance-weighted mean: the exact integral of the signal's
      linear interpolant over [x − 1 m, x + 1 m] divided by 2 m (independent of speed changes
      within the window);
    * ``samples_closed`` — arithmetic mean of the samples with x − 1 ≤ d ≤ x + 1;
    * ``samples_half_open`` — arithmetic mean of the samples with x − 1 ≤ d < x + 1.

A :class:`Reading` is one combination; :data:`CHOSEN` is railval's, :data:`READINGS` all
2 × 2 × 3 = 12. Which choices enter a quantity: the percentile method every percentile-based
quantity (median and maxima), the grid and window only the sliding-mean quantities; rms
values depend on none (:func:`alternatives_for`).

References
----------
Polach & Böttcher 2014 §5, Table 2 and its footnote a. EN 14363:2005, percentile values from
the cumulative frequency distribution; sliding mean over 2 m with 0.5 m steps for ΣY and Y/Q.
Hyndman, R.J. & Fan, Y. (1996) Sample quantiles in statistical packages, Am. Stat. 50(4),
361–365 (types 1 and 7).
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass

import numpy as np

from railval.core.errors import InvalidParameter, InvalidSignal

PERCENTILE_METHODS: tuple[str, ...] = ("inverted_cdf", "linear")
GRID_ALIGNMENTS: tuple[str, ...] = ("section_start", "first_sample")
WINDOW_MEANS: tuple[str, ...] = ("interpolant", "samples_closed", "samples_half_open")

TEXT = {
    "inverted_cdf": "percentile = smallest sample with F_n ≥ p (inverted CDF, Hyndman–Fan type 1)",
    "linear": "percentile linearly interpolated at (n − 1)·p (Hyndman–Fan type 7)",
    "section_start": "window centres from the evaluated range's start + 1 m",
    "first_sample": "window centres from the first evaluated sample + 1 m",
    "interpolant": "distance-weighted mean (integral of the linear interpolant / 2 m)",
    "samples_closed": "mean of the samples in the closed window [x − 1 m, x + 1 m]",
    "samples_half_open": "mean of the samples in the half-open window [x − 1 m, x + 1 m)",
}

SHORT = {"inverted_cdf": "inverted-CDF percentiles", "linear": "linear percentiles",
         "section_start": "grid from range start", "first_sample": "grid from first sample",
         "interpolant": "distance-weighted mean", "samples_closed": "closed sample window",
         "samples_half_open": "half-open sample window"}


@dataclass(frozen=True)
class Reading:
    """One reading of the open choices: percentile method, grid alignment, window mean."""

    percentile: str
    grid: str
    window: str

    def __post_init__(self) -> None:
        for value, allowed, name in ((self.percentile, PERCENTILE_METHODS, "percentile"),
                                     (self.grid, GRID_ALIGNMENTS, "grid"),
                                     (self.window, WINDOW_MEANS, "window")):
            if value not in allowed:
                raise InvalidParameter(f"reading {name} must be one of {allowed}, got {value!r}")

    @property
    def id(self) -> str:
        return f"percentile={self.percentile};grid={self.grid};window={self.window}"

    @property
    def sliding(self) -> tuple[str, str]:
        return self.grid, self.window

    def differs_from_chosen(self, sliding_mean: bool) -> list[str]:
        """The components in which this reading differs from :data:`CHOSEN` and that enter a
        quantity (with or without sliding mean)."""
        out = []
        if self.percentile != CHOSEN.percentile:
            out.append("percentile")
        if sliding_mean:
            if self.grid != CHOSEN.grid:
                out.append("grid")
            if self.window != CHOSEN.window:
                out.append("window")
        return out

    def to_dict(self) -> dict[str, str]:
        return {"id": self.id, "percentile": self.percentile, "grid": self.grid,
                "window": self.window}

    def short(self, sliding_mean: bool = True) -> str:
        """The components that differ from :data:`CHOSEN`, in a few words
        (e.g. "linear percentiles + half-open sample window")."""
        words = {"percentile": SHORT[self.percentile], "grid": SHORT[self.grid],
                 "window": SHORT[self.window]}
        parts = [words[c] for c in self.differs_from_chosen(sliding_mean)]
        return " + ".join(parts) or "chosen reading"

    def describe(self, sliding_mean: bool = True) -> str:
        parts = [self.percentile] + ([self.grid, self.window] if sliding_mean else [])
        return "; ".join(TEXT[p] for p in parts)


CHOSEN = Reading("inverted_cdf", "section_start", "interpolant")
READINGS: tuple[Reading, ...] = tuple(
    Reading(p, g, w) for p, g, w in itertools.product(PERCENTILE_METHODS, GRID_ALIGNMENTS,
                                                      WINDOW_MEANS))
SLIDING_VARIANTS: tuple[tuple[str, str], ...] = tuple(itertools.product(GRID_ALIGNMENTS,
                                                                        WINDOW_MEANS))


def alternatives_for(quantity) -> list[Reading]:
    """The readings other than :data:`CHOSEN` that can change ``quantity``'s value, one per
    distinct effect: all 11 for a sliding-mean quantity, the linear percentile for the other
    percentile-based ones, none for rms values. ``quantity``: a registry entry with
    ``processing`` and ``sliding_mean`` (:mod:`railval.core.quantities`).

    Parameters
    ----------
    quantity : Quantity
        A registry entry of :data:`railval.core.quantities.QUANTITIES`.

    Returns
    -------
    list of Reading
    """
    if quantity.processing == "rms":
        return []
    if quantity.sliding_mean:
        return [r for r in READINGS if r != CHOSEN]
    return [r for r in READINGS if r.percentile != CHOSEN.percentile
            and r.sliding == CHOSEN.sliding]


def sorted_percentiles(srt: np.ndarray, ps, method: str) -> np.ndarray:
    """Percentiles ``ps`` (fractions) of every row of the ascending-sorted ``srt`` (shape
    (rows, n)); returns shape (rows, len(ps)). ``inverted_cdf``: the sample of rank ⌈n·p⌉
    (rank 1 for n·p < 1); ``linear``: numpy's type-7 interpolation at h = (n − 1)·p with
    numpy's own lerp, so the result equals ``numpy.quantile(x, p, method=...)`` bit for bit.

    Parameters
    ----------
    srt : numpy.ndarray
        Rows sorted ascending, shape (rows, n).
    ps : sequence of float
        Percentiles as fractions in [0, 1].
    method : str
        ``"inverted_cdf"`` or ``"linear"``.

    Returns
    -------
    numpy.ndarray
        Shape (rows, len(ps)), unit of ``srt``.

    Examples
    --------
    >>> sorted_percentiles(np.array([[1.0, 2.0, 3.0, 4.0]]), [0.5], "inverted_cdf")
    array([[2.]])
    """
    srt = np.atleast_2d(srt)
    return percentiles_from_order(lambda i: srt[:, i], srt.shape[-1], ps, method)


def percentile_ranks(n: int, ps, method: str) -> list[int]:
    """The 0-based positions in the sorted sample of size ``n`` that :func:`sorted_percentiles`
    reads for ``ps`` under ``method`` (a percentile needs only these order statistics).

    Parameters
    ----------
    n : int
        Sample size.
    ps : sequence of float
        Percentiles as fractions.
    method : str
        ``"inverted_cdf"`` or ``"linear"``.

    Returns
    -------
    list of int

    Examples
    --------
    >>> percentile_ranks(4, [0.5], "inverted_cdf")
    [1]
    """
    return list(_percentile_ranks(int(n), tuple(float(p) for p in ps), method))


@functools.lru_cache(maxsize=1024)
def _percentile_ranks(n: int, ps: tuple[float, ...], method: str) -> tuple[int, ...]:
    read: list[int] = []

    def take(i: int) -> np.ndarray:  # records which order statistic the formula reads
        read.append(i)
        return np.zeros(1)

    percentiles_from_order(take, n, ps, method)
    return tuple(sorted(set(read)))


def percentiles_from_order(take, n: int, ps, method: str) -> np.ndarray:
    """:func:`sorted_percentiles` from the order statistics alone: ``take(i)`` gives the
    samples of 0-based rank ``i`` of every row (shape (rows,)), ``n`` the row length.

    Parameters
    ----------
    take : callable
        0-based rank → that order statistic of every row, shape (rows,).
    n : int
        Row length.
    ps, method
        As in :func:`sorted_percentiles`.

    Returns
    -------
    numpy.ndarray
        Shape (rows, len(ps)).
    """
    ps = [float(p) for p in ps]
    if method not in PERCENTILE_METHODS:
        raise InvalidParameter(
            f"percentile method must be one of {PERCENTILE_METHODS}, got {method!r}")
    cols = []
    for p in ps:
        mode, lo, hi, g, omg = _percentile_read(n, p, method)
        if mode == 0:
            cols.append(take(lo))
            continue
        a, b = take(lo), take(hi)
        diff = b - a
        # numpy's _lerp: a + diff·g, from the upper end for g ≥ 0.5 (monotone, exact ends)
        cols.append(b - diff * omg if mode == 2 else a + diff * g)
    return np.stack(cols, axis=-1)


def _percentile_read(n: int, p: float, method: str) -> tuple[int, int, int, float, float]:
    """How :func:`percentiles_from_order` reads percentile ``p`` of ``n`` sorted samples:
    ``(mode, lo, hi, g, 1 − g)``. ``inverted_cdf``: mode 0, the sample of 0-based rank
    ``lo`` = ⌈n·p⌉ − 1 (clipped to 0..n − 1); ``linear``: h = (n − 1)·p, ``lo`` = ⌊h⌋,
    ``hi`` = lo + 1 (both ≤ n − 1), g = h − lo; mode 2 (``b − diff·(1 − g)``) for g ≥ 0.5,
    else mode 1 (``a + diff·g``), a and b the samples of ranks lo and hi (numpy's lerp)."""
    if method == "inverted_cdf":
        idx = min(max(int(np.ceil(n * p - 1e-12)) - 1, 0), n - 1)
        return 0, idx, idx, 0.0, 1.0
    h = (n - 1) * p
    lo = min(int(np.floor(h)), n - 1)
    hi = min(lo + 1, n - 1)
    g = h - lo
    return (2 if g >= 0.5 else 1), lo, hi, g, 1.0 - g


@functools.lru_cache(maxsize=1024)
def percentile_recipe(n: int, ps: tuple[float, ...], methods: tuple[str, ...]) -> tuple:
    """The order statistics percentiles ``ps`` of ``n`` samples need under each of
    ``methods`` and how they are read, for compiled callers
    (:func:`railval.core.en_kernels._read_percentiles`): ``(ranks, cols, mode, g, omg)`` —
    ``ranks`` the sorted 0-based ranks (int64), ``cols[m, t]`` the columns (in ``ranks``) of
    the samples a and b of percentile t under method m, ``mode``, ``g``, ``omg`` = 1 − g as
    :func:`_percentile_read` gives them (the same reading as :func:`percentiles_from_order`).
    Cached per ``n``: the arrays must not be written to.

    Parameters
    ----------
    n : int
        Sample size.
    ps : tuple of float
        Percentiles as fractions.
    methods : tuple of str
        Percentile methods (:data:`PERCENTILE_METHODS`).

    Returns
    -------
    tuple of numpy.ndarray
    """
    for m in methods:
        if m not in PERCENTILE_METHODS:
            raise InvalidParameter(
                f"percentile method must be one of {PERCENTILE_METHODS}, got {m!r}")
    reads = [[_percentile_read(int(n), float(p), m) for p in ps] for m in methods]
    ranks = sorted({i for row in reads for r in row for i in r[1:3]})
    column = {r: c for c, r in enumerate(ranks)}
    cols = np.array([[[column[r[1]], column[r[2]]] for r in row] for row in reads],
                    dtype=np.int64).reshape(len(methods), len(ps), 2)
    mode = np.array([[r[0] for r in row] for row in reads], dtype=np.int64
                    ).reshape(len(methods), len(ps))
    g = np.array([[r[3] for r in row] for row in reads], dtype=np.float64
                 ).reshape(len(methods), len(ps))
    omg = np.array([[r[4] for r in row] for row in reads], dtype=np.float64
                   ).reshape(len(methods), len(ps))
    out = (np.array(ranks, dtype=np.int64), cols, mode, g, omg)
    for a in out:
        a.flags.writeable = False
    return out


def window_count(start_m: float, end_m: float, origin_m: float, window_m: float,
                 step_m: float) -> int:
    """The number of centres :func:`window_centres` gives (raises as it does).

    Parameters
    ----------
    start_m, end_m, origin_m, window_m, step_m : float
        As in :func:`window_centres`.

    Returns
    -------
    int
    """
    if window_m <= 0 or step_m <= 0:
        raise InvalidParameter(
            f"window_m and step_m must be > 0 m, got window_m={window_m}, step_m={step_m}")
    if end_m - origin_m < window_m or origin_m < start_m:
        raise InvalidSignal(
            f"sliding-window grid from {origin_m} m does not fit a {window_m} m window inside "
            f"the evaluated range {start_m}–{end_m} m")
    return int(np.floor((end_m - origin_m - window_m) / step_m + 1e-9)) + 1


def window_centres(start_m: float, end_m: float, origin_m: float, window_m: float,
                   step_m: float) -> np.ndarray:
    """Centres ``origin + w/2 + k·step`` of the windows lying inside [start_m, end_m] (m).

    Parameters
    ----------
    start_m, end_m : float
        Evaluated range in m.
    origin_m : float
        Grid origin in m (first window's start).
    window_m, step_m : float
        Window length and step in m.

    Returns
    -------
    numpy.ndarray
        Centres in m, shape (K,).

    Examples
    --------
    >>> window_centres(0.0, 3.0, 0.0, 2.0, 0.5)
    array([1. , 1.5, 2. ])
    """
    n_c = window_count(start_m, end_m, origin_m, window_m, step_m)
    return origin_m + window_m / 2.0 + step_m * np.arange(n_c)


def sample_window_means(values: np.ndarray, distance_m: np.ndarray, centres: np.ndarray,
                        window_m: float, closed: bool, prefix: np.ndarray | None = None) -> np.ndarray:
    """Arithmetic mean of the samples inside each window ``[x − w/2, x + w/2]`` (``closed``)
    or ``[x − w/2, x + w/2)`` of every row of ``values`` (shape (rows, n)) on the distance
    axis ``distance_m`` (increasing, m). Windows holding no sample give NaN. ``prefix``: the
    rows' prefix sums (shape (rows, n + 1), first column 0) when already formed.

    Parameters
    ----------
    values : numpy.ndarray
        Shape (rows, n), any unit.
    distance_m : numpy.ndarray
        Increasing distance axis in m, shape (n,).
    centres : numpy.ndarray
        Window centres in m, shape (K,).
    window_m : float
        Window length w in m.
    closed : bool
        Whether the window includes its upper end.
    prefix : numpy.ndarray or None
        Prefix sums of ``values``, shape (rows, n + 1).

    Returns
    -------
    numpy.ndarray
        Shape (rows, K), unit of ``values``.
    """
    v = np.atleast_2d(np.asarray(values, dtype=np.float64))
    d = np.asarray(distance_m, dtype=np.float64)
    half = window_m / 2.0
    lo = np.searchsorted(d, centres - half, side="left")
    hi = np.searchsorted(d, centres + half, side="right" if closed else "left")
    if prefix is None:
        cum = np.zeros((v.shape[0], v.shape[1] + 1))
        np.cumsum(v, axis=1, out=cum[:, 1:])
    else:
        cum = prefix
    count = (hi - lo).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        means = (cum[:, hi] - cum[:, lo]) / count
    means[:, count == 0] = np.nan
    return means
