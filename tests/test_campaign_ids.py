"""A campaign name of digits only cannot hide another campaign's id (db/campaigns.py).

The CLI takes a campaign's name or numeric id (``railval validate 1``). A campaign called
``1`` would be found instead of the campaign with id 1. Every way a campaign is created
(``railval import``, ``railval synth``, the Import page's zip upload) refuses such a name with
a precise error and stores nothing, and a digits argument always means the id — even when an
older database (or a restored backup) holds a row named ``1``. Both database backends.
"""

from __future__ import annotations

import io
import json
import zipfile

import pytest
from sqlalchemy import func, select, update

from railval.app.cli import main
from railval.app.services.synth import synth
from railval.app.services.web_import import import_zip
from railval.core.errors import CampaignFormatError, InvalidParameter
from railval.core.roles import Principal
from railval.db import repo
from railval.db.campaigns import check_campaign_name, get_campaign, is_campaign_id
from railval.db.engine import connect
from railval.db.importer import import_campaign
from railval.db.models import Campaign, Signal

from tests.factories import write_demo_campaign

ENGINEER = Principal("eng", frozenset({"engineer"}))


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    root = tmp_path_factory.mktemp("ids")
    for name in ("alpha", "beta", "1"):
        write_demo_campaign(root / name, n_sections=1, fs=50.0, seed=len(name), name=name)
    return root


def _state(db):
    with db.session() as s:
        return ([c.name for c in repo.list_campaigns(s)],
                s.scalar(select(func.count()).select_from(Signal)))


def _zip(folder) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for p in sorted(folder.rglob("*")):
            if p.is_file():
                zf.write(p, p.relative_to(folder).as_posix())
    return buf.getvalue()


def test_digits_name_refused_by_every_door(database, folders):
    import_campaign(database, folders / "alpha")
    before = _state(database)
    with pytest.raises(CampaignFormatError, match=r"campaign name '1' is digits only: a campaign "
                       r"is also found by its numeric id \(`railval validate 1` means the "
                       r"campaign with id 1\).*add a letter, e\.g\. 'C1'") as info:
        import_campaign(database, folders / "1")
    assert (info.value.file, info.value.field) == ("campaign.json", "name")
    assert _state(database) == before
    with pytest.raises(CampaignFormatError, match="campaign name '1' is digits only") as info:
        import_zip(database, ENGINEER, _zip(folders / "1"), "one.zip")
    assert (info.value.file, info.value.field) == ("campaign.json", "name")
    assert _state(database) == before
    with pytest.raises(InvalidParameter, match="campaign name '2026' is digits only"):
        synth(database, name="2026", n_sections=1)  # refused before minutes of simulation
    assert _state(database) == before


def test_name_rule():
    assert check_campaign_name("C1") == "C1" and check_campaign_name("1a") == "1a"
    for bad in ("1", "007", "2026"):
        with pytest.raises(InvalidParameter, match="digits only"):
            check_campaign_name(bad)
    assert is_campaign_id("12") and is_campaign_id(3) and is_campaign_id(" 4 ")
    # superscript digits are str.isdigit() but no id; 19 digits exceed a 64-bit id
    assert not is_campaign_id("²") and not is_campaign_id("1" * 19) and not is_campaign_id("1a")


def test_digits_argument_is_the_id_even_beside_a_row_named_so(database, folders, capsys):
    """The attack: a row called "1" (planted by an older version, or a restored backup) next
    to the campaign with id 1. `railval validate 1` must act on campaign id 1."""
    import_campaign(database, folders / "alpha")
    import_campaign(database, folders / "beta")

    def validate(arg: str) -> list[dict]:
        capsys.readouterr()
        assert main(["--db", database.url, "validate", arg, "--config", "baseline", "--json",
                     "--boot", "0"]) == 0
        return json.loads(capsys.readouterr().out)["quantities"]

    beta = validate("beta")
    with database.session(write=True) as s:
        alpha_id = s.scalar(select(Campaign.id).where(Campaign.name == "alpha"))
        beta_id = s.scalar(select(Campaign.id).where(Campaign.name == "beta"))
        s.execute(update(Campaign).where(Campaign.id == beta_id).values(name=str(alpha_id)))
    with database.session() as s:
        assert get_campaign(s, str(alpha_id)).name == "alpha"
        assert get_campaign(s, alpha_id).name == "alpha"
        assert get_campaign(s, str(beta_id)).name == str(alpha_id)  # reachable by its own id
        for text in ("²", "9" * 30):  # neither a crash nor an overflow in the database
            with pytest.raises(Exception, match="not found"):
                get_campaign(s, text)
    by_id, alpha = validate(str(alpha_id)), validate("alpha")
    assert by_id == alpha  # the campaign with id 1, not the row called "1"
    assert beta != alpha  # (the two campaigns' data differ: the check can tell them apart)
