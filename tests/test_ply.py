"""Our PLY reader and writer (thermodepth.io.ply): property round trips of any elements, any
header or cut-short file as one line, and the files read by trimesh's own PLY loader."""

from __future__ import annotations

import itertools
import re
import string
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from thermodepth.errors import InputError
from thermodepth.io.ply import TYPES, read_ply, write_ply
from thermodepth.io.pointcloud import read_ply as read_cloud
from thermodepth.io.pointcloud import write_ply as write_cloud

_DIR = tempfile.TemporaryDirectory(prefix="test-ply-")  # removed when the run ends
_files = itertools.count()


def _path() -> Path:
    return Path(_DIR.name) / f"f{next(_files)}.ply"


names = st.text(string.ascii_letters + "_", min_size=1, max_size=8)


@st.composite
def elements(draw: Any) -> dict[str, np.ndarray]:
    """One to three elements, each of scalar and fixed-length list properties of any PLY
    type, in either byte order, with any bytes in them (NaNs of every kind too)."""
    out = {}
    for element in draw(st.lists(names, min_size=1, max_size=3, unique=True)):
        fields = []
        for prop in draw(st.lists(names, min_size=1, max_size=5, unique=True)):
            kind = np.dtype(draw(st.sampled_from(sorted(TYPES.values()))))
            if draw(st.booleans()):
                kind = kind.newbyteorder(">")
            length = draw(st.none() | st.integers(0, 4))
            fields.append((prop, kind) if length is None else (prop, kind, (length,)))
        rows = draw(st.integers(0, 12))
        raw = draw(hnp.arrays(np.uint8, rows * np.dtype(fields).itemsize))
        out[element] = np.frombuffer(raw.tobytes(), fields, rows)
    return out


@settings(max_examples=80, deadline=None)
@given(elements(), st.lists(st.text(string.printable.strip(), max_size=20), max_size=2))
def test_what_is_written_is_read_back_bit_for_bit(
    written: dict[str, np.ndarray], comments: list[str]
) -> None:
    path = write_ply(_path(), written, comments)
    back = read_ply(path)
    assert list(back) == list(written)
    for name, rows in written.items():
        assert back[name].dtype.names == rows.dtype.names
        for prop in rows.dtype.names or ():
            a, b = rows[prop], back[name][prop]
            if not len(rows):  # no row tells a list's length: read as lists of none
                assert b.shape == a.shape[:1] + (0,) * (a.ndim - 1)
                continue
            assert a.shape == b.shape and a.dtype.newbyteorder("=") == b.dtype, prop
            assert a.astype(a.dtype.newbyteorder("<")).tobytes() == b.tobytes(), prop


HEADER = b"ply\nformat binary_little_endian 1.0\n"
LINES = [
    "element vertex 2",
    "element face 1",
    "property float x",
    "property uchar red",
    "property list uchar int vertex_indices",
    "property list float int bad",
    "property double",
    "element e -1",
    "comment hi",
    "format ascii 1.0",
    "junk",
]
"""Header lines, good and bad, to make headers of."""


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from(LINES), max_size=6), st.binary(max_size=40))
def test_any_header_and_body_gives_elements_or_one_line(lines: list[str], body: bytes) -> None:
    path = _path()
    path.write_bytes(HEADER + "".join(f"{x}\n" for x in [*lines, "end_header"]).encode() + body)
    try:
        read_ply(path)
    except InputError as exc:
        assert str(exc).startswith(f"{path}: ") and "\n" not in str(exc)


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=200))
def test_arbitrary_bytes_are_one_line(data: bytes) -> None:
    path = _path()
    path.write_bytes(data)
    with pytest.raises(InputError, match=f"^{re.escape(str(path))}: "):
        read_ply(path)


def test_a_file_cut_short_names_the_element_it_ends_in() -> None:
    faces = np.zeros(4, [("vertex_indices", "<i4", (3,))])
    vertex = np.zeros(5, [("x", "<f4"), ("temperature", "<f4")])
    path = write_ply(_path(), {"vertex": vertex, "face": faces})
    data = path.read_bytes()
    for cut, element in ((1, "face"), (4 * 13, "face"), (4 * 13 + 1, "vertex")):
        path.write_bytes(data[:-cut])
        with pytest.raises(InputError, match=f"element {element}: the file ends"):
            read_ply(path)


def test_lists_of_other_lengths_and_other_formats_are_refused() -> None:
    path = _path()
    body = bytes([3]) + np.arange(3, dtype="<i4").tobytes() + bytes([4])
    body += np.arange(4, dtype="<i4").tobytes()
    path.write_bytes(HEADER + b"element face 2\nproperty list uchar int v\nend_header\n" + body)
    with pytest.raises(InputError, match="element face, row 1: a v list of 4 items, the first"):
        read_ply(path)
    path.write_bytes(b"ply\nformat ascii 1.0\nelement v 0\nproperty float x\nend_header\n")
    with pytest.raises(InputError, match=r"header line 2 .*reads binary_little_endian PLY"):
        read_ply(path)
    path.write_bytes(HEADER + b"element vertex 1\nproperty float x\nend_header\n" + bytes(4))
    with pytest.raises(InputError, match="no vertex property y, z, temperature in its header"):
        read_cloud(path)


def test_point_clouds_are_read_by_trimesh() -> None:
    trimesh = pytest.importorskip("trimesh", reason="trimesh (the map extra) as a second reader")
    rng = np.random.default_rng(0)
    points = rng.normal(size=(30, 3))
    temps = rng.uniform(20, 80, 30)
    temps[4] = np.nan
    path = write_cloud(_path(), points, temps, 20.0, 80.0)
    header = path.read_bytes()[:400]
    assert b"property float temperature\nproperty uchar red" in header
    cloud = trimesh.load(path, process=False)  # trimesh's own PLY reader
    np.testing.assert_array_equal(cloud.vertices, points.astype(np.float32))
    raw = cloud.metadata["_ply_raw"]["vertex"]["data"]
    np.testing.assert_array_equal(raw["temperature"], temps.astype(np.float32))
    assert cloud.colors[0, :3].tolist() == [raw["red"][0], raw["green"][0], raw["blue"][0]]
    back_points, back_temps = read_cloud(path)
    np.testing.assert_array_equal(back_points, points.astype(np.float32))
    np.testing.assert_array_equal(back_temps, temps.astype(np.float32))
