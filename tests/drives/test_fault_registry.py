"""The fault registry is the one list of fault kinds: the drive, the injector, the machine's
specs, the REST list and the docs all follow it; encoder_noise is its proof row."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import pytest

from cnc.machine.faults import valid_specs
from drives import fault_docgen
from drives.cia402 import FAULTS, INJECT_KINDS, Drive402, State
from drives.fault_registry import _KINDS, DRIVE_FAULTS, FAULT_KINDS, _checked
from drives.faults import DETECTION, RECOVERY, describe, fault_types
from drives.plant import Plant

ROOT = Path(__file__).resolve().parents[2]
T = 0.002


def test_every_list_of_kinds_is_the_registry():
    assert tuple(k for k, row in FAULT_KINDS.items() if row.target == "drive") == INJECT_KINDS
    assert set(DETECTION) == set(RECOVERY) == set(FAULT_KINDS)
    assert [row["type"] for row in fault_types()] == list(FAULT_KINDS)
    assert [row["kind"] for row in describe()] == list(FAULT_KINDS)
    specs = " ".join(valid_specs())
    for name, row in FAULT_KINDS.items():
        form = f"bus:{name}:<AXIS>" if row.target == "bus" else f"drive:<AXIS>:{name}"
        assert form in specs, name


def test_every_emcy_code_of_a_kind_is_in_the_drives_catalogue():
    """0x8250 is the CiA 301 layer's RPDO timeout (not in the 402 catalogue, docs/cia402.md)."""
    for row in FAULT_KINDS.values():
        for code in row.emcy:
            assert code in FAULTS or code == 0x8250, (row.name, hex(code))


def test_every_kind_has_a_class_detection_and_recovery():
    for row in FAULT_KINDS.values():
        assert row.recovery_class and row.detection and row.recovery, row.name
    undetected = [k for k, row in FAULT_KINDS.items() if not row.detectable]
    assert undetected == ["backlash"]


def test_a_row_whose_handlers_do_not_fit_its_target_is_refused_by_name():
    bad = replace(FAULT_KINDS["blocked"], name="jammed", off_plant=None)
    with pytest.raises(ValueError, match="fault kind 'jammed': a drive fault has on_plant"):
        _checked((*_KINDS, bad))
    with pytest.raises(ValueError, match="'blocked' is listed twice"):
        _checked((*_KINDS, FAULT_KINDS["blocked"]))


def test_the_rest_list_is_json_numbers_only():
    noise = next(r for r in fault_types() if r["type"] == "encoder_noise")
    assert noise["target"] == "drive:<AXIS>" and noise["emcy"] == ["0x7305"]
    assert noise["error_register"] == FAULTS[0x7305].register
    assert noise["params"] == [
        {"name": "counts", "unit": "increments", "default": 32768.0, "min": 0.0, "max": 2.0**20}
    ]
    load = next(r for r in fault_types() if r["type"] == "load_force")
    assert all(v is None or math.isfinite(v) for p in load["params"] for v in (p["min"], p["max"]))


@pytest.mark.parametrize("doc", fault_docgen.DOCS)
def test_the_docs_fault_tables_are_the_registry(doc):
    text = (ROOT / doc).read_text(encoding="utf-8")
    assert fault_docgen.generated_sections(text), f"{doc} has no generated fault table"
    assert fault_docgen.sync_docs(text) == text, (
        f"{doc} differs from drives/fault_registry.py: run python -m drives.fault_docgen"
    )


def test_the_doc_generator_notices_a_stale_table():
    text = (ROOT / "docs/drives.md").read_text(encoding="utf-8")
    stale = text.replace("| `encoder_noise` |", "| `encoder_hum` |")
    assert stale != text and fault_docgen.sync_docs(stale) == text


def test_drive_inject_checks_the_parameters_like_every_other_face():
    d = Drive402()
    with pytest.raises(ValueError, match="counts = -5 outside 0..1048576 increments"):
        d.inject("encoder_noise", counts=-5)
    with pytest.raises(ValueError, match="unknown fault kind 'hum'; known: load_force"):
        d.inject("hum")
    with pytest.raises(ValueError, match="parameter volts .V. is required"):
        d.inject("mains_voltage")
    assert set(DRIVE_FAULTS) == set(INJECT_KINDS)


# ----------------------------------------------------------------------- encoder_noise
def test_noise_is_on_the_reading_bounded_repeatable_and_leaves_the_position():
    def readings(amplitude: float) -> list[int]:
        p = Plant()
        p.set_encoder_noise(amplitude)
        out = []
        for _ in range(400):
            p.step(125e-6, 0)  # power stage off: the table stands
            out.append(p.counts)
        p.set_encoder_noise(0.0)
        p.step(125e-6, 0)
        assert p.counts == 0  # the count did not drift: the position is not lost
        return out

    noisy = readings(1000.0)
    assert noisy == readings(1000.0)  # the same noise on every run (lockstep tests)
    assert max(abs(c) for c in noisy) <= 1000
    assert max(noisy) > 800 and min(noisy) < -800  # spread over the whole band
    assert len(set(noisy)) > 300


def _enabled_csp() -> Drive402:
    d = Drive402(objects={0x6060: 8})
    d.advance(T)
    for cw in (0x06, 0x07, 0x0F):
        d.write_object(0x6040, 0, cw)
        d.on_sync()
        d.advance(T)
    assert d.state == State.OPERATION_ENABLED
    return d


def test_large_noise_trips_the_encoder_plausibility_check_and_blocks_the_reset():
    d = _enabled_csp()
    d.inject("encoder_noise")  # 32 768 counts: twice the plausibility step at 8 kHz
    d.on_sync()
    d.advance(T)
    assert d.state == State.FAULT and d.error_code == 0x7305
    emcy = d.take_emcy()
    assert [(e.error_code, e.error_register) for e in emcy][-1] == (0x7305, 0x21)
    d.write_object(0x6040, 0, 0x80)  # fault reset while the noise is there: refused
    d.advance(T)
    assert d.state == State.FAULT
    d.clear_injection("encoder_noise")
    d.write_object(0x6040, 0, 0x00)
    d.advance(T)
    d.write_object(0x6040, 0, 0x80)
    d.advance(T)
    assert d.state == State.SWITCH_ON_DISABLED and d.error_code == 0


def test_small_noise_is_not_seen_by_the_drive():
    """15 µm of noise: no two readings differ by more than a moving axis can."""
    d = _enabled_csp()
    d.inject("encoder_noise", counts=1500)
    for _ in range(500):  # one second at a standstill
        d.on_sync()
        d.advance(T)
    assert d.state == State.OPERATION_ENABLED and d.error_code == 0
    assert d.plant.i2t > 0.0  # but the velocity loop chases it: current ripple
