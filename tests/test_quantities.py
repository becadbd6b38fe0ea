"""The quantity registry against Polach & Böttcher 2014 Table 2 (typed in here independently)."""

from __future__ import annotations

import pytest

from railval.core.errors import InvalidParameter
from railval.core.quantities import QUANTITIES, QUANTITY_IDS, get, limits, pairs_for_channels
from railval.core.types import WHEEL_POSITIONS

# Table 2 of Polach & Böttcher 2014: id → (unit, filter, processing, std limit at Q0)
TABLE2 = {
    "Y_qst": ("kN", "lowpass", "median", lambda q0: 5.0),
    "Q_qst": ("kN", "lowpass", "median", lambda q0: 4.0 * (1 + 0.01 * q0)),
    "YQ_qst": ("-", "lowpass", "median", lambda q0: 0.07),
    "SumY_qst": ("kN", "lowpass", "median", lambda q0: 6.0),
    "Y_max": ("kN", "lowpass", "maxabs", lambda q0: 9.0),
    "Q_max": ("kN", "lowpass", "p99.85", lambda q0: 6.0 * (1 + 0.01 * q0)),
    "YQ_max": ("-", "lowpass", "maxabs", lambda q0: 0.10),
    "SumY_max": ("kN", "lowpass", "maxabs", lambda q0: 9.0),
    "ay_rms": ("m/s^2", "bandpass", "rms", lambda q0: 0.15),
    "az_rms": ("m/s^2", "bandpass", "rms", lambda q0: 0.15),
    "ay_max": ("m/s^2", "bandpass", "maxabs", lambda q0: 0.40),
    "az_max": ("m/s^2", "bandpass", "maxabs", lambda q0: 0.40),
}
ACC = {"ay_rms", "az_rms", "ay_max", "az_max"}


def test_ids_exactly_the_twelve_of_table2():
    assert QUANTITY_IDS == ("Y_qst", "Q_qst", "YQ_qst", "SumY_qst", "Y_max", "Q_max", "YQ_max",
                            "SumY_max", "ay_rms", "az_rms", "ay_max", "az_max")


@pytest.mark.parametrize("qid", list(TABLE2))
def test_unit_filter_processing(qid):
    unit, filt, proc, _ = TABLE2[qid]
    q = QUANTITIES[qid]
    assert (q.unit, q.filter, q.processing) == (unit, filt, proc)
    assert q.sliding_mean == (qid in ("YQ_max", "SumY_max"))
    assert "Table 2" in q.source


@pytest.mark.parametrize("q0", [50.0, 77.3, 112.5])
@pytest.mark.parametrize("kind,secondary,acc_factor", [
    ("passenger", True, 1.0), ("freight", True, 2.0), ("passenger", False, 2.0),
    ("freight", False, 2.0)])
def test_limits_equal_table2(q0, kind, secondary, acc_factor):
    lim = limits(q0, kind, secondary)
    for qid, (_, _, _, std) in TABLE2.items():
        factor = acc_factor if qid in ACC else 1.0
        expected_std = std(q0) * factor
        assert lim[qid][1] == pytest.approx(expected_std, rel=1e-15)
        assert lim[qid][0] == pytest.approx(expected_std * 2 / 3, rel=1e-15)


def test_q_limits_at_q0_80():
    # 4·(1 + 0.8) = 7.2 kN and 6·1.8 = 10.8 kN; mean limits 4.8 and 7.2 kN
    assert get("Q_qst").std_limit(80.0) == pytest.approx(7.2)
    assert get("Q_max").std_limit(80.0) == pytest.approx(10.8)
    assert get("Q_qst").mean_limit(80.0) == pytest.approx(4.8)
    assert get("Q_max").mean_limit(80.0) == pytest.approx(7.2)


def test_q_limit_needs_q0_and_kind_is_checked():
    with pytest.raises(InvalidParameter, match="Q0_kN"):
        get("Q_qst").std_limit(None)
    with pytest.raises(InvalidParameter, match="vehicle kind"):
        get("Y_qst").std_limit(80.0, "tram")
    with pytest.raises(InvalidParameter, match="unknown quantity 'X'"):
        get("X")


def test_pair_channels():
    assert get("Y_qst").channels("w1L") == ("Y_w1L",)
    assert get("Q_max").channels("w4R") == ("Q_w4R",)
    assert get("YQ_max").channels("w2R") == ("Y_w2R", "Q_w2R")
    assert get("SumY_qst").channels("ws3") == ("Y_w3L", "Y_w3R")
    assert get("ay_rms").channels("b2") == ("ay_cb_b2",)
    assert get("az_max").channels("b1") == ("az_cb_b1",)
    with pytest.raises(InvalidParameter, match="position 'b1' is not a wheel position"):
        get("Y_qst").channels("b1")


def test_available_positions_and_pairs():
    chans = ["Y_w1L", "Y_w1R", "Q_w1L", "ay_cb_b1", "az_cb_b2", "ay_bg_b1"]
    assert get("SumY_qst").available_positions(chans) == ["ws1"]
    assert get("YQ_qst").available_positions(chans) == ["w1L"]
    assert get("Y_max").available_positions(chans) == ["w1L", "w1R"]
    pairs = pairs_for_channels(chans)
    assert ("ay_rms", "b1") in pairs and ("az_rms", "b2") in pairs
    assert ("ay_rms", "b2") not in pairs
    full = [f"{k}_{p}" for k in "YQ" for p in WHEEL_POSITIONS] + [
        f"{k}_cb_{b}" for k in ("ay", "az") for b in ("b1", "b2")]
    # 8 wheels × 6 + 4 wheelsets × 2 + 2 positions × 4 acceleration quantities
    assert len(pairs_for_channels(full)) == 48 + 8 + 8


def test_registry_to_dict_is_json_ready():
    import json

    doc = [q.to_dict() for q in QUANTITIES.values()]
    assert json.loads(json.dumps(doc))[6]["filtering"].startswith("low-pass 20 Hz, then sliding")
