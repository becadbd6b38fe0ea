"""A sign-off's recomputed validation result is the same evidence when it differs from the
signed one only in the last digits a different numpy/scipy build's summation order gives
(docs/audit.md "Recomputed result"); any larger change of a number, and any change of the
inputs, still makes the sign-off stale."""

from __future__ import annotations

import math

from railval.app.services.signoff import RESULT_REL_TOL, manifest_differences, same_numbers


def _result(mean: float) -> dict:
    return {"quantities": [{"quantity": "Y_qst", "unit": "kN", "n": 16, "mean": mean, "std": 0.29}],
            "verdict": "validated"}


def test_the_last_digits_of_a_recomputed_mean_are_the_same_evidence():
    signed, now = 0.2620494238930934, 0.26204942389309366  # seen after a library upgrade
    assert signed != now and math.isclose(signed, now, rel_tol=1e-14)  # ≈ 4 units in the last place
    m = {"inputs": {"signals": "ab" * 32}, "result": _result(signed)}
    assert manifest_differences(m, {"inputs": {"signals": "ab" * 32}, "result": _result(now)}) == []


def test_a_material_change_of_the_result_or_any_change_of_the_inputs_is_stale():
    m = {"inputs": {"signals": "ab" * 32}, "result": _result(0.262)}
    moved = _result(0.262 * (1 + 10 * RESULT_REL_TOL))
    assert manifest_differences(m, {"inputs": {"signals": "ab" * 32}, "result": moved})
    assert manifest_differences(m, {"inputs": {"signals": "ac" * 32}, "result": _result(0.262)})
    flipped = {**_result(0.262), "verdict": "not validated"}
    assert manifest_differences(m, {"inputs": {"signals": "ab" * 32}, "result": flipped})


def test_same_numbers_is_exact_on_everything_but_numbers():
    assert same_numbers({"a": [1.0, None, "x", True]}, {"a": [1.0 + 1e-16, None, "x", True]})
    assert not same_numbers({"a": 1.0}, {"b": 1.0})
    assert not same_numbers([1.0, 2.0], [1.0])
    assert not same_numbers(True, 1)
    assert not same_numbers(10**10, 10**10 + 1)  # a count is compared exactly
    assert not same_numbers(None, 0.0)
    assert same_numbers(float("nan"), float("nan"))
    assert not same_numbers(0.0, 1e-9)
