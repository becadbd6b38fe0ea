"""Import through the browser (the Import page; docs/app.md, "Import page").

An engineer uploads a zip file: a campaign folder (``campaign.json`` at the top of the zip,
or in its single top-level folder), or a configuration's simulated files for a stored
campaign (``configuration.json`` — one entry of campaign.json's ``configurations``, its
``parent`` naming a stored configuration — and the data files it lists). The zip is unpacked into a private temporary folder with
every entry checked (no absolute paths, no ``..``, no links, at most :data:`MAX_ENTRIES`
entries and :data:`MAX_UNPACKED_MB` unpacked) and then imported by exactly the code of
``railval import`` (:func:`railval.db.importer.import_campaign`): the same checks before
anything is written, one transaction, the same content hashes and seals, the same
``campaign.import`` audit row naming the signed-in user. On any error nothing is stored and
the message names the zip entry or the file, field and line of the campaign folder.
"""

from __future__ import annotations

import stat
import tempfile
import zipfile
from collections.abc import Callable
from io import BytesIO
from pathlib import Path, PurePosixPath
from typing import Any

from railval.core import lazy
from railval.core.errors import CampaignFormatError
from railval.core.roles import Principal, require

#: deferred (railval.core.lazy): the importer (readers, pandas) only when a zip is imported
acting_as = lazy.function("railval.db.engine", "acting_as")
importer = lazy.module("railval.db.importer")

#: largest zip accepted, in MB (stated on the page; the websocket message cap of ``railval
#: serve`` is set from it)
MAX_UPLOAD_MB = 100
#: largest total size of the unpacked files, in MB (zip bombs stop here)
MAX_UNPACKED_MB = 1000
#: most entries a zip may hold
MAX_ENTRIES = 5000


def _bad(entry: str, why: str) -> CampaignFormatError:
    return CampaignFormatError(why, file=entry)


def unpack(data: bytes, dest: Path, name: str = "upload.zip", manifest: str = "campaign.json") -> Path:
    """Unpack the zip ``data`` into ``dest``; return the folder holding ``manifest``
    (``campaign.json``, or ``configuration.json`` for a configuration upload). Raises
    :class:`CampaignFormatError` naming the zip or the entry."""
    if len(data) > MAX_UPLOAD_MB * 1024 * 1024:
        raise _bad(name, f"{len(data) / 1048576:.1f} MB is larger than the upload limit "
                         f"{MAX_UPLOAD_MB} MB; import larger campaigns with `railval import`")
    try:
        zf = zipfile.ZipFile(BytesIO(data))
    except zipfile.BadZipFile as exc:
        raise _bad(name, f"not a zip file ({exc})") from None
    with zf:
        infos = zf.infolist()
        if len(infos) > MAX_ENTRIES:
            raise _bad(name, f"{len(infos)} entries, more than the limit {MAX_ENTRIES}")
        total = 0
        for info in infos:
            path = PurePosixPath(info.filename)
            if path.is_absolute() or ".." in path.parts or "\\" in info.filename:
                raise _bad(info.filename, "entry path leaves the campaign folder (absolute, "
                                          "'..' or backslash)")
            if stat.S_ISLNK(info.external_attr >> 16):
                raise _bad(info.filename, "symbolic links are not accepted")
            total += info.file_size
            if total > MAX_UNPACKED_MB * 1024 * 1024:
                raise _bad(info.filename, f"unpacked size exceeds {MAX_UNPACKED_MB} MB")
        for info in infos:
            target = dest.joinpath(*PurePosixPath(info.filename).parts)
            if info.is_dir():
                target.mkdir(parents=True, exist_ok=True)
                continue
            target.parent.mkdir(parents=True, exist_ok=True)
            with zf.open(info) as src, target.open("wb") as out:
                written = 0
                while block := src.read(1 << 20):
                    written += len(block)
                    if written > info.file_size:  # a header that lies about the size
                        raise _bad(info.filename, "entry is larger than its zip header states")
                    out.write(block)
    if (dest / manifest).exists():
        return dest
    tops = [p for p in dest.iterdir() if not p.name.startswith(("__MACOSX", "."))]
    if len(tops) == 1 and (tops[0] / manifest).exists():
        return tops[0]
    raise _bad(name, f"no {manifest} at the top of the zip or in its single top-level folder")


def import_zip(database: Any, principal: Principal, data: bytes, name: str = "upload.zip",
               progress: Callable[[int, int, str], None] | None = None) -> str:
    """Unpack and import the campaign zip ``data`` as ``principal`` (needs ``data.import``);
    returns the campaign name."""

    require(principal, "data.import")
    with tempfile.TemporaryDirectory(prefix="railval-upload-") as tmp:
        folder = unpack(data, Path(tmp), name)
        with acting_as(principal.username):
            return importer.import_campaign(database, folder, progress=progress)


def import_configuration_zip(database: Any, principal: Principal, campaign: str, data: bytes,
                             name: str = "upload.zip",
                             progress: Callable[[int, int, str], None] | None = None) -> str:
    """Unpack a configuration's files (``configuration.json`` + data files) and import them
    into the stored ``campaign`` as ``principal`` (``railval import DIR --into CAMPAIGN``);
    returns the configuration name."""
    require(principal, "data.import")
    with tempfile.TemporaryDirectory(prefix="railval-upload-") as tmp:
        folder = unpack(data, Path(tmp), name, importer.CONFIGURATION_MANIFEST)
        with acting_as(principal.username):
            return importer.import_configuration(database, campaign, folder, progress=progress)
