"""Shared checks of one recording (time axis, distance axis, channel arrays).

Used by the importer (errors become :class:`railval.core.errors.CampaignFormatError` naming the
file) and by :func:`railval.db.repo.store_configuration` (errors become
:class:`railval.core.errors.InvalidSignal`). Both paths therefore accept and reject the same data.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from railval.core.errors import RailvalError

#: tolerated deviation of a time stamp from the uniform grid t0 + i/fs, as a fraction of
#: the sampling period (a logger with 1 % jitter is still "equally spaced")
TIME_JITTER_FRACTION = 0.01


class RecordingProblem(RailvalError):
    """A check failed; ``field`` names the column or key, the message says bound and value."""

    def __init__(self, field: str, message: str):
        self.field = field
        super().__init__(message)


def estimate_fs(time_s: np.ndarray) -> float:
    """Sampling rate in Hz from an equally spaced time axis: (n − 1)/(t[-1] − t[0]).

    Rounded to 1 µHz so that a time axis rebuilt as ``t0 + i/fs`` and read back gives the
    same ``fs`` (export → import reproduces the record exactly).
    """
    span = float(time_s[-1] - time_s[0])
    return float(np.round((time_s.shape[0] - 1) / span, 6))


def check_recording(
    time_s: np.ndarray,
    distance_m: np.ndarray,
    channels: Mapping[str, np.ndarray],
    known_channels: Iterable[str],
) -> float:
    """Check one (section, source) table and return its sampling rate ``fs`` in Hz.

    Rules: every array 1-D, numeric and of the same length ≥ 2; no NaN/inf; ``time_s``
    strictly increasing and equally spaced within :data:`TIME_JITTER_FRACTION` of a period;
    ``distance_m`` strictly increasing; channel names among ``known_channels``; at least
    one channel.
    """
    known = set(known_channels)
    if not channels:
        raise RecordingProblem("channels", "no channel column (need at least one of "
                               f"{sorted(known)[:6]}...)")
    unknown = sorted(set(channels) - known)
    if unknown:
        raise RecordingProblem(unknown[0], f"unknown channel column {unknown[0]!r}; the "
                               f"campaign declares {sorted(known)}")
    columns = {"time_s": time_s, "distance_m": distance_m, **channels}
    n = None
    for name, values in columns.items():
        a = np.asarray(values)
        if a.ndim != 1:
            raise RecordingProblem(name, f"column {name!r} has shape {a.shape}, expected 1-D")
        if a.dtype.kind == "b":
            raise RecordingProblem(name, f"column {name!r} holds booleans (true/false), "
                                   "expected numbers")
        if a.dtype.kind not in "fiu":
            raise RecordingProblem(name, f"column {name!r} has dtype {a.dtype}, expected numbers")
        if a.shape[0] == 0:
            raise RecordingProblem(name, f"column {name!r} is empty")
        if n is None:
            n = a.shape[0]
        elif a.shape[0] != n:
            raise RecordingProblem(name, f"column {name!r} has {a.shape[0]} samples, "
                                   f"time_s has {n}")
        if a.dtype.kind == "f":
            finite = np.isfinite(a)
            if not finite.all():
                i = int(np.flatnonzero(~finite)[0])
                raise RecordingProblem(name, f"column {name!r} holds {a[i]} at sample {i}; "
                                       "values must be finite")
    assert n is not None
    if n < 2:
        raise RecordingProblem("time_s", f"table has {n} sample, at least 2 are needed")
    t = np.asarray(time_s, dtype=np.float64)
    dt = np.diff(t)
    if not (dt > 0).all():
        i = int(np.flatnonzero(dt <= 0)[0])
        raise RecordingProblem("time_s", f"time_s is not strictly increasing at sample {i + 1} "
                               f"({t[i]} then {t[i + 1]})")
    d = np.asarray(distance_m, dtype=np.float64)
    dd = np.diff(d)
    if not (dd > 0).all():
        i = int(np.flatnonzero(dd <= 0)[0])
        raise RecordingProblem("distance_m", "distance_m is not strictly increasing at sample "
                               f"{i + 1} ({d[i]} then {d[i + 1]})")
    fs = estimate_fs(t)
    grid = t[0] + np.arange(n) / fs
    dev = np.abs(t - grid)
    worst = int(np.argmax(dev))
    if dev[worst] > TIME_JITTER_FRACTION / fs:
        raise RecordingProblem(
            "time_s",
            f"time_s is not equally spaced: sample {worst} is {dev[worst]:.3g} s off the "
            f"{fs:g} Hz grid (bound {TIME_JITTER_FRACTION / fs:.3g} s = "
            f"{TIME_JITTER_FRACTION:.0%} of a period)",
        )
    return fs


# -- plausibility of magnitudes (units) ----------------------------------------------------
#: largest magnitude any stored sample may have, in canonical units (kN, m/s²): beyond it
#: the EN 14363 filters overflow, and no wheel force or acceleration comes near it
MAX_ABS_VALUE = 1e9
#: the mean of every vertical wheel force channel Q must lie within this factor of the
#: vehicle's static wheel force Q0: each wheel carries Q0 plus the quasi-static load transfer
#: of cant deficiency or excess, a fraction of Q0 (EN 14363 limits the wheel unloading
#: ΔQ/Q0 to 0.6 even on twisted track); a factor 1000 off means N declared for kN data or
#: the reverse. The bound holds per channel, so one channel declared in the wrong unit
#: among correct ones is refused too (a mean over the channels would hide it).
Q_MEAN_FACTOR = 3.0
#: the 99th percentile of |Y| of every guiding-force channel declared in N must reach this
#: fraction of Q0: quasi-static curving forces, track irregularities and flange contact give
#: every running wheel lateral forces of a few kN (Y/Q of a few per cent on straight track,
#: 0.2–0.8 in curves; EN 14363 §7.6); kN data declared as N land 1000 times lower, far below
#: it (a simulation on ideal straight track with Y ≈ 0 is the honest exception: set
#: "check_unit": false on its channels)
Y_P99_MIN_FRACTION = 0.005
#: the 99th percentile of |Y| of every guiding-force channel must stay below this multiple of
#: Q0: the flange-climbing limit of EN 14363 is (Y/Q)lim = 0.8 (1.2 in the tightest curves)
#: and Q stays below Q_MEAN_FACTOR·Q0, so |Y| beyond 3·Q0 is no wheel force in kN — N data
#: declared as kN land 1000 times higher
Y_P99_MAX_FACTOR = 3.0
#: 99th percentile of |a| in m/s² above which an acceleration is implausible, per kind:
#: car body accelerations stay well below 0.5 g in service, bogie frames below 5 g
#: (EN 14363 limits the bogie frame to about 8 m/s² and the car body to about 2.5 m/s²;
#: data in m/s² declared as g are 9.81 times too large and land above these bounds)
ACC_P99_BOUND = {"ay_cb": 0.5 * 9.80665, "az_cb": 0.5 * 9.80665,
                 "ay_bg": 5 * 9.80665, "az_bg": 5 * 9.80665}


def check_magnitudes(channels: Mapping[str, np.ndarray], units: Mapping[str, str]) -> None:
    """Every sample within ±:data:`MAX_ABS_VALUE` (after any unit conversion); ``units``
    names the unit each channel was declared in (for the message)."""
    for name, values in channels.items():
        a = np.asarray(values, dtype=np.float64)
        bad = ~(np.abs(a) <= MAX_ABS_VALUE)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise RecordingProblem(
                name, f"column {name!r} holds {a[i]:g} at sample {i} after conversion from "
                f"{units.get(name, '?')}; samples must lie within ±{MAX_ABS_VALUE:g} "
                "(MAX_ABS_VALUE)")


_FIX = "fix the unit, or set \"check_unit\": false on the channel if the values are right"


def _unit_hint(ratio: float) -> str:
    """A hint when ``ratio`` (expected / found magnitude) is about 1000 or 1/1000."""
    if 300 < abs(ratio) < 3000:
        return " — the data look like kN declared as N"
    if 1 / 3000 < abs(ratio) < 1 / 300:
        return " — the data look like N declared as kN"
    return ""


def _check_wheel_load(name: str, values: np.ndarray, unit: str, q0_kn: float) -> None:
    """The magnitude of the mean of the vertical wheel force channel ``name`` (kN) within
    :data:`Q_MEAN_FACTOR` of Q0. The sign is not checked here: a transducer wired with
    reversed polarity reads −Q, a measurement fault that the diagnosis names (its ``sign``
    candidate, docs/diagnosis.md), not a unit error."""
    mean = float(np.mean(np.asarray(values, dtype=np.float64)))
    if not (q0_kn / Q_MEAN_FACTOR <= abs(mean) <= q0_kn * Q_MEAN_FACTOR):
        hint = _unit_hint(q0_kn / mean if mean else float("inf"))
        raise RecordingProblem(
            name, f"mean vertical wheel force Q of channel {name!r} is {mean:.4g} kN (unit "
            f"declared {unit}) but the vehicle's Q0 is {q0_kn:g} kN (plausible: "
            f"{q0_kn / Q_MEAN_FACTOR:.4g}–{q0_kn * Q_MEAN_FACTOR:.4g} kN){hint}; {_FIX}")


def _check_guiding_force(name: str, values: np.ndarray, unit: str, q0_kn: float) -> None:
    """The 99th percentile of |Y| of channel ``name`` (kN) below :data:`Y_P99_MAX_FACTOR` · Q0
    and, when declared in N, at least :data:`Y_P99_MIN_FRACTION` · Q0."""
    p99 = float(np.percentile(np.abs(np.asarray(values, dtype=np.float64)), 99))
    ceiling = Y_P99_MAX_FACTOR * q0_kn
    if p99 > ceiling:
        hint = " — the data look like N declared as kN" if p99 / 1000 <= ceiling else ""
        raise RecordingProblem(
            name, f"99 % of |Y| of channel {name!r} reach {p99:.4g} kN (unit declared {unit}), "
            f"more than any wheel carries: at most {ceiling:.4g} kN ({Y_P99_MAX_FACTOR:g}·Q0) "
            f"expected{hint}; {_FIX}")
    floor = Y_P99_MIN_FRACTION * q0_kn
    if unit == "N" and p99 < floor:
        hint = (" — the data look like kN declared as N"
                if floor <= p99 * 1000 <= ceiling else "")
        raise RecordingProblem(
            name, f"99 % of |Y| of channel {name!r} stay below {p99:.4g} kN (unit declared N), "
            f"too small for a running wheelset: at least {floor:.4g} kN "
            f"({Y_P99_MIN_FRACTION:g}·Q0) expected{hint}; {_FIX}")


def check_units_plausible(channels: Mapping[str, np.ndarray], declared: Mapping[str, str],
                          q0_kn: float, skip: Iterable[str] = ()) -> None:
    """Magnitudes consistent with the declared units (values already in canonical units),
    checked channel by channel so that one channel in the wrong unit is found among good ones:

    * every Q channel: its mean lies within a factor :data:`Q_MEAN_FACTOR` of Q0;
    * every Y channel: the 99th percentile of |Y| stays below :data:`Y_P99_MAX_FACTOR` · Q0,
      and, when declared in N (values that may have shrunk 1000 times), reaches
      :data:`Y_P99_MIN_FRACTION` · Q0;
    * accelerations: the 99th percentile of |a| stays below :data:`ACC_P99_BOUND`.

    ``skip``: channel names whose check the manifest switched off (``check_unit: false``).
    Raises :class:`RecordingProblem` naming the channel, its declared unit and the bound.
    """
    skip = set(skip)
    if q0_kn > 0:
        for name, values in channels.items():
            if name in skip:
                continue
            if name.startswith("Q_"):
                _check_wheel_load(name, values, declared.get(name, "?"), q0_kn)
            elif name.startswith("Y_"):
                _check_guiding_force(name, values, declared.get(name, "?"), q0_kn)
    for name, values in channels.items():
        kind = name.rpartition("_")[0]
        bound = ACC_P99_BOUND.get(kind)
        if bound is None or name in skip:
            continue
        p99 = float(np.percentile(np.abs(np.asarray(values, dtype=np.float64)), 99))
        if p99 > bound:
            hint = (" — the data look like m/s² declared as g"
                    if declared.get(name) == "g" and p99 / 9.80665 < bound else "")
            raise RecordingProblem(
                name, f"99 % of |{name}| reach {p99:.4g} m/s² (unit declared "
                f"{declared.get(name, '?')}), above the plausible {bound:.4g} m/s² for "
                f"{kind}{hint}; fix the unit, or set \"check_unit\": false on the channel if "
                "the values are right")
