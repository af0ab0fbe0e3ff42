"""Recordings: a Zarr v3 store appended frame by frame, crash-safe, replayed bit for bit.

:mod:`.format` holds the layout (arrays, tables, codecs, checksums; docs/recording.md),
:mod:`.writer` appends (:class:`RecordingWriter`) and records in the background
(:class:`Recorder`), :mod:`.reader` replays (:class:`Recording`), reading image frames
through :mod:`.chunks`.
"""

from .format import (
    CODECS,
    DEFAULT_CODEC,
    DEPTH_FRAMES,
    FORMAT,
    TABLE_CHUNK_ROWS,
    VERSION,
    CorruptFrameError,
    RecordingWarning,
    check_output,
    check_storage,
    checksum,
    compressors,
    is_recording,
    store_size_bytes,
    telemetry_from_row,
    telemetry_row,
)
from .reader import Recording
from .writer import Recorder, RecorderStats, RecordingWriter

__all__ = [
    "CODECS",
    "DEFAULT_CODEC",
    "DEPTH_FRAMES",
    "FORMAT",
    "TABLE_CHUNK_ROWS",
    "VERSION",
    "CorruptFrameError",
    "Recorder",
    "RecorderStats",
    "Recording",
    "RecordingWarning",
    "RecordingWriter",
    "check_output",
    "check_storage",
    "checksum",
    "compressors",
    "is_recording",
    "store_size_bytes",
    "telemetry_from_row",
    "telemetry_row",
]
