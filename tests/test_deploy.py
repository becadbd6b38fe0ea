"""The deployment files, checked without a container engine (none runs on the build machine):
``deploy/compose.yaml`` against the Compose specification's JSON schema (check-jsonschema's
vendored ``compose-spec``) and railval's own rules for it; the nginx template renders and
passes ``nginx -t``; the systemd units pass ``systemd-analyze verify``; the image bakes in no
secret."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from railval.app import nginx_static
from railval.app.bench.topology import TEMPLATE, nginx_binary, render, self_signed
from tests.conftest import require_program

DEPLOY = Path(__file__).resolve().parent.parent / "deploy"
SECRET_NAMES = ("RAILVAL_DB_PASSWORD", "RAILVAL_SECRET_KEY", "RAILVAL_COOKIE_SECRET",
                "BOKEH_SECRET_KEY", "POSTGRES_PASSWORD")


def _check_jsonschema(path: Path) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).with_name("check-jsonschema")
    return subprocess.run([str(exe), "--builtin-schema", "vendor.compose-spec", str(path)],
                          capture_output=True, text=True, check=False)


def test_compose_file_follows_the_compose_spec(tmp_path):
    done = _check_jsonschema(DEPLOY / "compose.yaml")
    assert done.returncode == 0, done.stdout + done.stderr
    broken = tmp_path / "compose.yaml"  # the check can fail: a misspelt key is refused
    broken.write_text((DEPLOY / "compose.yaml").read_text().replace("healthcheck:", "healthchek:", 1))
    assert _check_jsonschema(broken).returncode != 0


def _compose() -> dict:
    return yaml.safe_load((DEPLOY / "compose.yaml").read_text())


def test_compose_topology_rules():
    c = _compose()
    services = c["services"]
    apps = sorted(n for n in services if re.fullmatch(r"app\d+", n))
    assert len(apps) >= 2
    upstream = services["proxy"]["environment"]["RAILVAL_APP_SERVERS"]
    for name in apps:
        svc = services[name]
        assert f"server {name}:5006" in upstream  # every app process is behind the proxy
        assert "healthcheck" in svc and "/health" in " ".join(svc["healthcheck"]["test"])
        assert svc["depends_on"]["migrate"]["condition"] == "service_completed_successfully"
        assert "--behind-proxy" in svc["command"] and "--admin" in svc["command"]
    assert services["migrate"]["command"] == ["railval", "init"]
    assert services["migrate"]["depends_on"]["db"]["condition"] == "service_healthy"
    for name in ("db", "proxy", "scheduler"):
        assert "healthcheck" in services[name], name
    assert services["worker"]["command"][:3] == ["dask", "worker", "tcp://scheduler:8786"]
    # secrets only as files: no secret value in any environment, every secret file declared
    for name, svc in services.items():
        for key, value in (svc.get("environment") or {}).items():
            assert key not in SECRET_NAMES, f"{name}: {key} holds a secret value"
            if key == "RAILVAL_WITNESS_FILE":  # state, not a secret: on a named volume
                mounts = {v.split(":")[1]: v.split(":")[0] for v in svc.get("volumes", [])}
                assert str(Path(value).parent) in mounts, (name, key)
                assert mounts[str(Path(value).parent)] in c["volumes"], (name, key)
            elif key.endswith("_FILE"):
                assert str(value).startswith("/run/secrets/"), (name, key)
                assert Path(value).name in c["secrets"], (name, key)
    mount = services["proxy"]["volumes"][0].split(":")[0]
    assert (DEPLOY / mount).resolve() == TEMPLATE


def test_image_bakes_in_no_secret():
    text = (DEPLOY / "Dockerfile").read_text()
    for name in SECRET_NAMES:
        assert not re.search(rf"^\s*(ENV|ARG)\b.*\b{name}\b", text, re.MULTILINE), name
    for src in re.findall(r"^COPY (\S+)", text, re.MULTILINE):  # every copied path exists
        assert (DEPLOY.parent / src).exists(), src


def test_nginx_template_with_the_compose_values_passes_nginx_t(tmp_path):
    binary = require_program(nginx_binary(), "nginx missing (apt-get install nginx-light)")
    env = _compose()["services"]["proxy"]["environment"]
    cert, key = self_signed(tmp_path)
    # the one-shot `static` service writes the folder the proxy mounts: its files here
    static = _compose()["services"]["static"]
    folder = static["command"][2]
    assert static["command"] == ["railval", "nginx-static", folder]  # copies with .gz files
    assert f"static:{folder}:ro" in _compose()["services"]["proxy"]["volumes"]
    made = nginx_static.prepare(tmp_path / "static", copy=False)
    assert env["RAILVAL_STATIC_CONF"] == f"{folder}/{nginx_static.SNIPPET}"
    assert (env["RAILVAL_BOKEH_STATIC"], env["RAILVAL_PANEL_STATIC"]) == (f"{folder}/bokeh/",
                                                                         f"{folder}/panel/")
    values = {**{k: str(v) for k, v in env.items()}, **made,
              "RAILVAL_TLS_CERT": str(cert), "RAILVAL_TLS_KEY": str(key),
              # container names do not resolve here: the same lines on loopback
              "RAILVAL_APP_SERVERS": re.sub(r"app\d+:", "127.0.0.1:", env["RAILVAL_APP_SERVERS"]),
              "RAILVAL_HTTPS_PORT": "127.0.0.1:8443"}
    site = render(TEMPLATE.read_text(), values)
    assert "hash $railval_route consistent" in site and "proxy_set_header Upgrade" in site
    (tmp_path / "logs").mkdir()
    (tmp_path / "railval.conf").write_text(site)
    (tmp_path / "nginx.conf").write_text(
        "pid nginx.pid; error_log logs/error.log; events {}\n"
        "http { access_log off; client_body_temp_path tmp; proxy_temp_path tmp;"
        " fastcgi_temp_path tmp; uwsgi_temp_path tmp; scgi_temp_path tmp; include railval.conf; }\n")
    done = subprocess.run([binary, "-t", "-p", str(tmp_path), "-c", str(tmp_path / "nginx.conf")],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    with pytest.raises(KeyError, match="RAILVAL_TLS_KEY"):
        render(TEMPLATE.read_text(), {k: v for k, v in values.items() if k != "RAILVAL_TLS_KEY"})


def test_systemd_units_verify(tmp_path):
    exe = require_program(shutil.which("systemd-analyze"), "systemd-analyze missing (apt-get install systemd)")
    units = []
    venv = str(Path(sys.executable).parent.parent)
    for unit in sorted((DEPLOY / "systemd").glob("railval*")):
        if unit.suffix == ".env":
            continue
        name = unit.name.replace("@.service", "@5006.service")
        text = unit.read_text().replace("/opt/railval/venv", venv)  # this machine's railval
        (tmp_path / name).write_text(text)
        units.append(str(tmp_path / name))
    done = subprocess.run([exe, "verify", "--man=no", *units], capture_output=True, text=True,
                          cwd=tmp_path, check=False)
    problems = [ln for ln in (done.stdout + done.stderr).splitlines() if ln.strip()]
    assert done.returncode == 0 and not problems, problems
    bad = tmp_path / "railval-bad.service"
    bad.write_text("[Service]\nExecStart=relative/path\nRestart=sometimes\n")
    assert subprocess.run([exe, "verify", "--man=no", str(bad)], capture_output=True, check=False).returncode != 0


def test_a_missing_program_fails_when_required(monkeypatch):
    """Under CI (RAILVAL_REQUIRE_PROGRAMS=1) a missing nginx or systemd-analyze is a failure,
    not a skip; outside CI a skip with the install hint."""
    monkeypatch.setenv("RAILVAL_REQUIRE_PROGRAMS", "1")
    with pytest.raises(pytest.fail.Exception, match="nginx missing"):
        require_program(None, "nginx missing (apt-get install nginx-light)")
    monkeypatch.setenv("RAILVAL_REQUIRE_PROGRAMS", "0")
    with pytest.raises(pytest.skip.Exception, match="nginx missing"):
        require_program(None, "nginx missing (apt-get install nginx-light)")
    assert require_program("/usr/sbin/nginx", "unused") == "/usr/sbin/nginx"
