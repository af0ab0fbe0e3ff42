"""A folder of images from any rig: ``rig.yaml`` and ``frames.csv`` naming the image files.

Layout (``thermodepth run --source folder:PATH`` reads it; :func:`write_folder` writes one)::

    PATH/rig.yaml      a calibration file; its thermal.output says what the thermal values are
    PATH/frames.csv    one row per pair: depth, thermal (file paths relative to PATH) and,
                       optionally, depth_time_s, thermal_time_s, fpa_temp_c, in_ffc, ir

Depth images: 16-bit PNG or TIFF, or ``.npy``, in the calibration's ``depth_scale_m`` units
(0 = no depth). Thermal images: 16-bit PNG or TIFF, or ``.npy``, of uint16 values of the kind
rig.yaml states, or float kelvin (``.npy``, 32-bit float TIFF), which are stored as the
camera's own temperature at 1/64 K. ``in_ffc``: 1 / true while the shutter is closed. ``ir``:
the depth camera's 8-bit infrared image (what ``capture-board`` finds the board in).

A row that cannot be read (a missing file, an image that is not one, a value that is not a
number) is one line naming the row and the file (:class:`RowError`); an image whose size
differs from rig.yaml's is an :class:`~thermodepth.errors.InputError` naming it.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration
from ..csvfile import CsvWriter
from ..errors import InputError, read_text
from ..frames import FfcState, FramePair, Telemetry, thermal_output
from ..radiometry import ZERO_C_IN_K, ThermalOutput

RIG_FILE = "rig.yaml"
FRAMES_FILE = "frames.csv"
REQUIRED = ("depth", "thermal")
OPTIONAL = ("depth_time_s", "thermal_time_s", "fpa_temp_c", "in_ffc", "ir")
FLOAT_KELVIN = ThermalOutput.kelvin_per(1 / 64)
"""How float kelvin thermal images are held: the camera's own temperature at 1/64 K (up to
1024 K, 751 C)."""
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".npy")


class RowError(InputError):
    """A row of frames.csv that cannot be read: the message names the row and the file."""


@dataclass(frozen=True)
class Row:
    """One row of frames.csv: its line, the files it names, and what it says."""

    line: int
    depth: Path
    thermal: Path
    depth_time_s: float | None
    thermal_time_s: float | None
    fpa_temp_c: float | None
    in_ffc: bool
    ir: Path | None = None


def read_rows(folder: Path) -> list[Row]:
    """frames.csv's rows; a missing file or column is an InputError naming it. Rows whose
    values cannot be read come back as they are: :func:`row_of` says which."""
    path = folder / FRAMES_FILE
    reader = csv.DictReader(io.StringIO(read_text(path, "utf-8-sig"), newline=""))
    header = [h.strip() for h in reader.fieldnames or []]
    missing = [c for c in REQUIRED if c not in header]
    if missing:
        raise InputError(
            f"{path}: missing column {', '.join(missing)} (found: {', '.join(header)})"
        )
    unknown = [h for h in header if h not in REQUIRED + OPTIONAL]
    if unknown:
        raise InputError(
            f"{path}: unknown column {', '.join(unknown)} (known: {', '.join(REQUIRED + OPTIONAL)})"
        )
    return [_row(folder, reader.line_num, {k.strip(): (v or "").strip() for k, v in r.items() if k})
            for r in reader]  # fmt: skip


def _row(folder: Path, line: int, cells: dict[str, str]) -> Row:
    def number(name: str) -> float | None:
        text = cells.get(name, "")
        if not text:
            return None
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        return value

    ffc = cells.get("in_ffc", "").lower()
    return Row(
        line,
        folder / cells.get("depth", ""),
        folder / cells.get("thermal", ""),
        number("depth_time_s"),
        number("thermal_time_s"),
        number("fpa_temp_c"),
        ffc in ("1", "true", "yes"),
        folder / cells["ir"] if cells.get("ir") else None,
    )


def check_row(row: Row, where: str) -> None:
    """A row whose values cannot be right: one RowError naming it (``where``: the file)."""
    for name in ("depth_time_s", "thermal_time_s", "fpa_temp_c"):
        value = getattr(row, name)
        if value is not None and not math.isfinite(value):
            raise RowError(f"{where}: line {row.line}: {name} is not a number")
    for name in (*REQUIRED, "ir"):
        path = getattr(row, name)
        if path is not None and path.suffix.lower() not in IMAGE_SUFFIXES:
            raise RowError(
                f"{where}: line {row.line}: {name} {path.name}: expected a "
                f"{', '.join(IMAGE_SUFFIXES)} file"
            )


def read_image(path: Path, where: str) -> NDArray[np.generic]:
    """An image file's array as stored (16-bit PNG/TIFF, any .npy); RowError when it cannot
    be read (naming ``where``, the row)."""
    if not path.is_file():
        raise RowError(f"{where}: {path}: no such file")
    if path.suffix.lower() == ".npy":
        try:
            image = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise RowError(f"{where}: {path}: not a .npy array ({exc})") from None
    else:
        loaded = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if loaded is None:
            raise RowError(f"{where}: {path}: not an image OpenCV can read")
        image = loaded
    if image.ndim != 2:
        raise RowError(f"{where}: {path}: expected one channel, got shape {image.shape}")
    return image


def depth_image(
    path: Path, where: str, shape: tuple[int, int], dtype: type[np.generic] = np.uint16
) -> NDArray[Any]:
    """A depth camera's image: its depth (uint16, in depth units) or, with ``dtype`` uint8,
    its infrared image; RowError for another dtype, InputError for another size."""
    image = read_image(path, where)
    if image.dtype != dtype:
        what = "depth" if dtype == np.uint16 else "the infrared image"
        bits = 8 * np.dtype(dtype).itemsize
        raise RowError(f"{where}: {path}: {what} must be {bits}-bit, got {image.dtype}")
    _check_size(image, shape, path, "depth")
    return image


def thermal_image(
    path: Path, where: str, shape: tuple[int, int]
) -> tuple[NDArray[np.uint16], bool]:
    """A thermal image as uint16 values, and whether it was float kelvin (then held at
    :data:`FLOAT_KELVIN`)."""
    image = read_image(path, where)
    _check_size(image, shape, path, "thermal")
    if image.dtype == np.uint16:
        return image.astype(np.uint16, copy=False), False
    if image.dtype.kind == "f":
        return kelvin_values(image), True
    raise RowError(
        f"{where}: {path}: thermal must be uint16 values or float kelvin, got {image.dtype}"
    )


def kelvin_values(kelvin: NDArray[Any]) -> NDArray[np.uint16]:
    """Float kelvin as held: uint16 at :data:`FLOAT_KELVIN` (NaN and beyond: 0 or the top)."""
    finite = np.where(np.isfinite(kelvin), kelvin, 0.0)
    return np.clip(np.rint(finite / FLOAT_KELVIN.scale_k), 0, 65535).astype(np.uint16)


def _check_size(image: NDArray[np.generic], shape: tuple[int, int], path: Path, what: str) -> None:
    if image.shape != shape:
        raise InputError(
            f"{path}: the {what} image is {image.shape[1]}x{image.shape[0]} but {RIG_FILE}'s "
            f"{what} camera is {shape[1]}x{shape[0]}"
        )


def telemetry_of(
    index: int, fpa_temp_c: float | None, in_ffc: bool, float_kelvin: bool
) -> Telemetry:
    """What an image source tells of a thermal frame (a folder's row, a bag's messages):
    its number, the FPA temperature (C; None or NaN: not told), the shutter, and a
    float-kelvin image's output (held at :data:`FLOAT_KELVIN`)."""
    return Telemetry(
        frame_counter=index,
        fpa_temp_k=math.nan if fpa_temp_c is None else fpa_temp_c + ZERO_C_IN_K,
        housing_temp_k=math.nan,
        ffc_state=FfcState.IN_PROGRESS if in_ffc else FfcState.COMPLETE,
        tlinear=float_kelvin,
        tlinear_resolution_k=FLOAT_KELVIN.scale_k if float_kelvin else None,
    )


def write_folder(out: str | Path, calibration: Calibration, pairs: Iterable[FramePair]) -> Path:
    """Write pairs as a folder :class:`~thermodepth.sources.folder.FolderSource` reads: 16-bit
    PNGs of depth and of the thermal values as they are, frames.csv with every column, and
    rig.yaml (``calibration``, its thermal.output that of the frames: a camera whose
    telemetry says its own temperature, Lepton TLinear or a P2 Pro, writes that)."""
    folder = Path(out)
    (folder / "depth").mkdir(parents=True, exist_ok=True)
    (folder / "thermal").mkdir(exist_ok=True)
    output = calibration.thermal_output
    with (folder / FRAMES_FILE).open("w", newline="", encoding="utf-8") as fh:
        table = CsvWriter(fh, (*REQUIRED, *OPTIONAL))
        table.header()
        for pair in pairs:
            name = f"{pair.index:06d}.png"
            cv2.imwrite(str(folder / "depth" / name), pair.depth)
            cv2.imwrite(str(folder / "thermal" / name), pair.thermal)
            if pair.ir is not None:
                (folder / "ir").mkdir(exist_ok=True)
                cv2.imwrite(str(folder / "ir" / name), pair.ir)
            output = thermal_output(pair.telemetry, calibration.thermal_output)
            fpa = pair.telemetry.fpa_temp_c
            table.row(
                {
                    "depth": f"depth/{name}",
                    "thermal": f"thermal/{name}",
                    "depth_time_s": repr(pair.depth_time_s),
                    "thermal_time_s": repr(pair.thermal_time_s),
                    "fpa_temp_c": "" if math.isnan(fpa) else repr(fpa),
                    "in_ffc": int(pair.telemetry.in_ffc),
                    "ir": "" if pair.ir is None else f"ir/{name}",
                }
            )
    rig = Calibration(
        calibration.depth,
        calibration.thermal,
        calibration.depth_scale_m,
        calibration.thermal_from_depth,
        output,
    )
    rig.save(folder / RIG_FILE)
    return folder
