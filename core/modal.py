"""Operational modal analysis: covariance-driven stochastic subspace identification (SSI-COV),
stabilisation diagram, Modal Assurance Criterion (MAC) and MAC-based mode pairing.

Seed 002 (§3–4) identifies the rigid-body car body modes of a freight wagon from accelerations
recorded in service with SSI and pairs numerical with experimental modes "based on the highest
MAC value"; this module implements those steps from the published algorithms.

Units: accelerations in any consistent unit (m/s² in railval), ``fs`` in Hz, frequencies in
Hz, damping ratios dimensionless (fraction of critical), mode shapes dimensionless (normalised
to unit largest component).

References
----------
.. [PdR99] B. Peeters, G. De Roeck, "Reference-based stochastic subspace identification for
   output-only modal analysis", Mech. Syst. Signal Process. 13(6), 855–878, 1999 (eqs. 8–16:
   output covariances, block Toeplitz matrix, factorisation into observability × reversed
   controllability, shift structure).
.. [AB82] R. J. Allemang, D. L. Brown, "A correlation coefficient for modal vector analysis",
   Proc. 1st IMAC, 110–116, 1982 (the MAC).
.. [RPDR12] E. Reynders, J. Houbrechts, G. De Roeck, "Fully automated (operational) modal
   analysis", Mech. Syst. Signal Process. 29, 228–250, 2012 (stabilisation criteria
   1 % frequency, 5 % damping, MAC ≥ 0.98 between consecutive orders).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.signal import resample_poly

from railval.core.errors import InvalidParameter, InvalidSignal
from railval.core.types import SignalSet

__all__ = [
    "ModalResult",
    "Mode",
    "Pole",
    "StabilisationCriteria",
    "decimated_records",
    "mac",
    "mac_matrix",
    "modes_from_matrices",
    "output_covariances",
    "pair_modes",
    "ssi_cov",
    "ssi_cov_poles",
]


# --------------------------------------------------------------------------- MAC and pairing
def mac(phi_a: np.ndarray, phi_b: np.ndarray) -> float:
    """Modal Assurance Criterion of two mode shapes ([AB82]).

    MAC(a, b) = |a^H b|² / ((a^H a)(b^H b)), in [0, 1]: 1 for shapes that differ only by a
    (complex) scale factor, 0 for orthogonal shapes. Dimensionless.

    Parameters
    ----------
    phi_a, phi_b : numpy.ndarray
        Mode shapes, shape (n_sensors,), real or complex.

    Returns
    -------
    float

    Raises
    ------
    InvalidSignal
        Shapes of unequal length or a zero shape.

    Examples
    --------
    >>> mac(np.array([1.0, 0.0]), np.array([2.0, 0.0]))
    1.0
    """
    a = np.asarray(phi_a).ravel()
    b = np.asarray(phi_b).ravel()
    if a.shape != b.shape:
        raise InvalidSignal(f"mode shapes must have equal length, got {a.size} and {b.size}")
    den = float(np.real(np.vdot(a, a)) * np.real(np.vdot(b, b)))
    if den <= 0.0:
        raise InvalidSignal("MAC of a zero mode shape is undefined")
    return float(abs(np.vdot(a, b)) ** 2 / den)


def mac_matrix(shapes_a: np.ndarray, shapes_b: np.ndarray) -> np.ndarray:
    """MAC of every pair of columns: ``out[i, j] = MAC(shapes_a[:, i], shapes_b[:, j])``.

    Parameters
    ----------
    shapes_a, shapes_b : numpy.ndarray
        Mode shapes as columns, shapes (n_sensors, m_a) and (n_sensors, m_b).

    Returns
    -------
    numpy.ndarray
        Shape (m_a, m_b), in [0, 1].
    """
    A = np.atleast_2d(np.asarray(shapes_a))
    B = np.atleast_2d(np.asarray(shapes_b))
    if A.shape[0] != B.shape[0]:
        raise InvalidSignal(f"mode shapes must have equal length, got {A.shape[0]} and {B.shape[0]}")
    num = np.abs(A.conj().T @ B) ** 2
    na = np.real(np.sum(A.conj() * A, axis=0))
    nb = np.real(np.sum(B.conj() * B, axis=0))
    return num / np.outer(na, nb)


def pair_modes(freq_ref: np.ndarray, shapes_ref: np.ndarray, freq_other: np.ndarray,
               shapes_other: np.ndarray, *, freq_weight: float = 0.0) -> list[tuple[int, int, float]]:
    """Pair reference modes with other modes by highest MAC ([ref 3] §4).

    One-to-one assignment maximising the summed score MAC − ``freq_weight``·|Δf|/f_ref
    (Hungarian algorithm, ``scipy.optimize.linear_sum_assignment``); with ``freq_weight`` 0 it
    is the pure highest-MAC pairing of the seed, the weight breaks ties between modes whose
    shapes look alike on few sensors. Returns ``(i_ref, j_other, mac)`` sorted by ``i_ref``.

    Parameters
    ----------
    freq_ref, freq_other : numpy.ndarray
        Natural frequencies in Hz, shapes (m_ref,) and (m_other,).
    shapes_ref, shapes_other : numpy.ndarray
        Mode shapes as columns, shapes (n_sensors, m_ref) and (n_sensors, m_other).
    freq_weight : float
        Weight of the relative frequency difference (dimensionless).

    Returns
    -------
    list of tuple of (int, int, float)
    """
    fr = np.asarray(freq_ref, dtype=float)
    fo = np.asarray(freq_other, dtype=float)
    M = mac_matrix(shapes_ref, shapes_other)
    score = M - freq_weight * np.abs(fo[None, :] - fr[:, None]) / fr[:, None]
    rows, cols = linear_sum_assignment(-score)
    return sorted((int(r), int(c), float(M[r, c])) for r, c in zip(rows, cols, strict=True))


# --------------------------------------------------------------------------- SSI-COV
def _check_data(y: np.ndarray, fs: float) -> np.ndarray:
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    if y.ndim != 2:
        raise InvalidSignal(f"accelerations must be (n_samples, n_channels), got shape {y.shape}")
    if not np.all(np.isfinite(y)):
        raise InvalidSignal("accelerations contain NaN or inf")
    if not (fs > 0):
        raise InvalidParameter(f"fs must be > 0 Hz, got {fs}")
    return y - y.mean(axis=0)


def _records(y, fs: float) -> list[np.ndarray]:
    """One (n, l) array or a list of them (records of equal channel count)."""
    recs = [_check_data(r, fs) for r in y] if isinstance(y, (list, tuple)) else [_check_data(y, fs)]
    if not recs or len({r.shape[1] for r in recs}) != 1:
        raise InvalidSignal(f"records must share their channel count, got {[r.shape[1] for r in recs]}")
    return recs


def output_covariances(y: np.ndarray, max_lag: int) -> np.ndarray:
    """Unbiased output covariance matrices R_k = 1/(N−k) Σ_t y_{t+k} y_tᵀ, k = 0 … max_lag
    ([PdR99] eq. 8). ``y`` is (N, l); returns (max_lag + 1, l, l). Computed by FFT.

    Parameters
    ----------
    y : numpy.ndarray
        Outputs, shape (N, l), e.g. accelerations in m/s².
    max_lag : int
        Largest lag k in samples (< N).

    Returns
    -------
    numpy.ndarray
        Shape (max_lag + 1, l, l), in the square of the unit of ``y``.
    """
    y = np.asarray(y, dtype=float)
    n, _l = y.shape
    if max_lag >= n:
        raise InvalidParameter(f"max_lag must be < number of samples {n}, got {max_lag}")
    nfft = 1 << int(np.ceil(np.log2(2 * n)))
    Y = np.fft.rfft(y, nfft, axis=0)
    # R[k, a, b] = sum_t y[t+k, a] y[t, b]
    cross = np.fft.irfft(Y[:, :, None] * np.conj(Y[:, None, :]), nfft, axis=0)[: max_lag + 1]
    return cross / (n - np.arange(max_lag + 1))[:, None, None]


@dataclass(frozen=True)
class Pole:
    """One physical pole of an identified model: frequency in Hz, damping ratio (fraction of
    critical), mode shape at the channels (complex, unit largest component), model order."""

    order: int
    freq_hz: float
    damping: float
    shape: np.ndarray
    stable: bool = False


def _shapes_normalised(phi: np.ndarray) -> np.ndarray:
    idx = np.argmax(np.abs(phi), axis=0)
    return phi / phi[idx, np.arange(phi.shape[1])]


def modes_from_matrices(A: np.ndarray, C: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Modal parameters of a discrete state-space model x_{k+1} = A x_k, y_k = C x_k.

    λ_i eigenvalues of A; continuous poles μ_i = ln(λ_i)·fs (1/s); f_i = |μ_i|/(2π) Hz;
    ζ_i = −Re μ_i / |μ_i|; shapes φ_i = C ψ_i ([PdR99] eq. 16). Keeps one of each complex-
    conjugate pair (Im μ > 0) and returns (freq_hz, damping, shapes[l, m]) sorted by frequency.

    Parameters
    ----------
    A : numpy.ndarray
        State matrix, shape (n, n).
    C : numpy.ndarray
        Output matrix, shape (l, n).
    fs : float
        Sampling rate in Hz.

    Returns
    -------
    tuple of numpy.ndarray
        Frequencies in Hz (m,), damping ratios (m,), shapes (l, m).
    """
    lam, psi = np.linalg.eig(A)
    keep = np.imag(lam) > 1e-12
    lam, psi = lam[keep], psi[:, keep]
    mu = np.log(lam) * fs
    freq = np.abs(mu) / (2.0 * np.pi)
    damp = -np.real(mu) / np.abs(mu)
    shapes = _shapes_normalised(C @ psi) if psi.size else np.zeros((C.shape[0], 0), complex)
    order = np.argsort(freq)
    return freq[order], damp[order], shapes[:, order]


def ssi_cov_poles(y: np.ndarray, fs: float, *, block_rows: int, orders: range | list[int],
                  f_min: float = 0.0, f_max: float | None = None) -> dict[int, list[Pole]]:
    """Poles of the SSI-COV models of every order in ``orders`` ([PdR99] §3).

    ``block_rows`` i: the block Toeplitz matrix T = [R_i … R_1; …; R_{2i−1} … R_i] (il × il)
    is built from the output covariances R_1 … R_{2i−1} and factorised by SVD,
    T = U S Vᵀ. For order n the observability matrix is O = U_n S_n^{1/2}, C its first
    block row and A = O_↑⁺ O_↓ from its shift structure (O_↑ without the last, O_↓ without
    the first block row). i·l must exceed the largest order. Poles outside
    [f_min, f_max] Hz (default f_max: 0.45·fs) and non-physical ones (ζ ≤ 0 or ζ ≥ 0.5) are
    dropped.
    """
    records = _records(y, fs)
    l = records[0].shape[1]
    orders = list(orders)
    if block_rows < 1 or max(orders) > block_rows * l:
        raise InvalidParameter(
            f"block_rows·channels = {block_rows * l} must be ≥ the largest model order {max(orders)}")
    # several records (e.g. one per test section): covariances averaged, weighted by length
    weights = np.array([r.shape[0] - np.arange(2 * block_rows + 1) for r in records], float)
    R = sum(w[:, None, None] * output_covariances(r, 2 * block_rows) for w, r in zip(weights, records, strict=True))
    R = R / weights.sum(axis=0)[:, None, None]
    i = block_rows
    T = np.empty((i * l, i * l))
    for r in range(i):
        for c in range(i):
            T[r * l:(r + 1) * l, c * l:(c + 1) * l] = R[i + r - c]
    U, s, _ = np.linalg.svd(T)
    f_max = 0.45 * fs if f_max is None else f_max
    out: dict[int, list[Pole]] = {}
    for n in orders:
        O = U[:, :n] * np.sqrt(s[:n])
        C = O[:l]
        A = np.linalg.pinv(O[:-l]) @ O[l:]
        freq, damp, shapes = modes_from_matrices(A, C, fs)
        out[n] = [Pole(n, float(f), float(z), shapes[:, k]) for k, (f, z) in enumerate(zip(freq, damp, strict=True))
                  if f_min <= f <= f_max and 0.0 < z < 0.5]
    return out


@dataclass(frozen=True)
class StabilisationCriteria:
    """Stability of a pole between consecutive model orders ([RPDR12] defaults): relative
    frequency change ≤ ``freq_tol`` (1 %), relative damping change ≤ ``damping_tol`` (5 %),
    MAC ≥ ``mac_min`` (0.98). A mode is accepted when at least ``min_stable`` stable poles
    (default 5) fall within ``cluster_tol`` (2 %) of each other's frequency."""

    freq_tol: float = 0.01
    damping_tol: float = 0.05
    mac_min: float = 0.98
    min_stable: int = 5
    cluster_tol: float = 0.02


@dataclass
class Mode:
    """One identified mode: median frequency (Hz) and damping over its stable poles, the shape
    of the stable pole nearest the median frequency (real part after rotation, unit maximum),
    and how many stable poles support it."""

    freq_hz: float
    damping: float
    shape: np.ndarray
    n_stable: int
    freq_std_hz: float = 0.0

    def to_dict(self) -> dict:
        return {"freq_hz": self.freq_hz, "damping": self.damping, "shape": np.real(self.shape).tolist(),
                "n_stable": self.n_stable, "freq_std_hz": self.freq_std_hz}


@dataclass
class ModalResult:
    """Identified modes plus the stabilisation diagram (every pole per order, flagged)."""

    fs: float
    channels: list[str]
    modes: list[Mode]
    poles: dict[int, list[Pole]] = field(repr=False)
    criteria: StabilisationCriteria = field(default_factory=StabilisationCriteria)
    block_rows: int = 0

    @property
    def frequencies(self) -> np.ndarray:
        return np.array([m.freq_hz for m in self.modes])

    @property
    def shapes(self) -> np.ndarray:
        if not self.modes:
            return np.zeros((len(self.channels), 0))
        return np.column_stack([m.shape for m in self.modes])

    def stabilisation_diagram(self) -> list[dict]:
        """Rows ``order, freq_hz, damping, stable`` (for plotting)."""
        return [{"order": n, "freq_hz": p.freq_hz, "damping": p.damping, "stable": p.stable}
                for n, ps in sorted(self.poles.items()) for p in ps]

    def to_dict(self) -> dict:
        return {"fs": self.fs, "channels": list(self.channels), "block_rows": self.block_rows,
                "criteria": asdict(self.criteria), "modes": [m.to_dict() for m in self.modes],
                "n_poles": sum(len(v) for v in self.poles.values())}

    def to_pandas(self):
        import pandas as pd

        return pd.DataFrame([{k: v for k, v in m.to_dict().items() if k != "shape"} for m in self.modes])


def _real_shape(phi: np.ndarray) -> np.ndarray:
    """Rotate a complex shape so that its largest component is real and positive, keep the
    real part and scale to unit largest magnitude (monophase approximation)."""
    k = int(np.argmax(np.abs(phi)))
    rot = phi * np.exp(-1j * np.angle(phi[k]))
    re = np.real(rot)
    return re / np.max(np.abs(re))


def ssi_cov(y: np.ndarray, fs: float, *, channels: list[str] | None = None, block_rows: int | None = None,
            max_order: int | None = None, f_min: float = 0.0, f_max: float | None = None,
            criteria: StabilisationCriteria | None = None) -> ModalResult:
    """Identify modes from multichannel output-only data by SSI-COV with a stabilisation
    diagram ([PdR99], criteria [RPDR12]).

    Parameters
    ----------
    y : numpy.ndarray or list of numpy.ndarray
        Accelerations (n_samples, n_channels) equally sampled at ``fs`` Hz, or a list of such
        records (e.g. one per test section; their covariances are averaged).
    fs : float
        Sampling rate in Hz.
    channels : list of str or None
        Channel names (default ``ch0``, ``ch1``, …).
    block_rows : int or None
        i of the Toeplitz matrix (default: enough lags to span two periods of ``f_min`` or
        2·max_order/l, whichever is larger, at most n/20).
    max_order : int or None
        Largest model order (even; default 2·⌊i·l/2⌋ capped at 40); orders 2, 4, …
    f_min, f_max : float
        Frequency range of interest in Hz.
    criteria : StabilisationCriteria or None

    Returns
    -------
    ModalResult
        A pole of order n is *stable* when a pole of order n−2 lies within the frequency,
        damping and MAC tolerances. Stable poles are clustered by frequency (``cluster_tol``);
        clusters with ≥ ``min_stable`` members are the modes, sorted by frequency.
    """
    records = _records(y, fs)
    l = records[0].shape[1]
    crit = criteria or StabilisationCriteria()
    if block_rows is None:
        lags_fmin = int(np.ceil(2.0 * fs / f_min)) if f_min > 0 else 0
        block_rows = max(lags_fmin, int(np.ceil(60 / l)), 10)
        block_rows = min(block_rows, max(min(r.shape[0] for r in records) // 20, 2))
    if max_order is None:
        max_order = min(2 * ((block_rows * l) // 2), 40)
    orders = list(range(2, max_order + 1, 2))
    poles = ssi_cov_poles(records, fs, block_rows=block_rows, orders=orders, f_min=f_min, f_max=f_max)
    flagged: dict[int, list[Pole]] = {}
    prev: list[Pole] = []
    for n in orders:
        cur = []
        for p in poles[n]:
            stable = any(abs(p.freq_hz - q.freq_hz) <= crit.freq_tol * q.freq_hz
                         and abs(p.damping - q.damping) <= crit.damping_tol * q.damping
                         and mac(p.shape, q.shape) >= crit.mac_min for q in prev)
            cur.append(Pole(p.order, p.freq_hz, p.damping, p.shape, stable))
        flagged[n] = cur
        prev = poles[n]
    stable = sorted((p for ps in flagged.values() for p in ps if p.stable), key=lambda p: p.freq_hz)
    modes: list[Mode] = []
    cluster: list[Pole] = []

    def close(cl: list[Pole]) -> None:
        if len(cl) >= crit.min_stable:
            f = np.array([p.freq_hz for p in cl])
            fmed = float(np.median(f))
            rep = cl[int(np.argmin(np.abs(f - fmed)))]
            modes.append(Mode(fmed, float(np.median([p.damping for p in cl])), _real_shape(rep.shape),
                              len(cl), float(np.std(f))))

    for p in stable:
        if cluster and p.freq_hz > cluster[0].freq_hz * (1.0 + crit.cluster_tol):
            close(cluster)
            cluster = []
        cluster.append(p)
    if cluster:
        close(cluster)
    return ModalResult(fs=fs, channels=list(channels) if channels else [f"ch{k}" for k in range(l)],
                       modes=modes, poles=flagged, criteria=crit, block_rows=block_rows)


def decimated_records(signalsets: Iterable[SignalSet], channels: Sequence[str],
                      fs_target: float = 20.0) -> tuple[list[np.ndarray], float | None]:
    """The records for :func:`ssi_cov`: each SignalSet's ``channels`` as columns, decimated by
    the integer factor nearest ``fs / fs_target`` with an anti-alias FIR
    (``scipy.signal.resample_poly``). Records whose decimated rate differs from the first
    one's are left out. Returns (records, decimated rate), ([], None) when nothing is given.

    Parameters
    ----------
    signalsets : iterable of SignalSet
    channels : sequence of str
        Acceleration channels (m/s²), one column each.
    fs_target : float
        Wanted rate in Hz.

    Returns
    -------
    tuple of (list of numpy.ndarray, float or None)
        Records of shape (n_samples, len(channels)) and their rate in Hz.
    """
    records, fs_used = [], None
    for ss in signalsets:
        q = max(round(ss.fs / fs_target), 1)
        fs_new = ss.fs / q
        if fs_used is not None and not math.isclose(fs_new, fs_used):
            continue
        fs_used = fs_new
        records.append(np.column_stack([resample_poly(ss.channels[c], 1, q) for c in channels]))
    return records, fs_used
