"""Recordings: a Zarr v3 store appended frame by frame, crash-safe, replayed bit for bit.

Layout (docs/recording.md has the full description)::

    session.zarr/                 group; attributes: format, version, calibration, settings,
                                  device_depth, source, created_utc, complete, counts, ...
      depth/image   (N, H, W) uint16   one chunk per frame
      depth/ir      (N, H, W) uint8    optional, one chunk per frame
      depth/meta    (N, 3)    float64  time_s, index, crc32c -- written last: commit marker
      thermal/image (N, h, w) uint16   one chunk per frame
      thermal/meta  (N, 11)   float64  time_s, index, crc32c, telemetry (SI) -- commit marker
      pairs         (N, 3)    int64    depth row, thermal row, pair index (-1 = none)

Crash safety: a frame's image chunks are written before its meta row, and a pair row only
after both its frames; every chunk is a file, which zarr (>= 3.1.3, zarr-python PR 3412)
writes to a temporary file and renames into place, so a SIGKILL leaves each file either whole
(old or new content) or absent (a torn chunk from another writer would fail its checksums).
Image chunks hold one frame; meta and pair chunks hold :data:`TABLE_CHUNK_ROWS` rows, each
row write rewriting its chunk whole (so a recording opens reading a few hundred files, not one
per frame). A frame counts only when its meta row is there (not NaN) and its pixels match the
CRC-32C the row holds (version 1: zlib's CRC-32); arrays grow by doubling (their shape may
run ahead of the frames), and the true counts are found on open. So a killed recording loses
at most the frames in flight. A corrupt or missing image chunk costs its frame only, a
corrupt meta or pair chunk the rows it holds: each is skipped with one warning line and
counted.

Compression: Blosc (:data:`CODECS`: lz4 level 9 with bit shuffle unless asked for zstd) then
a CRC-32C checksum codec per chunk; recordings written with any Blosc codec read the same.
"""

from __future__ import annotations

import json
import os
import zlib
from pathlib import Path
from typing import Any

import google_crc32c
import numpy as np
import zarr
from numpy.typing import NDArray
from zarr.codecs import BloscCodec, Crc32cCodec

from ...errors import FieldError, InputError, ThermodepthError
from ...frames import FfcState, Telemetry

FORMAT = "thermodepth-recording"
VERSION = 2
"""The version recordings are written in. Version 2 stores the pixels' CRC-32C where version
1 stored zlib's CRC-32 (1.6-2.8x slower to check on a depth frame, measured); both are
read."""
VERSIONS = {1: "CRC-32", 2: "CRC-32C"}
"""The versions read, each with the name of the pixels' checksum it stores (:func:`checksum`)."""
DEPTH_META = ("time_s", "index", "crc32c")
THERMAL_META = (
    "time_s",
    "index",
    "crc32c",
    "frame_counter",
    "fpa_temp_k",
    "housing_temp_k",
    "ffc_state",
    "time_since_ffc_s",
    "ffc_desired",
    "tlinear",
    "tlinear_resolution_k",
)
PAIR_COLUMNS = ("depth_row", "thermal_row", "index")
DEPTH_FRAMES = ("all", "paired")
"""Which depth frames a recording keeps (attribute ``depth_frames``): every one the camera
gave (30 fps), or only those that pair with a thermal frame (8.7 fps: 3.4x fewer, all that a
replay measures). A recording without the attribute keeps all."""


FIRST_CAPACITY = 64
TABLE_CHUNK_ROWS = 256
"""Rows per chunk of the meta and pair tables (one file each): a row write rewrites its
chunk (at most 256 x 11 float64 = 22 KB), a corrupt chunk costs its rows."""


class RecordingWarning(UserWarning):
    """A frame of a recording was skipped (corrupt or missing chunk)."""


class CorruptFrameError(ThermodepthError):
    """A recorded frame whose chunks cannot be read or do not match their checksum.
    ``reported``: the cause was already warned about when the recording was opened (a table
    chunk missing or corrupt: one warning for all the rows it held)."""

    def __init__(self, message: str, reported: bool = False) -> None:
        super().__init__(message)
        self.reported = reported


CODECS = {
    "lz4": BloscCodec(cname="lz4", clevel=9, shuffle="bitshuffle"),
    "zstd": BloscCodec(cname="zstd", clevel=1, shuffle="shuffle"),
}
"""The image codecs a recording can be written with (``record --codec``), chosen by
measurement (docs/recording.md, "Depth codec"): Blosc lz4 level 9 with bit shuffle, the
default, and zstd level 1 with byte shuffle for archives where disk counts more than time.
On one thread, as the recorder encodes and a replay decodes, lz4 decodes a 1280x720 depth
frame in 0.5 ms where zstd takes 1.6-2.0 and encodes it in 0.9-1.3 ms where zstd takes
2.4-4.8; zstd stores 6-33 % less (ratio 2.65 against 2.48 on simulated depth, 3.14 against
2.11 on realistic depth)."""
DEFAULT_CODEC = "lz4"


def check_storage(depth_frames: str, codec: str) -> None:
    """FieldError (``depth_frames`` or ``codec``) for a way of storing that a recording does
    not offer (:data:`DEPTH_FRAMES`, :data:`CODECS`)."""
    for field, value, choices in (
        ("depth_frames", depth_frames, DEPTH_FRAMES),
        ("codec", codec, tuple(CODECS)),
    ):
        if value not in choices:
            raise FieldError(field, f"expected one of {', '.join(choices)}")


def compressors(codec: str = DEFAULT_CODEC) -> list[Any]:
    """The image arrays' codecs: ``codec`` (:data:`CODECS`), then a CRC-32C of the compressed
    chunk."""
    return [CODECS[codec], Crc32cCodec()]


def checksum(*arrays: NDArray[Any] | None, version: int = VERSION) -> int:
    """The checksum of the arrays' bytes in order (None skipped) that a recording of
    ``version`` stores: CRC-32C (2), zlib's CRC-32 (1)."""
    crc = 0
    for a in arrays:
        if a is not None:
            data = np.ascontiguousarray(a)
            if version == 1:
                crc = zlib.crc32(data.data, crc)
            else:
                crc = google_crc32c.extend(crc, data.reshape(-1).view(np.uint8))
    return crc


def telemetry_row(t: Telemetry) -> list[float]:
    """Telemetry as float64 columns (THERMAL_META[3:]); None -> NaN, exact for every value
    the Lepton reports (32-bit counters, centikelvin)."""
    nan = float("nan")
    return [
        float(t.frame_counter),
        t.fpa_temp_k,
        t.housing_temp_k,
        float(int(t.ffc_state)),
        nan if t.time_since_ffc_s is None else t.time_since_ffc_s,
        float(t.ffc_desired),
        float(t.tlinear),
        nan if t.tlinear_resolution_k is None else t.tlinear_resolution_k,
    ]


def telemetry_from_row(row: NDArray[np.float64]) -> Telemetry:
    """Inverse of :func:`telemetry_row`."""
    since, res = float(row[4]), float(row[7])
    return Telemetry(
        frame_counter=int(row[0]),
        fpa_temp_k=float(row[1]),
        housing_temp_k=float(row[2]),
        ffc_state=FfcState(int(row[3])),
        time_since_ffc_s=None if np.isnan(since) else since,
        ffc_desired=bool(row[5]),
        tlinear=bool(row[6]),
        tlinear_resolution_k=None if np.isnan(res) else res,
    )


def create_array(
    group: zarr.Group,
    name: str,
    frame_shape: tuple[int, ...],
    dtype: Any,
    fill: Any,
    codec: str = DEFAULT_CODEC,
) -> zarr.Array:
    """An array growing along time: images (2-D frames) one frame per chunk compressed with
    ``codec``, table rows (1-D) :data:`TABLE_CHUNK_ROWS` per chunk, uncompressed; CRC-32C on
    every chunk."""
    image = len(frame_shape) == 2
    return group.create_array(
        name,
        shape=(FIRST_CAPACITY, *frame_shape),
        chunks=(1 if image else TABLE_CHUNK_ROWS, *frame_shape),
        dtype=dtype,
        fill_value=fill,
        compressors=compressors(codec) if image else [Crc32cCodec()],
    )


def grow(arrays: list[zarr.Array], row: int) -> None:
    """Double the time extent of ``arrays`` (one ``zarr.json`` rewrite each) if ``row`` is
    past it."""
    capacity = arrays[-1].shape[0]
    if row >= capacity:
        for a in arrays:
            a.resize((capacity * 2, *a.shape[1:]))


def is_recording(path: str | Path) -> bool:
    """True when ``path`` is a thermodepth recording: a directory whose ``zarr.json`` is a
    group carrying our format marker (read as plain JSON; nothing is opened for writing)."""
    meta = Path(path) / "zarr.json"
    try:
        data = json.loads(meta.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    attrs = data.get("attributes") if isinstance(data, dict) else None
    return isinstance(attrs, dict) and attrs.get("format") == FORMAT


def check_output(path: str | Path, overwrite: bool = False, inputs: tuple[Path, ...] = ()) -> Path:
    """Where a new recording may be written, or a one-line InputError: the path must not be
    (inside) one of ``inputs`` (the files a source reads) nor contain one; it must not exist,
    unless ``overwrite`` and it is a thermodepth recording (:func:`is_recording`) -- any
    other file or directory is never deleted."""
    out = Path(path)
    target = out.resolve()
    for inp in inputs:
        src = Path(inp).resolve()
        if target == src or src.is_relative_to(target) or target.is_relative_to(src):
            raise InputError(f"{out}: the source reads {inp}; write the recording somewhere else")
    if out.exists() or out.is_symlink():
        if not overwrite:
            raise InputError(
                f"{out}: already exists (choose another output, or --overwrite to replace a "
                "recording)"
            )
        if not is_recording(out):
            raise InputError(
                f"{out}: not a thermodepth recording; --overwrite replaces recordings only "
                "(nothing was deleted)"
            )
    return out


def is_url(path: str | Path) -> bool:
    """True for an fsspec URL (``file:///data/a.zarr``, ``s3://bucket/a.zarr``), False for a
    local path."""
    return isinstance(path, str) and "://" in path


def short_error(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


def store_size_bytes(path: str | Path) -> int:
    """Bytes on disk of a recording directory."""
    total = 0
    for root, _dirs, files in os.walk(path):
        for f in files:
            total += os.path.getsize(os.path.join(root, f))
    return total
