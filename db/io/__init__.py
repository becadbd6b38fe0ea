"""Readers and writers of data tables (one table per section and source).

``read_table(path) -> dict[str, np.ndarray]`` and ``write_table(path, columns)`` choose the
format from the file extension:

=================  ==========  ====================================================
extension          library     layout
=================  ==========  ====================================================
``.csv``           pandas      header row; floats written with ``%.17g`` (exact round trip)
``.parquet``       pyarrow     one column each
``.h5 .hdf5``      h5py        one 1-D dataset per column at the file root
``.mat``           scipy.io    one variable per column (MATLAB v5)
``.mf4 .mdf``      asammdf     ``time_s`` = master channel, the others channels by name
``.tdms``          npTDMS      one group ``data``, one channel per column
=================  ==========  ====================================================

Columns are ``time_s``, ``distance_m`` and channel names (``docs/campaign-format.md``).
A file that cannot be read raises :class:`railval.core.errors.CampaignFormatError` naming it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from railval.core.errors import CampaignFormatError
from railval.db.io import formats

READERS = {
    ".csv": formats.read_csv,
    ".parquet": formats.read_parquet,
    ".h5": formats.read_h5,
    ".hdf5": formats.read_h5,
    ".mat": formats.read_mat,
    ".mf4": formats.read_mdf,
    ".mdf": formats.read_mdf,
    ".tdms": formats.read_tdms,
}
WRITERS = {
    ".csv": formats.write_csv,
    ".parquet": formats.write_parquet,
    ".h5": formats.write_h5,
    ".hdf5": formats.write_h5,
    ".mat": formats.write_mat,
    ".mf4": formats.write_mdf,
    ".mdf": formats.write_mdf,
    ".tdms": formats.write_tdms,
}
#: export format name → file extension
FORMAT_EXTENSIONS = {"csv": ".csv", "parquet": ".parquet", "h5": ".h5", "hdf5": ".h5",
                     "mat": ".mat", "mf4": ".mf4", "mdf": ".mf4", "tdms": ".tdms"}


def _suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in READERS:
        raise CampaignFormatError(
            f"unsupported data file extension {suffix or '(none)'!r}; supported: "
            f"{', '.join(sorted(READERS))}", file=str(path))
    return suffix


def read_table(path: str | Path) -> dict[str, np.ndarray]:
    """Read one table; column name → 1-D array (floats as float64)."""
    path = Path(path)
    suffix = _suffix(path)
    if not path.is_file():
        raise CampaignFormatError("data file does not exist", file=str(path))
    try:
        columns = READERS[suffix](path)
    except CampaignFormatError:
        raise
    except Exception as exc:  # noqa: BLE001 - every library has its own error types
        raise CampaignFormatError(
            f"cannot read {suffix} file ({type(exc).__name__}: {exc})", file=str(path)
        ) from None
    out: dict[str, np.ndarray] = {}
    for name, values in columns.items():
        a = np.asarray(values)
        if a.ndim != 1:
            a = a.reshape(-1) if a.size == max(a.shape, default=0) else a
        if a.dtype.kind in "fiu":  # booleans stay booleans and are refused by the checks
            a = a.astype(np.float64, copy=False)
        out[str(name)] = a
    return out


def write_table(path: str | Path, columns: dict[str, np.ndarray]) -> None:
    """Write one table (format by extension), creating the parent folder."""
    path = Path(path)
    suffix = _suffix(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    WRITERS[suffix](path, {k: np.ascontiguousarray(v, dtype=np.float64) for k, v in columns.items()})
