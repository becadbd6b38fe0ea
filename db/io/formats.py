"""One reader and one writer per file format (see :mod:`railval.db.io`). Floats stay float64."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from railval.core.errors import CampaignFormatError


# -- CSV ---------------------------------------------------------------------------------
def read_csv(path: Path) -> dict[str, np.ndarray]:
    import pyarrow.csv as pacsv

    # pyarrow parses decimal floats exactly (the shortest repr written below reads back
    # bit-identical) and is several times faster than a Python-level parser
    table = pacsv.read_csv(path)
    if table.num_columns == 0:
        raise CampaignFormatError("CSV file has no columns", file=str(path))
    if table.num_rows == 0:
        raise CampaignFormatError("CSV file holds a header but no samples", file=str(path),
                                  field=table.column_names[0])
    out = {}
    for name in table.column_names:
        col = table.column(name)
        if not (pa_is_numeric(col.type)):
            raise CampaignFormatError(f"column {name!r} is not numeric (type {col.type})",
                                      file=str(path), field=str(name))
        out[name] = col.to_numpy()
    return out


def pa_is_numeric(dtype) -> bool:
    import pyarrow.types as pat

    return pat.is_floating(dtype) or pat.is_integer(dtype) or pat.is_boolean(dtype)


def write_csv(path: Path, columns: dict[str, np.ndarray]) -> None:
    """Header row plus one row per sample; floats in their shortest exact decimal form."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    pacsv.write_csv(pa.table({k: pa.array(v) for k, v in columns.items()}), path)


# -- Parquet -----------------------------------------------------------------------------
def read_parquet(path: Path) -> dict[str, np.ndarray]:
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    return {name: table.column(name).to_numpy() for name in table.column_names}


def write_parquet(path: Path, columns: dict[str, np.ndarray]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    pq.write_table(pa.table({k: pa.array(v) for k, v in columns.items()}), path)


# -- HDF5 --------------------------------------------------------------------------------
def read_h5(path: Path) -> dict[str, np.ndarray]:
    import h5py

    out = {}
    with h5py.File(path, "r") as fh:
        for name, item in fh.items():
            if isinstance(item, h5py.Dataset):
                out[name] = item[()]
    return out


def write_h5(path: Path, columns: dict[str, np.ndarray]) -> None:
    import h5py

    with h5py.File(path, "w", track_order=True) as fh:
        for name, values in columns.items():
            fh.create_dataset(name, data=values)


# -- MATLAB ------------------------------------------------------------------------------
def read_mat(path: Path) -> dict[str, np.ndarray]:
    from scipy.io import loadmat

    raw = loadmat(path, squeeze_me=False)
    return {k: np.asarray(v).reshape(-1) for k, v in raw.items() if not k.startswith("__")}


def write_mat(path: Path, columns: dict[str, np.ndarray]) -> None:
    from scipy.io import savemat

    savemat(path, {k: v.reshape(-1, 1) for k, v in columns.items()}, oned_as="column")


# -- MDF4 (asammdf) ----------------------------------------------------------------------
def read_mdf(path: Path) -> dict[str, np.ndarray]:
    from asammdf import MDF

    out: dict[str, np.ndarray] = {}
    time = None
    with MDF(path) as mdf:
        for sig in mdf.iter_channels(skip_master=True):
            out[sig.name] = np.asarray(sig.samples)
            if time is None:
                time = np.asarray(sig.timestamps, dtype=np.float64)
    if time is None:
        raise CampaignFormatError("MDF file holds no channel", file=str(path))
    return {"time_s": time, **out}


def write_mdf(path: Path, columns: dict[str, np.ndarray]) -> None:
    from asammdf import MDF, Signal

    if "time_s" not in columns:
        raise CampaignFormatError("an MDF file needs a time_s column for its master channel",
                                  file=str(path), field="time_s")
    t = columns["time_s"]
    mdf = MDF(version="4.10")
    mdf.append([Signal(samples=v, timestamps=t, name=k) for k, v in columns.items()
                if k != "time_s"], common_timebase=True)
    mdf.save(path, overwrite=True)
    mdf.close()


# -- TDMS (npTDMS) -----------------------------------------------------------------------
def read_tdms(path: Path) -> dict[str, np.ndarray]:
    from nptdms import TdmsFile

    tdms = TdmsFile.read(path)
    groups = tdms.groups()
    if len(groups) != 1:
        raise CampaignFormatError(f"TDMS file has {len(groups)} groups, expected exactly one",
                                  file=str(path))
    return {ch.name: ch[:] for ch in groups[0].channels()}


def write_tdms(path: Path, columns: dict[str, np.ndarray]) -> None:
    from nptdms import ChannelObject, GroupObject, TdmsWriter

    with TdmsWriter(path) as writer:
        writer.write_segment([GroupObject("data")]
                             + [ChannelObject("data", k, v) for k, v in columns.items()])
