"""One validation pipeline (issue 30): the many-configurations path
(``validate_configurations``, the DynoTRAIN scale, ``railval bench dynotrain``) checks the
seals of the evidence first like ``validate_configuration`` and reports the same info."""

from __future__ import annotations

import pytest
from sqlalchemy import select, update

from railval.app.services.validation import validate_configuration, validate_configurations
from railval.db import codec, integrity
from railval.db.importer import import_campaign
from railval.db.models import Channel, Recording, Section, Signal
from tests.factories import write_demo_campaign


def test_many_configurations_refuse_a_forged_signal(database, tmp_path):
    write_demo_campaign(tmp_path / "c", n_sections=12, fmt="csv", n_configs=2, fs=200.0)
    import_campaign(database, tmp_path / "c")
    many = validate_configurations(database, "demo", n_boot=0)
    with database.write_session(deferred=True) as s:
        single = validate_configuration(s, "demo", "variant1", n_boot=0)
    assert many["variant1"].info["sections_simulated"] == {"cached": 0, "computed": 12}
    assert single.info["sections_simulated"] == {"cached": 12, "computed": 0}
    assert {k: v for k, v in many["variant1"].info.items() if not k.startswith("sections_")} \
        == {k: v for k, v in single.info.items() if not k.startswith("sections_")}
    with database.session(write=True) as s:
        sig_id, blob = s.execute(
            select(Signal.id, Signal.blob)
            .join(Recording, Signal.recording_id == Recording.id)
            .join(Section, Recording.section_id == Section.id)
            .join(Channel, Signal.channel_id == Channel.id)
            .where(Channel.name == "Y_w1L", Section.section_id == "S03",
                   Recording.configuration_id.is_(None))).first()
        forged, sha = codec.encode(codec.decode(blob) * 0.5)
        s.execute(update(Signal).where(Signal.id == sig_id).values(blob=forged, sha256=sha))
    with pytest.raises(integrity.IntegrityError, match="section S03, measurement, Y_w1L"):
        validate_configurations(database, "demo", ["baseline"], n_boot=0)
