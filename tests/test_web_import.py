"""Import through the browser's upload path (app/services/web_import.py) against the CLI
import: identical signal hashes and seals' validity, the same refusal messages, nothing stored
on rejection, an audit row naming the signed-in user, hostile zips refused."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import pytest
from sqlalchemy import func, select

from railval.app.cli import main
from railval.app.services.web_import import MAX_UPLOAD_MB, import_zip, unpack
from railval.core.errors import CampaignFormatError
from railval.core.roles import PermissionDenied, Principal
from railval.db.engine import connect

ENGINEER = Principal("eng", frozenset({"engineer"}))


def zip_folder(folder: Path, top: str | None = "demo") -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for p in sorted(folder.rglob("*")):
            if p.is_file():
                rel = p.relative_to(folder).as_posix()
                zf.write(p, f"{top}/{rel}" if top else rel)
    return buf.getvalue()


def signal_hashes(db, campaign: str = "demo") -> list[tuple]:
    from railval.db.models import Campaign, Channel, Configuration, Recording, Section, Signal

    with db.session() as s:
        rows = s.execute(
            select(Section.section_id, Configuration.name, Channel.name, Signal.sha256)
            .join(Recording, Signal.recording_id == Recording.id)
            .join(Section, Recording.section_id == Section.id)
            .outerjoin(Configuration, Recording.configuration_id == Configuration.id)
            .join(Channel, Signal.channel_id == Channel.id)
            .join(Campaign, Section.campaign_id == Campaign.id)
            .where(Campaign.name == campaign)).all()
    return sorted((a, b or "", c, d) for a, b, c, d in rows)


@pytest.fixture(scope="module")
def campaign_dir(tmp_path_factory):
    from tests.factories import write_demo_campaign

    folder = tmp_path_factory.mktemp("upload") / "demo"
    write_demo_campaign(folder, n_sections=4, fs=50.0, n_configs=2)
    return folder


def test_upload_equals_cli_import(campaign_dir, db_url, tmp_path, capsys):
    from railval.db import repo
    from railval.db.models import AuditEvent

    web = connect(db_url)
    web.init()
    for top in ("demo", None):  # zip of the folder, or of its contents
        data = zip_folder(campaign_dir, top)
        assert import_zip(web, ENGINEER, data, "demo.zip") == "demo"
        with web.session() as s:
            ev = s.scalars(select(AuditEvent).where(AuditEvent.action == "campaign.import")).all()[-1]
            assert ev.actor == "eng" and ev.object == "campaign:demo"
            assert repo.verify_storage(s)["ok"]
            web_after = ev.after_sha256
        web_hashes = signal_hashes(web)
        with web.session(write=True) as s:  # room for the second round
            from railval.db.models import Campaign

            s.delete(s.scalar(select(Campaign).where(Campaign.name == "demo")))
    web.dispose()
    cli_url = f"sqlite:///{tmp_path / 'cli.db'}"
    assert main(["--db", cli_url, "import", str(campaign_dir), "--no-progress"]) == 0
    cli = connect(cli_url)
    with cli.session() as s:
        (cli_ev,) = s.scalars(select(AuditEvent).where(AuditEvent.action == "campaign.import")).all()
    assert signal_hashes(cli) == web_hashes and len(web_hashes) > 100
    assert cli_ev.after_sha256 == web_after  # manifest + every content hash
    cli.dispose()


def _count(db) -> int:
    from railval.db.models import Signal

    with db.session() as s:
        return s.scalar(select(func.count()).select_from(Signal))


def test_rejections_store_nothing_and_name_the_place(campaign_dir, sqlite_database, tmp_path):
    import shutil

    bad = tmp_path / "demo"
    shutil.copytree(campaign_dir, bad)
    m = json.loads((bad / "campaign.json").read_text())
    for ch in m["channels"]:
        if ch["name"].startswith("Y_"):
            ch["unit"] = "N"  # kN data declared as N: too small for their unit
    (bad / "campaign.json").write_text(json.dumps(m))
    with pytest.raises(CampaignFormatError, match="file measured/S01.csv, field Y_w.*look like kN "
                       "declared as N"):
        import_zip(sqlite_database, ENGINEER, zip_folder(bad))
    assert _count(sqlite_database) == 0
    with pytest.raises(PermissionDenied):
        import_zip(sqlite_database, Principal("ass", frozenset({"assessor"})), zip_folder(campaign_dir))
    with pytest.raises(CampaignFormatError, match="upload.zip.*not a zip file"):
        import_zip(sqlite_database, ENGINEER, b"PK\x03\x04 not really")
    assert _count(sqlite_database) == 0


@pytest.mark.parametrize("entry,match", [
    ("../evil.txt", "leaves the campaign folder"),
    ("/etc/evil", "leaves the campaign folder"),
    ("a\\..\\b", "leaves the campaign folder"),
])
def test_hostile_zip_entries_refused(tmp_path, entry, match):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr(entry, "x")
    with pytest.raises(CampaignFormatError, match=match):
        unpack(buf.getvalue(), tmp_path / "out")
    assert not (tmp_path / "evil.txt").exists()


def test_size_cap_is_stated_and_enforced(tmp_path):
    with pytest.raises(CampaignFormatError, match=f"larger than the upload limit {MAX_UPLOAD_MB} MB"):
        unpack(b"\0" * (MAX_UPLOAD_MB * 1024 * 1024 + 1), tmp_path)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr("a/readme.txt", "x")
        zf.writestr("b/campaign.json", "{}")
    with pytest.raises(CampaignFormatError, match="no campaign.json at the top of the zip"):
        unpack(buf.getvalue(), tmp_path / "e")


def configuration_folder(campaign_dir: Path, dest: Path, name: str = "mbs1",
                         parent: str | None = "baseline") -> Path:
    """A configuration upload: the variant1 files of the demo folder as configuration ``name``."""
    import shutil

    m = json.loads((campaign_dir / "campaign.json").read_text())
    (entry,) = [c for c in m["configurations"] if c["name"] == "variant1"]
    dest.mkdir(parents=True)
    for rel in entry["files"].values():
        (dest / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(campaign_dir / rel, dest / rel)
    (dest / "configuration.json").write_text(json.dumps({**entry, "name": name, "parent": parent}))
    return dest


def test_configuration_upload_equals_cli_and_checks(campaign_dir, tmp_path, capsys):
    from railval.app.services.web_import import import_configuration_zip
    from railval.db import repo
    from railval.db.models import AuditEvent
    from tests.factories import write_demo_campaign

    base = tmp_path / "base"
    write_demo_campaign(base, n_sections=4, fs=50.0, n_configs=1)
    conf = configuration_folder(campaign_dir, tmp_path / "conf")
    urls = {k: f"sqlite:///{tmp_path / f'{k}.db'}" for k in ("web", "cli")}
    for url in urls.values():
        assert main(["--db", url, "import", str(base), "--no-progress"]) == 0
    assert main(["--db", urls["cli"], "import", str(conf), "--into", "demo"]) == 0
    web = connect(urls["web"])
    assert import_configuration_zip(web, ENGINEER, "demo", zip_folder(conf, "mbs1")) == "mbs1"
    cli = connect(urls["cli"])
    try:
        assert signal_hashes(web) == signal_hashes(cli)
        assert {h for h in signal_hashes(web) if h[1] == "mbs1"}
        with web.session() as s:
            assert repo.get_configuration(s, "demo", "mbs1").parent.name == "baseline"
            ev = s.scalars(select(AuditEvent).where(AuditEvent.action == "configuration.import")).one()
            assert ev.actor == "eng" and ev.object == "configuration:demo/mbs1"
            assert repo.verify_storage(s)["ok"]
        # the same name again, an unknown parent, kN guiding forces declared in N: refused,
        # nothing stored
        before = _count(web)
        with pytest.raises(CampaignFormatError, match="field name: campaign 'demo' already has"):
            import_configuration_zip(web, ENGINEER, "demo", zip_folder(conf, None))
        other = configuration_folder(campaign_dir, tmp_path / "c2", "mbs2", parent="nope")
        with pytest.raises(CampaignFormatError, match="field parent: unknown parent configuration 'nope'"):
            import_configuration_zip(web, ENGINEER, "demo", zip_folder(other, None))
        assert _count(web) == before
    finally:
        web.dispose()
        cli.dispose()


def test_import_page_adds_a_configuration_to_the_selected_campaign(campaign_dir, tmp_path):
    """The Import page's state and job without a browser (the browser upload of a campaign is
    in tests/test_team_server.py): configuration mode, progress, result, new selection;
    a refusal lands in the status area and stores nothing."""
    from railval.app.pages.importer import ImportPage
    from railval.app.state import AppState, Backend
    from tests.factories import write_demo_campaign

    base = tmp_path / "base"
    write_demo_campaign(base, n_sections=4, fs=50.0, n_configs=1)
    url = f"sqlite:///{tmp_path / 'page.db'}"
    assert main(["--db", url, "import", str(base), "--no-progress"]) == 0
    db = connect(url)
    try:
        app = AppState(Backend(db), principal=ENGINEER)
        page = ImportPage(app)
        page.safe_refresh()
        page.kind.value = "configuration"
        page.file.filename = "mbs1.zip"
        page.file.value = zip_folder(configuration_folder(campaign_dir, tmp_path / "c"), None)
        page.start()
        app.wait(60)
        assert app.status_level == "success", app.status
        assert "configuration <b>mbs1</b> into campaign <b>demo</b>" in page.result.object
        assert app.configuration == "mbs1"
        n = _count(db)
        page.file.filename = "again.zip"
        page.file.value = zip_folder(tmp_path / "c", None)
        page.start()
        app.wait(60)
        assert app.status_level == "error" and "already has a configuration named 'mbs1'" in app.status
        assert _count(db) == n
    finally:
        db.dispose()
