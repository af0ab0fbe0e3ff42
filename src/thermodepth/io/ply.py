"""PLY files (Stanford polygon format), binary little endian, as numpy structured arrays.

An element is a structured array, one row per item: a scalar field is a property (``f4``:
``property float x``); a field that is a fixed-length array is a list property, written with
a ``uchar`` count (``("vertex_indices", "<i4", (3,))``: ``property list uchar int
vertex_indices``, a triangle a face). The reader takes what the writer writes and any other
binary little-endian PLY whose lists are each of one length; anything else is one
:class:`~thermodepth.errors.InputError` line naming the file.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError

FORMAT = "binary_little_endian"

TYPES = {
    "char": "i1",
    "uchar": "u1",
    "short": "<i2",
    "ushort": "<u2",
    "int": "<i4",
    "uint": "<u4",
    "float": "<f4",
    "double": "<f8",
}
"""PLY's type names and the little-endian numpy types they are."""
ALIASES = {
    "int8": "char",
    "uint8": "uchar",
    "int16": "short",
    "uint16": "ushort",
    "int32": "int",
    "uint32": "uint",
    "float32": "float",
    "float64": "double",
}
"""The sized names some writers use for the same types."""
_NAMES = {np.dtype(t): name for name, t in TYPES.items()}

Element = NDArray[Any]  # a structured array (numpy void rows)


def _type_name(dtype: np.dtype[Any], where: str) -> str:
    """PLY's name for a numpy type of either byte order (written little endian)."""
    name = _NAMES.get(dtype.newbyteorder("<"))
    if name is None:
        raise ValueError(f"{where}: {dtype} has no PLY type")
    return name


def write_ply(
    path: str | Path, elements: Mapping[str, Element], comments: Sequence[str] = ()
) -> Path:
    """Write ``elements`` (name -> structured array, in order) as a binary little-endian PLY
    at ``path`` (its folder made if needed), each comment a ``comment`` line of the header.

    Args:
        path: the file.
        elements: each element's rows; a field of shape (k,) is a list property of k items
            (k <= 255), every other field a scalar property.
        comments: header comments (one line each).

    Returns:
        ``path``.
    """
    header = ["ply", f"format {FORMAT} 1.0", *(f"comment {c}" for c in comments)]
    blocks = []
    for name, rows in elements.items():
        if rows.dtype.names is None:
            raise ValueError(f"element {name}: give a structured array")
        header.append(f"element {name} {len(rows)}")
        fields: list[tuple[Any, ...]] = []  # the rows as stored: a count before each list
        for field in rows.dtype.names:
            ftype = rows.dtype[field]
            kind = _type_name(ftype.base, f"element {name}, property {field}")
            if ftype.shape:
                if len(ftype.shape) != 1 or ftype.shape[0] > 255:
                    raise ValueError(f"element {name}, property {field}: lists of {ftype.shape}")
                header.append(f"property list uchar {kind} {field}")
                fields += [(f"{field} count", "u1"), (field, TYPES[kind], ftype.shape)]
            else:
                header.append(f"property {kind} {field}")
                fields.append((field, TYPES[kind]))
        packed = np.empty(len(rows), dtype=fields)  # no padding: the bytes PLY lays out
        for field in rows.dtype.names:
            packed[field] = rows[field]
            if rows.dtype[field].shape:
                packed[f"{field} count"] = rows.dtype[field].shape[0]
        blocks.append(packed.tobytes())
    header.append("end_header")
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.writelines(blocks)
    return out


def read_ply(
    path: str | Path, need: Mapping[str, Sequence[str]] | None = None
) -> dict[str, Element]:
    """The elements of a binary little-endian PLY, by name, in the file's order.

    Args:
        path: the file.
        need: element -> the properties it must have (a file without them is refused).

    Returns:
        Each element as a structured array: a field per property, a list property a field
        of shape (k,) (its count not kept; an element without rows has lists of none).

    Raises:
        InputError: one line naming the file, and the header line or the element, when it
        cannot be read, is not such a PLY, ends before its header's rows do, or lacks a
        property ``need`` names.
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise InputError(f"{p}: cannot read ({exc.strerror or exc})") from None
    end = data.find(b"\nend_header")
    stop = data.find(b"\n", end + 1)
    lines = data[: max(stop, 0)].decode("ascii", "replace").splitlines() or [""]
    if end < 0 or stop < 0 or lines[0].strip() != "ply" or lines[-1].strip() != "end_header":
        raise InputError(f"{p}: not a PLY file (no 'ply' ... 'end_header' header)")
    declared = _header(p, lines)
    offset = stop + 1
    elements = {}
    for name, count, props in declared:
        rows, offset = _element(p, data, offset, name, count, props)
        elements[name] = rows
    for name, wanted in (need or {}).items():
        has = elements[name].dtype.names or () if name in elements else ()
        missing = [prop for prop in wanted if prop not in has]
        if missing:
            raise InputError(f"{p}: no {name} property {', '.join(missing)} in its header")
    return elements


_Property = tuple[str, str, str | None]  # name, type, the list's count type (None: a scalar)


def _header(p: Path, lines: list[str]) -> list[tuple[str, int, list[_Property]]]:
    """The elements a header declares: name, count and properties (names, each once)."""
    elements: list[tuple[str, int, list[_Property]]] = []
    seen_format = False
    for n, line in enumerate(lines[1:-1], 2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        why = None
        if words[0] == "format":
            seen_format = len(words) == 3 and words[1] == FORMAT
            why = None if seen_format else f"thermodepth reads {FORMAT} PLY files"
        elif words[0] == "element":
            if len(words) != 3 or not words[2].isdigit():
                why = "give 'element NAME COUNT'"
            elif words[1] in (e[0] for e in elements):
                why = f"a second element {words[1]}"
            else:
                elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and not elements:
            why = "a property before any element"
        elif words[0] == "property" and len(words) in (3, 5):
            listed = len(words) == 5 and words[1] == "list"
            names = words[2:4] if listed else words[1:2]
            types = [_TYPE_OF[w] for w in names if w in _TYPE_OF]
            if len(types) != len(names) or (len(words) == 5 and not listed):
                why = f"unknown type in {' '.join(words[1:-1])!r}"
            elif listed and np.dtype(types[0]).kind != "u":
                why = "a list's count is an unsigned integer"
            elif words[-1] in (prop[0] for prop in elements[-1][2]):
                why = f"element {elements[-1][0]} has a property {words[-1]} already"
            else:
                elements[-1][2].append((words[-1], types[-1], types[0] if listed else None))
        elif words[0] == "property":
            why = "give 'property TYPE NAME' or 'property list TYPE TYPE NAME'"
        else:
            why = f"unknown keyword {words[0]!r}"
        if why:
            raise InputError(f"{p}: header line {n} ({line.strip()!r}): {why}")
    if not seen_format:
        raise InputError(f"{p}: not a PLY file (its header says no format)")
    return elements


_TYPE_OF = {**TYPES, **{alias: TYPES[name] for alias, name in ALIASES.items()}}


def _element(
    p: Path, data: bytes, offset: int, name: str, count: int, props: list[_Property]
) -> tuple[Element, int]:
    """An element's rows from ``data`` at ``offset``, and the offset after them. A list's
    length is the first row's; every row's count must be the same."""
    fields: list[tuple[Any, ...]] = []
    row_size = 0
    for prop, item_type, count_type in props:
        if count_type is None:
            fields.append((prop, item_type))
            row_size += np.dtype(item_type).itemsize
            continue
        at = offset + row_size
        if count == 0:
            length = 0
        elif at + np.dtype(count_type).itemsize > len(data):
            raise InputError(f"{p}: element {name}: the file ends in its first row")
        else:
            length = int(np.frombuffer(data, count_type, 1, at)[0])
        fields += [(f"{prop} count", count_type), (prop, item_type, (length,))]
        row_size += np.dtype(count_type).itemsize + length * np.dtype(item_type).itemsize
    dtype = np.dtype(fields)
    if offset + count * dtype.itemsize > len(data):
        raise InputError(
            f"{p}: element {name}: the file ends before its {count} rows "
            f"({len(data) - offset} of {count * dtype.itemsize} bytes)"
        )
    # an element without properties takes no bytes (and numpy reads no zero-size items)
    rows = np.frombuffer(data, dtype, count, offset) if dtype.itemsize else np.zeros(count, dtype)
    for prop, _, count_type in props:
        if count_type is not None and count:
            counts = rows[f"{prop} count"]
            odd = np.flatnonzero(counts != counts[0])
            if odd.size:
                raise InputError(
                    f"{p}: element {name}, row {odd[0]}: a {prop} list of {counts[odd[0]]} "
                    f"items, the first has {counts[0]} (thermodepth reads lists of one length)"
                )
    keep = [prop for prop, _, _ in props]
    # a copy of the fields without the counts: contiguous, writable, native byte order
    out = np.empty(count, [(k, dtype[k].newbyteorder("=")) for k in keep])
    for k in keep:
        out[k] = rows[k]
    return out, offset + count * dtype.itemsize
