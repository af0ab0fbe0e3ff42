"""Depth codecs for recordings: what each lossless Blosc choice stores and costs.

Two kinds of 1280x720 Z16 frames: the simulator's (the plate scene at 1 m: per-pixel
independent noise at the D435's RMS, the stereo shadow) and a realistic variant of the same
scene (the noise correlated over the stereo matcher's 7x7 window, depth quantised through
1/32-pixel disparity steps, 6 % of the pixels in invalid holes, as a D435 gives on real
surfaces). For each codec: compression ratio, MB per frame, MB/s on disk at 30 fps (all depth
frames) and 8.7 fps (``--depth paired``), encode and decode ms on one thread (medians; blosc
decodes without its own threads off the main thread, which is where the recorder encodes and
a replay decodes). Every codec is checked to give the frame back bit for bit. Row delta:
numcodecs' Delta over the frame's pixels in row order (each pixel minus its left neighbour;
the first of a row minus the last of the row above).
"""

from __future__ import annotations

import numpy as np
from numcodecs import Blosc, Delta, blosc
from numpy.typing import NDArray
from rich.console import Console
from rich.table import Table
from scipy.ndimage import uniform_filter

from thermodepth.sim import Rig, camera_pose, plate_scene

from .common import measure

FX, BASELINE_M, SUBPIXEL = 640.0, 0.050, 0.08  # reference-values.md: D435


def realistic(depth: NDArray[np.uint16], rng: np.random.Generator) -> NDArray[np.uint16]:
    """The frame's depth with stereo-like noise, disparity quantisation and holes."""
    valid = depth > 0
    z_m = np.where(valid, depth / 1000.0, 1.0)
    noise = uniform_filter(rng.standard_normal(depth.shape), 7) * 7  # unit SD, correlated
    disparity = np.round((FX * BASELINE_M / z_m + SUBPIXEL * noise) * 32) / 32
    out = np.where(valid & (disparity > 0), FX * BASELINE_M / np.maximum(disparity, 1e-6), 0)
    out[uniform_filter(rng.random(depth.shape), 15) < 0.47] = 0  # blobs ~ 6 % of pixels
    return np.clip(np.round(out * 1000), 0, 65535).astype(np.uint16)


def codecs() -> list[tuple[str, Blosc, bool]]:
    out = []
    for cname, levels in (("zstd", (1, 3, 5)), ("lz4", (1, 5, 9))):
        for level in levels:
            for shuffle, sname in ((Blosc.SHUFFLE, "byte"), (Blosc.BITSHUFFLE, "bit")):
                for delta in (False, True) if cname == "zstd" else (False,):
                    name = f"{cname}-{level} {sname}-shuffle" + (" + row delta" if delta else "")
                    out.append((name, Blosc(cname=cname, clevel=level, shuffle=shuffle), delta))
    return out


def main() -> None:
    blosc.use_threads = False  # one thread, as off the main thread
    rig = Rig(plate_scene(chip_temp_c=70.0), camera_pose(1.0))
    sim = rig.frame().depth
    kinds = {"simulated": sim, "realistic": realistic(sim, np.random.default_rng(0))}
    delta = Delta(dtype="<u2")
    table = Table(title="depth codecs (1280x720 Z16, lossless)")
    for col in ("depth", "codec", "ratio", "MB/frame", "MB/s 30 fps", "MB/s 8.7 fps",
                "encode ms", "decode ms"):  # fmt: skip
        table.add_column(col, justify="left" if col in ("depth", "codec") else "right")
    for kind, frame in kinds.items():
        for name, codec, with_delta in codecs():

            def encode(c: Blosc = codec, d: bool = with_delta, f: NDArray = frame) -> bytes:  # type: ignore[type-arg]
                return bytes(c.encode(delta.encode(f) if d else f))

            def decode(blob: bytes, c: Blosc = codec, d: bool = with_delta) -> NDArray:  # type: ignore[type-arg]
                raw = np.frombuffer(c.decode(blob), np.uint16)
                return np.asarray(delta.decode(raw) if d else raw)

            blob = encode()
            assert np.array_equal(decode(blob).reshape(frame.shape), frame), name
            mb = len(blob) / 1e6
            enc = measure("encode", encode, n=15).median_ms
            dec = measure("decode", lambda b=blob, f=decode: f(b), n=15).median_ms
            ratio = frame.nbytes / len(blob)
            cells = (ratio, mb, 30 * mb, 8.7 * mb, enc, dec)
            table.add_row(kind, name, *(f"{x:.3f}" if x is mb else f"{x:.2f}" for x in cells))
        table.add_section()
    Console(width=140).print(table)  # the codec names whole
    blosc.use_threads = None
