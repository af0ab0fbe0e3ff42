"""Lepton telemetry: split frames into image and telemetry rows, decode the rows.

Pure functions over ``uint16`` words, tested on rows built byte for byte from the layout.

Layout of the Lepton 3 / 3.5 (FLIR Lepton Engineering Datasheet 500-0659-00-09 and Software
Interface Description Document (IDD) 110-0144-04, "Telemetry" section, rows A, B and C of 80
words each; the same offsets are used by GroupGets' PureThermal firmware ``lepton.h``
(``telemetry_data_l3``) and the periph.io / Cacophony ``lepton3`` drivers). Only the fields
below are decoded; the Lepton 2 layout (housing temperature in words 25-26 and 32) is not.

Row A (words 0-79)

=======  ====================================================================
word     content
=======  ====================================================================
0        telemetry revision
1-2      time counter, ms since power-on (32 bits)
3-4      status bits (32 bits): bit 3 FFC desired; bits 4-5 FFC state (0 never
         commanded, 1 imminent, 2 in progress, 3 complete); bit 12 AGC on;
         bit 15 shutter lockout; bit 20 over-temperature shutdown imminent
5-12     reserved on the Lepton 3 (module serial number on the Lepton 2)
13-16    software revision (64 bits)
20-21    frame counter (32 bits)
22       frame mean (counts)
23       FPA temperature, counts
24       FPA temperature, kelvin x 100 (the paper's "VOx temperature")
25-28    reserved on the Lepton 3 (housing temperature on the Lepton 2):
         ``housing_temp_k`` is NaN
29       FPA temperature at the last FFC, kelvin x 100
30-31    time counter at the last FFC, ms (32 bits)
=======  ====================================================================

FFC state (status bits 4-5) is decoded as the datasheet's Table 3 gives it (0 never commanded,
1 imminent, 2 in progress, 3 complete), whatever the telemetry revision in word 0. The periph.io
driver decodes it differently when word 0 is 8 (1 in progress, 2 complete); the Cacophony
Lepton 3 driver, like this module, does not. A camera that used periph.io's encoding would
show every frame as "in progress" between FFCs: check ``in_ffc`` on a first recording.

Row C (words 160-239 of the telemetry block): word 48 TLinear enable state (Lepton 2.5 / 3.5),
word 49 TLinear resolution (0: 0.1 K per count, 1: 0.01 K per count). With TLinear on, the
image holds kelvin x 100 (or x 10), not raw counts: the frame's telemetry says so, and the
radiometry reads it as the camera's own temperature
(:func:`~thermodepth.frames.thermal_output`).

Word order of 32-bit fields: two consecutive words, **least significant word first** (word n
holds bits 0-15, word n + 1 bits 16-31), as the IDD's telemetry tables list them and as the
periph.io driver reads them ("big-endian 16-bit words, little-endian word order").
Within a word, PureThermal's Y16 UVC stream delivers the value in host byte order (the frame
is read as ``uint16`` like the image), so this module works on word *values*.

Where the rows sit: on a Lepton 3 / 3.5 (160x120) with telemetry enabled each frame has 122
rows of 160 words; the 240 telemetry words (rows A, B, C) plus 80 reserved fill two rows: row
A | row B, then row C | reserved. On a Lepton 2.x (80x60: 2.0, 2.5) each telemetry row is an
image row of its own: 63 rows of 80 words. The Lepton puts them first (``header``) or last
(``footer``, the location PureThermal firmware configures and the default here). A frame of
the image's size alone has no telemetry (telemetry disabled).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from ..frames import FfcState, Telemetry

ROW_WORDS = 80
"""Words per telemetry row (A, B, C)."""
IMAGE_SHAPE = (120, 160)
"""Lepton 3 image, rows x columns."""
FRAME_SHAPE = (122, 160)
"""Lepton 3 frame with telemetry rows, as PureThermal delivers it over UVC Y16."""
TELEMETRY_ROWS = {160: 2, 80: 3}
"""Telemetry rows a frame carries, by image width: the Lepton 3's 160 (2), the Lepton 2's 80
(rows A, B and C, one each)."""
IMAGE_SHAPES = {160: (120, 160), 80: (60, 80)}
"""The Lepton images by width: Lepton 3 / 3.5 / 3.1R, Lepton 2.0 / 2.5."""
FRAME_SHAPES = (
    (122, 160),
    (120, 160),
    (63, 80),
    (60, 80),
)
"""Every Y16 frame a PureThermal delivers: each image with its telemetry rows, and alone."""

TelemetryLocation = Literal["footer", "header"]

# row A word offsets (IDD), the fields decoded
W_TIME_COUNTER = 1  # 32 bits, LSW first
W_STATUS = 3  # 32 bits, LSW first
W_FRAME_COUNTER = 20  # 32 bits, LSW first
W_FPA_TEMP_CK = 24
W_TIME_FFC = 30  # 32 bits, LSW first
# row C word offsets (IDD), relative to the start of row C
W_TLINEAR_ENABLE = 48
W_TLINEAR_RESOLUTION = 49
ROW_C_START = 2 * ROW_WORDS

# status bits (IDD, row A words 3-4)
STATUS_FFC_DESIRED = 1 << 3
STATUS_FFC_STATE_SHIFT = 4
STATUS_FFC_STATE_MASK = 0b11 << STATUS_FFC_STATE_SHIFT

TLINEAR_RESOLUTION_K = {0: 0.1, 1: 0.01}
"""Row C word 49 -> kelvin per TLinear count (IDD: LEP_RAD_RESOLUTION_0_1 = 0, _0_01 = 1)."""

FPA_TEMP_RANGE_K = (173.15, 423.15)
"""Plausible FPA temperatures (-100 .. 150 C; the Lepton operates at -10 .. 80 C): a value
outside means the words are not telemetry (telemetry off, wrong rows, corrupt frame)."""


class TelemetryError(InputError):
    """Telemetry words that cannot be a Lepton's (the message says which field and why)."""


def word32(words: NDArray[np.uint16], offset: int) -> int:
    """The 32-bit value at ``offset``: least significant word first (IDD word order)."""
    return int(words[offset]) | (int(words[offset + 1]) << 16)


def centikelvin_to_k(value: int) -> float:
    """Telemetry temperature word (kelvin x 100) -> kelvin (edge conversion)."""
    return value / 100.0


def parse_telemetry(row_words: NDArray[np.uint16]) -> Telemetry:
    """Decode Lepton telemetry words into :class:`~thermodepth.frames.Telemetry` (SI units).

    row_words: uint16 word values, at least row A (80 words); with rows B and C (240 words or
    more: the 320 of a Lepton 3 frame, the 240 of a Lepton 2's, :func:`split_frame`) the
    TLinear state and resolution are read from row C.
    Raises :class:`TelemetryError` when the words cannot be telemetry: fewer than 80 words,
    an all-zero row A (telemetry disabled) or an FPA temperature outside
    :data:`FPA_TEMP_RANGE_K`. The housing temperature is NaN (reserved on the Lepton 3); the
    time since FFC is None when unknown (no FFC yet, or a last-FFC time after the current
    time).
    """
    words = np.asarray(row_words)
    if words.ndim != 1 or words.size < ROW_WORDS:
        raise TelemetryError(
            f"telemetry: expected at least {ROW_WORDS} words (row A), got shape {words.shape}"
        )
    if words.dtype != np.uint16:
        if not np.issubdtype(words.dtype, np.integer) or words.min() < 0 or words.max() > 0xFFFF:
            raise TelemetryError(f"telemetry: expected uint16 words, got {words.dtype}")
        words = words.astype(np.uint16)
    row_a = words[:ROW_WORDS]
    if not row_a.any():
        raise TelemetryError(
            "telemetry: row A is all zeros (is telemetry enabled? expected 160x122 or 80x63 frames)"
        )
    fpa_ck = int(row_a[W_FPA_TEMP_CK])
    fpa_k = centikelvin_to_k(fpa_ck)
    lo, hi = FPA_TEMP_RANGE_K
    if not lo <= fpa_k <= hi:
        raise TelemetryError(
            f"telemetry: FPA temperature {fpa_k:.2f} K (word {W_FPA_TEMP_CK} = {fpa_ck}) is "
            f"outside {lo}-{hi} K: not telemetry, or a corrupt frame"
        )
    status = word32(row_a, W_STATUS)
    state = FfcState((status & STATUS_FFC_STATE_MASK) >> STATUS_FFC_STATE_SHIFT)
    now_ms = word32(row_a, W_TIME_COUNTER)
    ffc_ms = word32(row_a, W_TIME_FFC)
    since: float | None = None
    if state != FfcState.NEVER_COMMANDED and 0 < ffc_ms <= now_ms:
        since = (now_ms - ffc_ms) / 1000.0
    tlinear = False
    resolution: float | None = None
    if words.size >= ROW_C_START + ROW_WORDS:
        row_c = words[ROW_C_START : ROW_C_START + ROW_WORDS]
        tlinear = int(row_c[W_TLINEAR_ENABLE]) == 1
        resolution = TLINEAR_RESOLUTION_K.get(int(row_c[W_TLINEAR_RESOLUTION])) if tlinear else None
    return Telemetry(
        frame_counter=word32(row_a, W_FRAME_COUNTER),
        fpa_temp_k=fpa_k,
        housing_temp_k=float("nan"),  # reserved on the Lepton 3
        ffc_state=state,
        time_since_ffc_s=since,
        ffc_desired=bool(status & STATUS_FFC_DESIRED),
        tlinear=tlinear,
        tlinear_resolution_k=resolution,
    )


def split_frame(
    frame: NDArray[np.uint16], location: TelemetryLocation = "footer"
) -> tuple[NDArray[np.uint16], NDArray[np.uint16] | None]:
    """Split a Lepton frame into its image ((120, 160) or (60, 80)) and its telemetry words
    (320 or 240; None: a frame of the image alone, telemetry disabled).

    location: ``"footer"`` (the last rows; PureThermal's setting) or ``"header"`` (the first).
    Raises InputError naming the shapes expected, and the dtype, otherwise.
    """
    arr = np.asarray(frame)
    if arr.ndim != 2 or arr.shape not in FRAME_SHAPES:
        got = f"{arr.shape[1]}x{arr.shape[0]}" if arr.ndim == 2 else f"shape {arr.shape}"
        raise InputError(
            "Lepton frame: expected 160x122 or 80x63 Y16 (the image and its telemetry rows), "
            f"or the image alone (160x120, 80x60), got {got}"
        )
    if arr.dtype != np.uint16:
        raise InputError(f"Lepton frame: expected 16-bit Y16 pixels (uint16), got {arr.dtype}")
    image_rows = IMAGE_SHAPES[arr.shape[1]][0]
    if arr.shape[0] == image_rows:
        return arr, None
    if location == "footer":
        return arr[:image_rows], arr[image_rows:].reshape(-1)
    if location == "header":
        return arr[arr.shape[0] - image_rows :], arr[: arr.shape[0] - image_rows].reshape(-1)
    raise InputError(f"telemetry location: expected 'footer' or 'header', got {location!r}")
