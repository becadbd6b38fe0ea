"""The production topology on one machine, without containers: N ``railval serve`` processes
on their own loopback ports behind real nginx (``deploy/nginx/railval.conf.template``) with
TLS (a self-signed certificate made by ``openssl``). Used by the topology test
(tests/test_team_server.py) and ``railval bench team``.

``Topology(db_url, workdir, n_apps=2).start()`` renders the nginx template exactly as a site
does (only the ``${RAILVAL_*}`` names are substituted, like envsubst in the nginx image; the
static folders and the security-header snippet from :func:`railval.app.nginx_static.prepare`),
writes the secrets to files (the app reads ``*_FILE`` settings, :mod:`railval.db.settings`),
starts the app processes and nginx, and waits until ``/health`` answers through the proxy.
"""

from __future__ import annotations

import base64
import json
import os
import re
import secrets
import shutil
import signal
import socket
import ssl
import subprocess
import sys
import time
import urllib.error
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path
from typing import Self

from railval.core import lazy

#: deferred (railval.core.lazy): the app module (Panel, Bokeh) runs in the served processes,
#: not in the one that starts them
upkeep = lazy.module("railval.app.upkeep")
nginx_static = lazy.module("railval.app.nginx_static")
#: the certificate's key read by :func:`browser_trust` only
x509 = lazy.module("cryptography.x509")
hashes = lazy.module("cryptography.hazmat.primitives.hashes")
serialization = lazy.module("cryptography.hazmat.primitives.serialization")

REPO = Path(__file__).resolve().parents[2]
TEMPLATE = REPO / "deploy" / "nginx" / "railval.conf.template"
_VAR = re.compile(r"\$\{(RAILVAL_[A-Z0-9_]+)\}")


def nginx_binary() -> str | None:
    """Path of Debian's nginx (``apt-get install nginx-light``), else None."""
    return shutil.which("nginx") or (("/usr/sbin/nginx") if os.path.exists("/usr/sbin/nginx") else None)


def render(template: str, values: dict[str, str]) -> str:
    """``template`` with its ``${RAILVAL_*}`` names replaced; a name without value raises."""
    missing = sorted({m for m in _VAR.findall(template) if m not in values})
    if missing:
        raise KeyError(f"no value for {', '.join(missing)}")
    return _VAR.sub(lambda m: values[m.group(1)], template)


def readable(folder: Path) -> None:
    """Let every user traverse to ``folder``: ``o+x`` on each of its ancestors lacking it (a
    ``mkdtemp`` folder is 0700; nginx's workers run as another user)."""
    for p in folder.parents:
        mode = p.stat().st_mode
        if not mode & 0o001:
            p.chmod(mode | 0o001)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def self_signed(folder: Path, host: str = "127.0.0.1") -> tuple[Path, Path]:
    """A self-signed certificate for ``host`` (openssl; 2 days); returns (cert, key)."""
    cert, key = folder / "tls.crt", folder / "tls.key"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "2",
                    "-subj", f"/CN={host}", "-addext", f"subjectAltName=IP:{host},DNS:localhost",
                    "-keyout", str(key), "-out", str(cert)], check=True, capture_output=True)
    key.chmod(0o600)
    return cert, key


#: FastListTemplate's Google Fonts requests fail at once (no route: Playwright's request
#: interception turns the browser's HTTP cache off)
NO_FONT_HOSTS = "--host-resolver-rules=MAP fonts.googleapis.com ~NOTFOUND, MAP fonts.gstatic.com ~NOTFOUND"


def browser_trust(cert: Path) -> list[str]:
    """Chromium flags under which the topology's self-signed certificate ``cert`` is trusted
    (its public key's SHA-256 in ``--ignore-certificate-errors-spki-list``) rather than an
    error passed over: a page whose certificate is in error is never stored in the browser's
    cache, so a returning engineer's cached static files could not be measured otherwise; and
    :data:`NO_FONT_HOSTS`."""
    key = x509.load_pem_x509_certificate(cert.read_bytes()).public_key()
    spki = key.public_bytes(serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo)
    digest = hashes.Hash(hashes.SHA256())
    digest.update(spki)
    return [f"--ignore-certificate-errors-spki-list={base64.b64encode(digest.finalize()).decode()}", NO_FONT_HOSTS]


def insecure_context() -> ssl.SSLContext:
    """TLS client context that accepts the test's self-signed certificate."""
    ctx = ssl.create_default_context()
    ctx.check_hostname = False
    ctx.verify_mode = ssl.CERT_NONE
    return ctx


@dataclass
class Topology:
    db_url: str
    workdir: Path
    n_apps: int = 2
    extra_args: list[str] = field(default_factory=list)
    #: environment of the app processes on top of the deployment's (railval.app.upkeep.SERVE_ENV)
    app_env: dict[str, str] | None = None
    #: Panel's admin page on the app processes (it keeps a record of every session it saw)
    admin: bool = True
    #: the nginx site template (``--nginx-template`` of ``railval bench team``: an older one)
    template: Path = TEMPLATE
    #: static folders copied with ``.gz`` files beside them (``railval nginx-static``, ≈ 15 s)
    #: instead of nginx reading the packages' folders and compressing itself (tests: quicker)
    static_copy: bool = False
    apps: dict[int, subprocess.Popen] = field(default_factory=dict)
    nginx: subprocess.Popen | None = None
    port: int = 0

    @property
    def url(self) -> str:
        return f"https://127.0.0.1:{self.port}"

    def _env(self) -> dict[str, str]:
        env = {k: v for k, v in os.environ.items()
               if not k.startswith(("RAILVAL_", "BOKEH_SECRET", "PYTHONMALLOC"))}
        env.update(upkeep.SERVE_ENV if self.app_env is None else self.app_env)
        env.update(RAILVAL_DB=self.db_url, PYTHONUNBUFFERED="1")
        for name in ("RAILVAL_SECRET_KEY", "RAILVAL_COOKIE_SECRET", "BOKEH_SECRET_KEY"):
            env[f"{name}_FILE"] = str(self.workdir / "secrets" / name.lower())
        return env

    def _secrets(self) -> None:
        d = self.workdir / "secrets"
        d.mkdir(parents=True, exist_ok=True)
        for name in ("railval_secret_key", "railval_cookie_secret", "bokeh_secret_key"):
            p = d / name
            if not p.exists():
                p.write_text(secrets.token_urlsafe(36) + "\n")
                p.chmod(0o600)

    def start_app(self, port: int) -> subprocess.Popen:
        log = open(self.workdir / f"app-{port}.log", "ab")  # noqa: SIM115 - lives with the process
        proc = subprocess.Popen(
            [sys.executable, "-m", "railval.app", "serve", "--address", "127.0.0.1", "--port",
             str(port), "--no-demo", "--behind-proxy", *(["--admin"] if self.admin else []),
             "--allow-websocket-origin", f"127.0.0.1:{self.port}", *self.extra_args],
            env=self._env(), stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        self.apps[port] = proc
        return proc

    def start(self, timeout_s: float = 90.0) -> Topology:
        binary = nginx_binary()
        if binary is None:
            raise RuntimeError("nginx not installed (apt-get install nginx-light)")
        self.workdir.mkdir(parents=True, exist_ok=True)
        self._secrets()
        self.port = free_port()
        ports = [free_port() for _ in range(self.n_apps)]
        cert, key = self_signed(self.workdir)
        if self.static_copy:  # nginx's workers (user nobody under root) read the copies
            readable(self.workdir / "static")
        site = render(self.template.read_text(), {
            **nginx_static.prepare(self.workdir / "static", copy=self.static_copy),
            "RAILVAL_HOST": "127.0.0.1", "RAILVAL_HTTPS_PORT": f"127.0.0.1:{self.port}",
            "RAILVAL_TLS_CERT": str(cert), "RAILVAL_TLS_KEY": str(key),
            "RAILVAL_APP_SERVERS": "\n    ".join(
                f"server 127.0.0.1:{p} max_fails=1 fail_timeout=10s;" for p in ports)})
        ng = self.workdir / "nginx"
        for sub in ("logs", "tmp"):
            (ng / sub).mkdir(parents=True, exist_ok=True)
        (ng / "railval.conf").write_text(site)
        (ng / "nginx.conf").write_text(
            "worker_processes 1;\npid nginx.pid;\nerror_log logs/error.log warn;\n"
            "events { worker_connections 1024; }\nhttp {\n"
            # which requests an app process answered: $upstream_addr is "-" for the static
            # files nginx answers itself (tests/test_nginx_static.py)
            "  log_format railval '$status $upstream_addr \"$request\"';\n"
            "  access_log logs/access.log railval;\n"
            "  client_body_temp_path tmp/body; proxy_temp_path tmp/proxy;\n"
            "  fastcgi_temp_path tmp/fcgi; uwsgi_temp_path tmp/uwsgi; scgi_temp_path tmp/scgi;\n"
            "  include railval.conf;\n}\n")
        for p in ports:
            self.start_app(p)
        subprocess.run([binary, "-t", "-p", str(ng), "-c", str(ng / "nginx.conf")],
                       check=True, capture_output=True)
        self.nginx = subprocess.Popen(
            [binary, "-p", str(ng), "-c", str(ng / "nginx.conf"), "-g", "daemon off;"],
            stdout=subprocess.DEVNULL, stderr=open(ng / "logs" / "stderr.log", "ab"),  # noqa: SIM115
            start_new_session=True)
        deadline = time.monotonic() + timeout_s
        for p in ports:
            self.wait_healthy(f"http://127.0.0.1:{p}/health", deadline)
        self.wait_healthy(f"{self.url}/health", deadline)
        return self

    def wait_healthy(self, url: str, deadline: float) -> dict:
        ctx = insecure_context() if url.startswith("https") else None
        while True:
            try:
                with urllib.request.urlopen(url, timeout=5, context=ctx) as r:
                    return json.loads(r.read())
            except (OSError, urllib.error.URLError):
                if time.monotonic() > deadline:
                    raise TimeoutError(f"{url} did not answer; logs in {self.workdir}") from None
                time.sleep(0.2)

    def kill(self, port: int) -> None:
        """Kill one app process at once (SIGKILL: no clean shutdown)."""
        proc = self.apps.pop(port)
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(10)

    def port_of(self, pid: int) -> int:
        return next(p for p, proc in self.apps.items() if proc.pid == pid)

    def stop(self) -> None:
        for proc in [*self.apps.values(), *([self.nginx] if self.nginx else [])]:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
        for proc in [*self.apps.values(), *([self.nginx] if self.nginx else [])]:
            try:
                proc.wait(15)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
        self.apps.clear()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
