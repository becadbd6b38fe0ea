"""nginx answers Bokeh's and Panel's static files (docs/app.md, "Cheap sessions"; issue 41).

A new browser loads ≈ 20 static files (≈ 6 MB of Panel/Bokeh JavaScript and CSS) before its
Panel session starts; served by Tornado they cost the app process CPU that no other session can
use. ``deploy/nginx/railval.conf.template`` answers them from the installed packages' folders
instead, at the URLs the app serves them:

* ``/static/…`` except ``/static/extensions/…``: Bokeh's ``StaticHandler``
  (``bokeh.settings.bokehjs_path()``, the package's ``server/static`` folder; route
  ``/static/(?!extensions/)(.*)`` as Panel patches it in ``panel.io.server``);
* ``/static/extensions/panel/…``: Bokeh's ``MultiRootStaticHandler`` over the extension
  folders (``bokeh.embed.bundle.extension_dirs``; Panel's is ``panel.io.resources.DIST_DIR``,
  the only extension railval loads — :func:`extension_dirs` checks);
* any other ``/static/extensions/…`` is 404, as in the app.

The app's own ``/railval-static/`` route needs a sign-in (Panel's
``AuthenticatedStaticFileHandler``) and stays with the app.

:func:`snippet` renders what every static location includes (``${RAILVAL_STATIC_CONF}`` in the
template): the security headers from :data:`railval.app.security.HEADERS` — the one home of
their values, so nginx's static responses cannot drift from the app's — the MIME types the app
gives the same files (Python's :mod:`mimetypes`, as Tornado's ``StaticFileHandler``), the cache
lifetime (a year, immutable, when the URL carries ``?v=`` — Bokeh's content hash or Panel's
version — else revalidate) and gzip (``gzip_static`` when :func:`prepare` wrote ``.gz`` files
beside the originals, else nginx compresses every response). ``railval nginx-static DIR``
copies the folders with their ``.gz`` files, writes the snippet and prints the template's values
(:func:`prepare`). Measured (docs/app.md, "Cheap sessions"): the 24 static requests of a new
browser cost an app process 0.04 CPU-s (its gzip kept once per process); nginx answers them for
0.01 CPU-s from the ``.gz`` copies, but for 0.26 CPU-s when it compresses them itself.
"""

from __future__ import annotations

import gzip
import mimetypes
import os
import shutil
from pathlib import Path

from railval.app import security
from railval.core import lazy

#: deferred (railval.core.lazy): Bokeh and Panel only when the folders are looked up
bokeh_settings = lazy.module("bokeh.settings")
panel_resources = lazy.module("panel.io.resources")
bokeh_bundle = lazy.module("bokeh.embed.bundle")

#: the snippet's file name in the folder given to :func:`prepare`
SNIPPET = "railval-static.conf"
#: files compressed ahead (``gzip_static``): the types browsers fetch as text
GZIP_SUFFIXES = (".js", ".mjs", ".css", ".json", ".svg", ".html", ".txt")
GZIP_TYPES = ("text/javascript", "application/javascript", "text/css", "application/json",
              "image/svg+xml", "text/plain")  # and text/html, which nginx always compresses
#: Cache-Control of a static response, by whether its URL is versioned (``?v=``)
CACHE_VERSIONED = "public, max-age=31536000, immutable"
CACHE_UNVERSIONED = "no-cache"


def folders() -> dict[str, Path]:
    """The installed packages' static folders the app serves: ``bokeh`` (``/static/``) and
    ``panel`` (``/static/extensions/panel/``)."""
    return {"bokeh": Path(bokeh_settings.settings.bokehjs_path()).resolve(),
            "panel": Path(panel_resources.DIST_DIR).resolve()}


def extension_dirs() -> dict[str, Path]:
    """Bokeh's extension folders as the app process serves them under
    ``/static/extensions/NAME/`` (after Panel is imported)."""
    return {k: Path(v).resolve() for k, v in bokeh_bundle.extension_dirs.items()}


def _quoted(value: str) -> str:
    if any(c in value for c in '"\\$\n\r{}'):
        raise ValueError(f"header value {value!r} cannot be written into nginx's configuration")
    return f'"{value}"'


def mime_types(roots: list[Path]) -> dict[str, str]:
    """File suffix (no dot) → the type Tornado's ``StaticFileHandler`` sends for it
    (``mimetypes.guess_type``), for every suffix under ``roots`` that has one; nginx sends
    ``application/octet-stream`` for the rest, as Tornado does."""
    out: dict[str, str] = {}
    for root in roots:
        for _dirpath, _dirs, files in os.walk(root):
            for name in files:
                suffix = name.rsplit(".", 1)[-1] if "." in name else ""
                if suffix and suffix not in out:
                    kind, encoding = mimetypes.guess_type(name)
                    if kind and not encoding and all(c.isalnum() or c in "-_" for c in suffix):
                        out[suffix] = kind
    return dict(sorted(out.items()))


def snippet(types: dict[str, str], headers: dict[str, str] | None = None) -> str:
    """The nginx directives every static location includes: :data:`security.HEADERS` (or
    ``headers``) as ``add_header … always`` (on 404s too), HSTS as on every proxied response,
    Cache-Control by ``$railval_static_cache`` (the template's map on ``$arg_v``), the MIME
    ``types``, gzip and ``try_files $uri =404`` (a folder or a missing file is 404)."""
    lines = ["# rendered by `railval nginx-static` from railval.app.security.HEADERS: do not edit"]
    for name, value in (security.HEADERS if headers is None else headers).items():
        lines.append(f"add_header {name} {_quoted(value)} always;")
    lines += ['add_header Strict-Transport-Security "max-age=31536000" always;',
              "add_header Cache-Control $railval_static_cache always;",
              "types {"]
    by_type: dict[str, list[str]] = {}
    for suffix, kind in types.items():
        by_type.setdefault(kind, []).append(suffix)
    lines += [f"    {kind} {' '.join(sfx)};" for kind, sfx in by_type.items()]
    lines += ["}", "default_type application/octet-stream;", "charset off;",
              "gzip on;", "gzip_static on;", "gzip_vary on;", "gzip_comp_level 5;",
              "gzip_min_length 1024;", f"gzip_types {' '.join(GZIP_TYPES)};",
              "disable_symlinks if_not_owner from=$document_root;",
              "try_files $uri =404;", ""]
    return "\n".join(lines)


def _compress(root: Path) -> int:
    """Write ``NAME.gz`` beside every text file under ``root`` (level 9, mtime kept:
    ``gzip_static`` serves it instead of compressing); returns how many."""
    n = 0
    for dirpath, _dirs, files in os.walk(root):
        for name in files:
            if name.endswith(GZIP_SUFFIXES):
                src = Path(dirpath) / name
                data = src.read_bytes()
                if len(data) >= 1024:
                    dst = src.with_name(name + ".gz")
                    dst.write_bytes(gzip.compress(data, 9, mtime=0))
                    st = src.stat()
                    os.utime(dst, (st.st_atime, st.st_mtime))
                    n += 1
    return n


def _link_or_copy(src: str, dst: str) -> None:
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def prepare(dest: Path, copy: bool = True) -> dict[str, str]:
    """Write the snippet to ``dest/railval-static.conf`` and return the template's values
    ``RAILVAL_STATIC_CONF``, ``RAILVAL_BOKEH_STATIC``, ``RAILVAL_PANEL_STATIC`` (folders end
    in ``/``, as nginx's ``alias`` of a ``/``-ended location needs). ``copy``: the folders are
    copied to ``dest/bokeh`` and ``dest/panel`` (hard links where possible; also what an nginx
    container sharing a volume needs) with a ``.gz`` beside each text file; else nginx reads
    the packages' folders and compresses every response itself."""
    dest = Path(dest).resolve()
    dest.mkdir(parents=True, exist_ok=True)
    src = folders()
    if copy:
        out = {}
        for name, folder in src.items():
            target = dest / name
            if target.exists():
                shutil.rmtree(target)
            shutil.copytree(folder, target, copy_function=_link_or_copy)
            _compress(target)
            out[name] = target
        src = out
    (dest / SNIPPET).write_text(snippet(mime_types(list(src.values()))))
    return {"RAILVAL_STATIC_CONF": str(dest / SNIPPET),
            "RAILVAL_BOKEH_STATIC": f"{src['bokeh']}/",
            "RAILVAL_PANEL_STATIC": f"{src['panel']}/"}
