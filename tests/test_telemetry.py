"""Lepton telemetry: rows built byte for byte from the IDD layout, round trips and fuzzing."""

from __future__ import annotations

import math
import re
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from thermodepth.errors import InputError
from thermodepth.frames import FfcState
from thermodepth.sources.telemetry import (
    TelemetryError,
    parse_telemetry,
    split_frame,
)


def telemetry_bytes(
    *,
    revision: int = 0x0E0E,
    time_ms: int = 123_456,
    ffc_desired: bool = False,
    ffc_state: int = 3,
    frame_counter: int = 42,
    frame_mean: int = 8100,
    fpa_ck: int = 30815,
    housing_ck: int = 30715,
    fpa_ffc_ck: int = 30800,
    time_ffc_ms: int = 100_000,
    tlinear: int = 0,
    tlinear_res: int = 1,
    extra_status: int = 0,
) -> bytes:
    """320 telemetry words as the bytes of a Y16 frame (little-endian uint16 on the wire of
    the UVC stream), laid out per the IDD: row A, row B, row C, reserved; 32-bit fields as
    two words, least significant word first."""
    status = extra_status | (int(ffc_desired) << 3) | ((ffc_state & 3) << 4)

    def u32(v: int) -> bytes:  # LSW first, each word little-endian bytes on the host
        return struct.pack("<HH", v & 0xFFFF, v >> 16)

    a = bytearray(160)
    a[0:2] = struct.pack("<H", revision)
    a[2:6] = u32(time_ms)
    a[6:10] = u32(status)
    a[10:26] = bytes(range(1, 17))  # serial number
    a[40:44] = u32(frame_counter)
    a[44:46] = struct.pack("<H", frame_mean)
    a[46:48] = struct.pack("<H", 3000)  # FPA counts
    a[48:50] = struct.pack("<H", fpa_ck)
    a[52:54] = struct.pack("<H", housing_ck)
    a[58:60] = struct.pack("<H", fpa_ffc_ck)
    a[60:64] = u32(time_ffc_ms)
    b = bytearray(160)
    c = bytearray(160)
    c[96:98] = struct.pack("<H", tlinear)
    c[98:100] = struct.pack("<H", tlinear_res)
    reserved = bytearray(160)
    out = bytes(a + b + c + reserved)
    assert len(out) == 640
    return out


def words_of(raw: bytes) -> np.ndarray:
    return np.frombuffer(raw, dtype="<u2").astype(np.uint16)


def test_parse_known_row() -> None:
    t = parse_telemetry(words_of(telemetry_bytes()))
    assert t.frame_counter == 42
    assert t.fpa_temp_k == pytest.approx(308.15)
    assert t.fpa_temp_c == pytest.approx(35.0)
    assert math.isnan(t.housing_temp_k)  # reserved on the Lepton 3
    assert t.ffc_state == FfcState.COMPLETE
    assert t.time_since_ffc_s == pytest.approx(23.456)
    assert not t.ffc_desired
    assert not t.tlinear and t.tlinear_resolution_k is None


def test_32_bit_fields_are_least_significant_word_first() -> None:
    # frame counter 0x00012345: word 20 = 0x2345, word 21 = 0x0001
    words = words_of(telemetry_bytes(frame_counter=0x00012345, time_ms=0x00030000))
    assert words[20] == 0x2345 and words[21] == 0x0001
    t = parse_telemetry(words)
    assert t.frame_counter == 0x12345
    assert t.time_since_ffc_s == pytest.approx((0x30000 - 100_000) / 1000)


@pytest.mark.parametrize("state", list(FfcState))
def test_ffc_state_bits_and_in_ffc(state: FfcState) -> None:
    t = parse_telemetry(words_of(telemetry_bytes(ffc_state=int(state), ffc_desired=True)))
    assert t.ffc_state == state
    assert t.ffc_desired
    assert t.in_ffc == (state == FfcState.IN_PROGRESS)


def test_other_status_bits_do_not_leak_into_ffc_fields() -> None:
    # AGC (bit 12), shutter lockout (15), over-temperature (20) set, FFC bits clear
    t = parse_telemetry(
        words_of(telemetry_bytes(ffc_state=0, extra_status=(1 << 12) | (1 << 15) | (1 << 20)))
    )
    assert t.ffc_state == FfcState.NEVER_COMMANDED and not t.ffc_desired
    assert t.time_since_ffc_s is None  # never commanded: no FFC time


@pytest.mark.parametrize(("res_word", "res_k"), [(0, 0.1), (1, 0.01), (7, None)])
def test_tlinear_from_row_c(res_word: int, res_k: float | None) -> None:
    t = parse_telemetry(words_of(telemetry_bytes(tlinear=1, tlinear_res=res_word)))
    assert t.tlinear
    assert t.tlinear_resolution_k == res_k


def test_row_a_alone_has_no_tlinear() -> None:
    t = parse_telemetry(words_of(telemetry_bytes(tlinear=1))[:80])
    assert not t.tlinear and t.frame_counter == 42


@pytest.mark.parametrize("housing_ck", [0, 30715, 65535])
def test_lepton3_reserved_words_25_to_28_are_not_a_housing_temperature(housing_ck: int) -> None:
    # words 25-28 are reserved on the Lepton 3 (PureThermal's telemetry_data_l3): whatever
    # they hold, the housing temperature is unknown
    words = words_of(telemetry_bytes(housing_ck=housing_ck))
    words[25:29] = [11, housing_ck, 13, 14]
    assert math.isnan(parse_telemetry(words).housing_temp_k)


def test_last_ffc_after_now_is_unknown() -> None:
    t = parse_telemetry(words_of(telemetry_bytes(time_ms=1000, time_ffc_ms=5000)))
    assert t.time_since_ffc_s is None


@pytest.mark.parametrize(
    ("words", "message"),
    [
        (np.zeros(320, np.uint16), "row A is all zeros (is telemetry enabled"),
        (np.zeros(79, np.uint16), "expected at least 80 words"),
        (words_of(telemetry_bytes(fpa_ck=100)), "FPA temperature 1.00 K (word 24 = 100)"),
        (words_of(telemetry_bytes(fpa_ck=65535)), "is outside 173.15-423.15 K"),
        (np.full(320, -1, np.int32), "expected uint16 words"),
    ],
)
def test_bad_telemetry_is_a_clear_error(words: np.ndarray, message: str) -> None:
    with pytest.raises(TelemetryError, match=re.escape(message)) as info:
        parse_telemetry(words)
    assert "\n" not in str(info.value)


@settings(max_examples=200, deadline=None)
@given(
    time_ms=st.integers(0, 2**32 - 1),
    frame_counter=st.integers(0, 2**32 - 1),
    fpa_ck=st.integers(17315, 42315),
    housing_ck=st.integers(1, 65535),
    state=st.sampled_from(list(FfcState)),
    desired=st.booleans(),
    time_ffc_ms=st.integers(1, 2**32 - 1),
    tlinear=st.integers(0, 1),
    res=st.integers(0, 1),
)
def test_round_trip(
    time_ms: int,
    frame_counter: int,
    fpa_ck: int,
    housing_ck: int,
    state: FfcState,
    desired: bool,
    time_ffc_ms: int,
    tlinear: int,
    res: int,
) -> None:
    raw = telemetry_bytes(
        time_ms=time_ms,
        frame_counter=frame_counter,
        fpa_ck=fpa_ck,
        housing_ck=housing_ck,
        ffc_state=int(state),
        ffc_desired=desired,
        time_ffc_ms=time_ffc_ms,
        tlinear=tlinear,
        tlinear_res=res,
    )
    t = parse_telemetry(words_of(raw))
    assert t.frame_counter == frame_counter
    assert round(t.fpa_temp_k * 100) == fpa_ck
    assert math.isnan(t.housing_temp_k)
    assert t.ffc_state == state and t.ffc_desired == desired
    if state != FfcState.NEVER_COMMANDED and time_ffc_ms <= time_ms:
        assert t.time_since_ffc_s == pytest.approx((time_ms - time_ffc_ms) / 1000)
    else:
        assert t.time_since_ffc_s is None
    assert t.tlinear == bool(tlinear)
    assert t.tlinear_resolution_k == ((0.1, 0.01)[res] if tlinear else None)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.integers(0, 0xFFFF), min_size=0, max_size=400))
def test_fuzz_arbitrary_words_never_crash(values: list[int]) -> None:
    words = np.asarray(values, dtype=np.uint16)
    try:
        t = parse_telemetry(words)
    except TelemetryError as exc:
        assert str(exc).startswith("telemetry: ")
        return
    lo, hi = 173.15, 423.15
    assert lo <= t.fpa_temp_k <= hi
    assert isinstance(t.ffc_state, FfcState)
    assert t.time_since_ffc_s is None or t.time_since_ffc_s >= 0
    assert 0 <= t.frame_counter < 2**32


@pytest.mark.parametrize("location", ["footer", "header"])
@pytest.mark.parametrize("width", [160, 80])
def test_split_frame(location: str, width: int) -> None:
    # a Lepton 3's frame carries its 320 telemetry words in two rows of 160, a Lepton 2.x's
    # its rows A, B and C in three rows of 80
    h = 120 if width == 160 else 60
    image = np.arange(h * width, dtype=np.uint16).reshape(h, width)
    words = words_of(telemetry_bytes(tlinear=1, tlinear_res=1))[: 240 if width == 80 else 320]
    telem = words.reshape(-1, width)
    frame = np.vstack([image, telem] if location == "footer" else [telem, image])
    img, got = split_frame(frame, location)  # type: ignore[arg-type]
    assert np.array_equal(img, image)
    assert got is not None
    t = parse_telemetry(got)
    assert t.frame_counter == 42 and t.tlinear and t.tlinear_resolution_k == 0.01


@pytest.mark.parametrize("shape", [(120, 160), (60, 80)])
def test_a_frame_of_the_image_alone_has_no_telemetry(shape: tuple[int, int]) -> None:
    image = np.ones(shape, np.uint16)
    img, words = split_frame(image)
    assert img is image and words is None


@pytest.mark.parametrize(
    ("frame", "message"),
    [
        (
            np.zeros((121, 160), np.uint16),
            "expected 160x122 or 80x63 Y16 (the image and its telemetry rows), or the image "
            "alone (160x120, 80x60), got 160x121",
        ),
        (np.zeros((122, 160, 3), np.uint8), "got shape (122, 160, 3)"),
        (np.zeros((122, 160), np.uint8), "expected 16-bit Y16 pixels (uint16), got uint8"),
    ],
)
def test_split_frame_wrong_format(frame: np.ndarray, message: str) -> None:
    with pytest.raises(InputError, match=re.escape(message)):
        split_frame(frame)
