"""Shared input validators of the metrics package (messages name quantity, bound and value)."""

from __future__ import annotations

import math

import numpy as np

from railval.core.errors import InvalidParameter, InvalidSignal


def as_signal(x: object, name: str, *, min_len: int = 2) -> np.ndarray:
    """Return ``x`` as a finite 1-D float64 array of at least ``min_len`` samples."""
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 1:
        raise InvalidSignal(f"{name} must be 1-D, got shape {a.shape}")
    if a.shape[0] < min_len:
        raise InvalidSignal(f"{name} needs at least {min_len} samples, got {a.shape[0]}")
    if not np.all(np.isfinite(a)):
        bad = int(np.count_nonzero(~np.isfinite(a)))
        raise InvalidSignal(f"{name} contains {bad} non-finite sample(s) (NaN/inf)")
    return a


def as_pair(measured: object, simulated: object, *, min_len: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Validate a measured/simulated pair that must already share one sampling grid."""
    m = as_signal(measured, "measured", min_len=min_len)
    c = as_signal(simulated, "simulated", min_len=min_len)
    if m.shape != c.shape:
        raise InvalidSignal(
            f"measured and simulated must have equal length on a common grid, got "
            f"{m.shape[0]} and {c.shape[0]} samples (use core.metrics.common_grid first)"
        )
    return m, c


def positive(value: float, name: str, unit: str = "") -> float:
    v = float(value)
    if not math.isfinite(v) or v <= 0.0:
        raise InvalidParameter(f"{name} must be a finite value > 0{(' ' + unit) if unit else ''}, got {value!r}")
    return v


def fraction(value: float, name: str, *, lo: float = 0.0, hi: float = 1.0,
             lo_open: bool = True, hi_open: bool = False) -> float:
    v = float(value)
    too_low = v <= lo if lo_open else v < lo
    too_high = v >= hi if hi_open else v > hi
    if not math.isfinite(v) or too_low or too_high:
        lb = "(" if lo_open else "["
        rb = ")" if hi_open else "]"
        raise InvalidParameter(f"{name} must lie in {lb}{lo:g}, {hi:g}{rb}, got {value!r}")
    return v
