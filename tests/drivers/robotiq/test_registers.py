"""The register maths against the manual's own example frames and the spec's ranges."""

from __future__ import annotations

import pytest

from drivers.robotiq_gripper.registers import (
    ActionRequest,
    Calibration,
    GripperStatus,
    decode_request,
    decode_status,
    encode_request,
    encode_status,
    fault_text,
    force_count,
    speed_count,
)


def test_manual_example_frames() -> None:
    # "Close with full speed and force": 09 10 03 E8 00 03 06 | 09 00 | 00 FF | FF FF
    req = ActionRequest(act=True, gto=True, position=255, speed=255, force=255)
    assert encode_request(req) == [0x0900, 0x00FF, 0xFFFF]
    assert decode_request([0x0900, 0x00FF, 0xFFFF]) == req
    # Activation request: all zeros, then rACT
    assert encode_request(ActionRequest(act=False)) == [0, 0, 0]
    assert encode_request(ActionRequest(act=True)) == [0x0100, 0, 0]
    # Status after opening (manual): F9 00 | 00 00 | 0D 00 -> gACT 1, gGTO 1, gSTA 3, gOBJ 3
    st = decode_status([0xF900, 0x0000, 0x0D00])
    assert (st.act, st.gto, st.sta, st.obj, st.flt, st.pr, st.po, st.cu) == (1, 1, 3, 3, 0, 0,
                                                                            13, 0)
    assert st.activated
    # Closing on an object: B9 -> gOBJ 2; fault byte 0x08 -> gFLT 8
    st = decode_status([0xB900, 0x08FF, 0xBD10])
    assert (st.obj, st.flt, st.pr, st.po, st.cu) == (2, 8, 255, 0xBD, 0x10)


def test_status_round_trip() -> None:
    st = GripperStatus(act=1, gto=1, sta=3, obj=1, flt=0xE, kflt=2, pr=77, po=80, cu=9)
    assert decode_status(encode_status(st)) == st


def test_calibration_maps_counts_to_widths() -> None:
    cal = Calibration(open_count=4, closed_count=227)
    assert cal.width(4) == pytest.approx(0.085)
    assert cal.width(227) == 0.0
    assert cal.width(0) == pytest.approx(0.085)  # clipped
    assert cal.width(255) == 0.0
    assert cal.count(0.085) == 0 and cal.count(1.0) == 0  # full opening asks for the limit
    assert cal.count(0.0) == 255  # full closing too
    half_count = 0.5 * 0.085 / 223 + 1e-9
    for width in (0.010, 0.030, 0.0425, 0.080):
        assert cal.width(cal.count(width)) == pytest.approx(width, abs=half_count)
    with pytest.raises(ValueError):
        Calibration(200, 100)


def test_speed_and_force_scaling() -> None:
    assert speed_count(0.020) == 0 and speed_count(0.150) == 255
    assert speed_count(0.0) == 0 and speed_count(1.0) == 255  # clipped to the gripper's range
    assert speed_count(0.085) == 128  # midpoint
    assert force_count(20.0) == 0 and force_count(235.0) == 255
    assert force_count(-5.0) == 0 and force_count(1000.0) == 255
    assert force_count(127.5) == 128


def test_fault_codes_read_as_text() -> None:
    assert fault_text(0) is None
    assert "temperature" in fault_text(0x08)
    assert fault_text(0x07).startswith("fault 0x07: the activation bit")
    assert "overcurrent" in fault_text(0x0E)
    assert "unknown" in fault_text(0x03)
