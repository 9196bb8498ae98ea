"""The differential tests catch a twin that drifts, and never skip where the compiled path must be there.

A mutation of the Python reference (a constant, a receive rule) is run through the very differential tests that
hold the twins equal, and they must report a difference (unmutated, the same tests pass in their own modules).
A mutation of the C is a rebuild: the manual run is in DECISIONS.md ("The gateway's compiled data path").
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest
import test_native_gateway as gateway_twins  # modules, not their tests: pytest would collect those here again
import test_native_roster as roster_twins
import test_native_tags as tags_twins
import test_native_twins as engine_twins

import vstig_hw.engine as engine_module
import vstig_hw.gateway.outlet as outlet_module
import vstig_hw.gateway.roster as roster_module
import vstig_hw.tagged as tagged_module
from vstig_hw.timestamps import is_newer

ROOT = Path(__file__).resolve().parents[2]


def test_a_python_window_with_another_pace_burst_is_caught(compiled: ModuleType,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(outlet_module, "PACE_BURST", outlet_module.PACE_BURST - 1)
    with pytest.raises((AssertionError, ExceptionGroup)):
        gateway_twins.test_window_equals_send_window(compiled=compiled)


def test_a_python_engine_that_takes_an_equal_timestamp_as_newer_is_caught(compiled: ModuleType,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(engine_module, "is_newer", lambda ts, held: ts == held or is_newer(ts, held))
    with pytest.raises((AssertionError, ExceptionGroup)):
        engine_twins.test_engine_equals_stigmergy(compiled=compiled)


def test_a_python_roster_remembering_fewer_behind_keys_is_caught(compiled: ModuleType,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(roster_module, "MAX_BEHIND_KEYS", 2)
    with pytest.raises((AssertionError, ExceptionGroup)):
        roster_twins.test_the_tally_folded_in_equals_the_python_roster(compiled=compiled)


def test_a_python_roster_whose_usual_gap_moves_faster_is_caught(compiled: ModuleType,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(roster_module, "_GAP_WEIGHT", 0.5)
    with pytest.raises((AssertionError, ExceptionGroup)):
        roster_twins.test_the_tally_folded_in_equals_the_python_roster(compiled=compiled)


def test_a_python_roster_whose_rate_moves_faster_is_caught(compiled: ModuleType,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(roster_module, "RATE_WINDOW", 0.5)  # the tally keeps the rates: the sweep's C half
    with pytest.raises((AssertionError, ExceptionGroup)):
        roster_twins.test_the_tally_folded_in_equals_the_python_roster(compiled=compiled)


def test_a_python_roster_quiet_after_fewer_usual_gaps_is_caught(compiled: ModuleType,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(roster_module, "QUIET_PERIODS", 2)  # the tally's `due` still judges with 3
    with pytest.raises((AssertionError, ExceptionGroup)):
        roster_twins.test_the_tally_folded_in_equals_the_python_roster(compiled=compiled)


def test_a_python_tagged_engine_that_orders_by_timestamp_alone_is_caught(compiled: ModuleType,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(tagged_module, "tagged_newer", lambda epoch, ts, than_epoch, than_ts: is_newer(ts, than_ts))
    with pytest.raises((AssertionError, ExceptionGroup)):
        tags_twins.test_the_compiled_delivery_with_tags_equals_the_python_node(compiled=compiled)


def _run_a_native_test(**env: str) -> subprocess.CompletedProcess[str]:
    clean = {k: v for k, v in os.environ.items() if k not in ("CI", "VSTIG_REQUIRE_NATIVE", "VSTIG_REQUIRE_PEERS")}
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
         "tests/native/test_native_declared.py::test_no_private_name_is_used"],
        cwd=ROOT, env={**clean, "VSTIG_PURE": "1", **env}, capture_output=True, text=True, timeout=120, check=False)


@pytest.mark.parametrize("requirement", [{"CI": "true"}, {"VSTIG_REQUIRE_NATIVE": "1"}])
def test_without_the_compiled_path_a_differential_test_fails_where_it_is_required(requirement: dict[str, str]
                                                                                  ) -> None:
    run = _run_a_native_test(**requirement)
    assert run.returncode == 1, run.stdout[-2000:]
    assert "but the compiled data path is not loaded (VSTIG_PURE=1)" in run.stdout


def test_without_the_compiled_path_a_differential_test_skips_elsewhere() -> None:
    run = _run_a_native_test()
    assert run.returncode == 0, run.stdout[-2000:]
    assert "1 skipped" in run.stdout
