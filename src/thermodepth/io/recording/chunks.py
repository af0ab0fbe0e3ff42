"""Reading image frames chunk by chunk, without zarr's per-call work.

An image array holds one frame per chunk (:func:`~.format.create_array`). Read through zarr,
each call goes through its event loop, a thread per codec and a copy out of the chunk buffer:
measured on a replay, a pair took 4.0-4.3 ms of CPU to read that way and 2.9 ms from the chunk
files, of which blosc decoding the 1280x720 depth frame is 1.6 ms (docs/recording.md,
"Replay"). For an array on a local disk stored as we write it (one frame per chunk, bytes
little endian -> Blosc -> CRC-32C, no sharding), :class:`FrameChunks` reads the chunk's file,
checks its CRC-32C and has blosc decode it straight into the frame, holding no lock: several
threads decode frames at once. Any other array (a remote store, other codecs) is read
through zarr.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import google_crc32c
import numpy as np
import zarr
from numcodecs import blosc
from numpy.typing import NDArray
from zarr.codecs import BloscCodec, BytesCodec, Crc32cCodec
from zarr.storage import LocalStore

_BLOSC_HEADER = 16  # bytes: version, flags, type size, then nbytes (uint32 LE) at offset 4


class ChunkError(ValueError):
    """A chunk file that is not a whole, valid chunk of its array."""


class FrameChunks:
    """The frames of one image array (N, H, W), read ``rows(first, last)`` at a time."""

    def __init__(self, array: zarr.Array) -> None:
        self.array = array
        self.frame_shape: tuple[int, ...] = tuple(array.shape[1:])
        self.dtype = np.dtype(array.dtype)
        self._dir = _direct_dir(array)

    @property
    def direct(self) -> bool:
        """True when frames are read from the chunk files directly (else through zarr)."""
        return self._dir is not None

    def rows(self, first: int, last: int) -> list[NDArray[Any]]:
        """Frames ``first`` to ``last`` (inclusive), each an array of its own: a frame kept
        (a clip's, a picture's) keeps only its own bytes, not its batch's (a view of one
        (n, H, W) block kept the block: 22 batches of 8 depth frames, 320 MB, held by one
        monitored rig's frames in flight, measured). A chunk file that is absent reads as the
        array's fill value, as zarr reads it; a corrupt one raises (ChunkError, or zarr's own
        error)."""
        if self._dir is None:
            block = np.asarray(self.array[first : last + 1])
            return [frame.copy() for frame in block] if len(block) > 1 else list(block)
        out = [np.empty(self.frame_shape, self.dtype) for _ in range(last - first + 1)]
        for k, frame in enumerate(out):
            self._decode(self._dir, first + k, frame)
        return out

    def _decode(self, directory: Path, row: int, out: NDArray[Any]) -> None:
        meta = self.array.metadata
        path = directory / meta.encode_chunk_key((row,) + (0,) * len(self.frame_shape))
        try:
            data = np.frombuffer(path.read_bytes(), np.uint8)
        except FileNotFoundError:
            out[...] = meta.fill_value
            return
        if data.size < _BLOSC_HEADER + 4:
            raise ChunkError(f"{data.size} bytes, too short for a chunk")
        body, crc = data[:-4], int.from_bytes(data[-4:].tobytes(), "little")
        if google_crc32c.value(body) != crc:
            raise ChunkError("the chunk does not match its CRC-32C")
        size = int.from_bytes(body[4:8].tobytes(), "little")
        if size != out.nbytes:
            raise ChunkError(f"the chunk holds {size} bytes, a frame {out.nbytes}")
        blosc.decompress(body, out)


def _direct_dir(array: zarr.Array) -> Path | None:
    """The directory of a local array whose chunks :class:`FrameChunks` can decode itself (a
    frame per chunk, bytes -> Blosc -> CRC-32C), else None."""
    store = array.store_path.store
    meta = array.metadata
    codecs: tuple[Any, ...] = tuple(getattr(meta, "codecs", ()))  # none in Zarr v2 metadata
    if not isinstance(store, LocalStore) or len(codecs) != 3:
        return None
    raw, compressor, crc = codecs
    plain = isinstance(raw, BytesCodec) and (
        np.dtype(array.dtype).itemsize == 1 or (raw.endian and raw.endian.value == sys.byteorder)
    )
    if not (plain and isinstance(compressor, BloscCodec) and isinstance(crc, Crc32cCodec)):
        return None
    if tuple(array.chunks) != (1, *array.shape[1:]):
        return None
    return Path(store.root) / array.store_path.path
