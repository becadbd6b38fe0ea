"""One reader and one writer per file format (see :mod:`railval.db.io`). Floats stay float64."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from railval.core.errors import CampaignFormatError

#: largest number of samples a column may declare; checked against the file's own metadata
#: (HDF5 dataset shape, Parquet row count, MDF cycle count, TDMS channel length, MAT
#: header) before any sample is read, so a small file declaring a huge array is refused at
#: once. 20 million samples are 28 h at 200 Hz, 160 MB per float64 column.
MAX_SAMPLES = 20_000_000
#: largest number of columns (datasets, channels, variables) a data file may hold
MAX_COLUMNS = 512


def _check_declared(path: Path, name: str, n: int) -> None:
    if n > MAX_SAMPLES:
        raise CampaignFormatError(
            f"column {name!r} declares {n} samples, more than the limit MAX_SAMPLES = "
            f"{MAX_SAMPLES}", file=str(path), field=str(name))


def _check_columns(path: Path, names: list[str]) -> None:
    if len(names) > MAX_COLUMNS:
        raise CampaignFormatError(f"file holds {len(names)} columns, more than the limit "
                                  f"MAX_COLUMNS = {MAX_COLUMNS}", file=str(path))
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise CampaignFormatError(f"column {name!r} appears twice", file=str(path),
                                      field=str(name))
        seen.add(name)


# -- CSV ---------------------------------------------------------------------------------
def read_csv(path: Path) -> dict[str, np.ndarray]:
    import pyarrow as pa
    import pyarrow.csv as pacsv

    _check_csv_dialect(path)
    # pyarrow parses decimal floats exactly (the shortest repr written below reads back
    # bit-identical) and is several times faster than a Python-level parser
    try:
        table = pacsv.read_csv(path)
    except pa.ArrowInvalid as exc:
        raise CampaignFormatError(f"cannot read .csv file ({exc})", file=str(path)) from None
    if table.num_columns == 0:
        raise CampaignFormatError("CSV file has no columns", file=str(path))
    _check_columns(path, table.column_names)
    if table.num_rows == 0:
        raise CampaignFormatError("CSV file holds a header but no samples", file=str(path),
                                  field=table.column_names[0])
    out = {}
    for name in table.column_names:
        col = table.column(name)
        if not (pa_is_numeric(col.type)):
            what = ("boolean (true/false)" if str(col.type) == "bool"
                    else f"not numeric (type {col.type})")
            raise CampaignFormatError(f"column {name!r} is {what}; expected numbers",
                                      file=str(path), field=str(name))
        out[name] = col.to_numpy()
    return out


def _check_csv_dialect(path: Path) -> None:
    """Name the two usual spreadsheet dialects instead of a column-count error: ``;`` as the
    separator, and decimal commas (``0,5``), which split every number into two columns."""
    with path.open("rb") as fh:
        head = fh.read(64 * 1024).decode("utf-8", errors="replace").splitlines()
    lines = [ln for ln in head[:-1] or head if ln.strip()][:6]
    if not lines:
        return
    header, rows = lines[0], lines[1:]
    if ";" in header and header.count(";") >= header.count(","):
        raise CampaignFormatError(
            f"the header separates columns with ';' ({header.count(';') + 1} fields); railval "
            "reads CSV with ',' as the separator and '.' as the decimal mark — export the "
            "file with commas", file=str(path), field=header.split(";")[0].strip().strip('"') or None)
    if rows:
        n_head = header.count(",") + 1
        n_row = rows[0].count(",") + 1
        import re

        if n_row > n_head and re.search(r"(^|[,;])-?\d+,\d", rows[0]):
            raise CampaignFormatError(
                f"line 2 has {n_row} comma-separated fields but the header has {n_head}: "
                "the numbers use a decimal comma (e.g. '0,5'); write them with a decimal "
                "point ('0.5')", file=str(path))


def pa_is_numeric(dtype) -> bool:
    import pyarrow.types as pat

    return pat.is_floating(dtype) or pat.is_integer(dtype)


def write_csv(path: Path, columns: dict[str, np.ndarray]) -> None:
    """Header row plus one row per sample; floats in their shortest exact decimal form.

    Only numbers are written below the header (:func:`railval.db.io.write_table` makes every
    column float64; a negative number is a number to a spreadsheet, not a formula); a column
    name a spreadsheet would read as a formula (:func:`spreadsheet_safe`) is refused, since
    escaping it would change what a re-import reads.
    """
    import pyarrow as pa
    import pyarrow.csv as pacsv

    table = pa.table({k: pa.array(v) for k, v in columns.items()})
    for name in table.column_names:
        if spreadsheet_safe(name) != name:
            raise CampaignFormatError(f"column name {name!r} begins like a spreadsheet "
                                      "formula; it is not written to CSV", file=str(path),
                                      field=name)
    pacsv.write_csv(table, path)


#: first characters that make a spreadsheet (Excel, LibreOffice Calc, Google Sheets) read a
#: CSV cell as a formula: ``=``, ``+``, ``-``, ``@``, tab (0x09) and carriage return (0x0D)
#: — OWASP, "CSV Injection", https://owasp.org/www-community/attacks/CSV_Injection
FORMULA_LEADS = ("=", "+", "-", "@", "\t", "\r")


def spreadsheet_safe(value: object) -> object:
    """A CSV cell that no spreadsheet evaluates: text beginning with one of
    :data:`FORMULA_LEADS` gets a leading single quote, as OWASP's CSV-injection guidance
    prescribes; numbers (negative ones included) and every other value stay as they are.

    Text that already begins with single quotes followed by a formula lead gets one more
    quote, so that :func:`spreadsheet_text` undoes the escape exactly.

    Examples
    --------
    >>> spreadsheet_safe("@SUM(A1)")
    "'@SUM(A1)"
    >>> spreadsheet_safe(-1.5), spreadsheet_safe("a - b")
    (-1.5, 'a - b')
    """
    if isinstance(value, str) and value.lstrip("'").startswith(FORMULA_LEADS):
        return "'" + value
    return value


def spreadsheet_text(cell: str) -> str:
    """The text :func:`spreadsheet_safe` escaped, read back from a CSV cell (the one leading
    quote it added removed; any other text unchanged).

    Examples
    --------
    >>> spreadsheet_text("'=1+1"), spreadsheet_text("''=1+1"), spreadsheet_text("'quoted")
    ('=1+1', "'=1+1", "'quoted")
    """
    if cell.startswith("'") and cell.lstrip("'").startswith(FORMULA_LEADS):
        return cell[1:]
    return cell


# -- Parquet -----------------------------------------------------------------------------
def read_parquet(path: Path) -> dict[str, np.ndarray]:
    import pyarrow.parquet as pq

    meta = pq.ParquetFile(path).metadata
    names = [meta.schema.column(i).name for i in range(meta.num_columns)]
    _check_columns(path, names)
    for name in names:
        _check_declared(path, name, meta.num_rows)
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
        datasets = [(name, item) for name, item in fh.items() if isinstance(item, h5py.Dataset)]
        _check_columns(path, [name for name, _ in datasets])
        for name, item in datasets:
            _check_declared(path, name, int(np.prod(item.shape, dtype=np.int64)))
        for name, item in datasets:
            out[name] = item[()]
    return out


def write_h5(path: Path, columns: dict[str, np.ndarray]) -> None:
    import h5py

    with h5py.File(path, "w", track_order=True) as fh:
        for name, values in columns.items():
            fh.create_dataset(name, data=values)


# -- MATLAB ------------------------------------------------------------------------------
def read_mat(path: Path) -> dict[str, np.ndarray]:
    from scipy.io import loadmat, whosmat

    declared = whosmat(path)
    _check_columns(path, [name for name, _shape, _cls in declared])
    for name, shape, _cls in declared:
        _check_declared(path, name, int(np.prod(shape, dtype=np.int64)))
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
        names = [ch.name for g, grp in enumerate(mdf.groups) for c, ch in enumerate(grp.channels)
                 if mdf.masters_db.get(g) != c]
        _check_columns(path, names)
        for g, grp in enumerate(mdf.groups):
            for c, ch in enumerate(grp.channels):
                name = "time_s" if mdf.masters_db.get(g) == c else ch.name
                _check_declared(path, name, int(grp.channel_group.cycles_nr))
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

    meta = TdmsFile.read_metadata(path)
    if len(meta.groups()) == 1:
        chans = meta.groups()[0].channels()
        _check_columns(path, [ch.name for ch in chans])
        for ch in chans:
            _check_declared(path, ch.name, len(ch))
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
