"""Image pairs of a calibration folder, matched by name."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from .images import IMAGE_SUFFIXES

DEPTH_ROLES = ("ir", "color", "rgb")
"""Name suffixes of the depth camera's image: ``_ir`` (infrared, shares the depth stream's
intrinsics and frame on a D435) or ``_color`` / ``_rgb`` (a colour camera)."""


@dataclass(frozen=True)
class ImagePair:
    """One pose: the depth camera's image (IR or colour) and the thermal image."""

    name: str
    depth_path: Path
    thermal_path: Path


@dataclass(frozen=True)
class PairListing:
    """What :func:`discover_pairs` found: matched pairs and files left out, with why."""

    pairs: tuple[ImagePair, ...]
    unmatched: tuple[tuple[Path, str], ...]


_SUFFIX_RULE = re.compile(rf"(?P<stem>.+)_(?P<role>{'|'.join(DEPTH_ROLES)}|thermal)", re.IGNORECASE)
_SIDE_RULE = re.compile(r"(?P<role>left|right)(?P<stem>.*)", re.IGNORECASE)
RULES_TEXT = "<stem>_ir|_color|_rgb + <stem>_thermal, or left<key> + right<key>"


def discover_pairs(pairs_dir: str | Path) -> PairListing:
    """Match the images of ``pairs_dir`` into pairs by name.

    Two rules (any image extension of :data:`IMAGE_SUFFIXES`, case-insensitive):

    - ``<stem>_ir.<ext>`` (or ``_color`` / ``_rgb``) with ``<stem>_thermal.<ext>``;
    - ``left<key>.<ext>`` with ``right<key>.<ext>`` (OpenCV's stereo samples): left is the
      depth camera's image, right the thermal image.

    Images that fit no rule, lack a partner, or duplicate a role of a stem (``a_ir.png`` and
    ``a_ir.npy``) are listed in ``unmatched`` with the reason; other files are ignored.
    Pairs are sorted by name. Raises InputError if the folder is missing or has no pair.
    """
    folder = Path(pairs_dir)
    if not folder.is_dir():
        raise InputError(f"{folder}: not a folder of image pairs")
    roles: dict[tuple[str, str], dict[str, Path]] = {}
    unmatched: list[tuple[Path, str]] = []
    for path in sorted(folder.iterdir()):
        if not path.is_file() or path.suffix.lower() not in IMAGE_SUFFIXES:
            continue
        stem = path.stem
        m = _SUFFIX_RULE.fullmatch(stem)
        if m:
            key = ("suffix", m.group("stem"))
            role = "thermal" if m.group("role").lower() == "thermal" else "depth"
        elif m2 := _SIDE_RULE.fullmatch(stem):
            key = ("side", m2.group("stem"))
            role = "depth" if m2.group("role").lower() == "left" else "thermal"
        else:
            unmatched.append((path, f"name fits no rule ({RULES_TEXT})"))
            continue
        slot = roles.setdefault(key, {})
        if role in slot:
            unmatched.append((path, f"{slot[role].name} already is the {role} image"))
            continue
        slot[role] = path
    pairs = []
    for (rule, stem), slot in roles.items():
        if "depth" in slot and "thermal" in slot:
            name = stem if rule == "suffix" else (stem or "(blank)")
            pairs.append(ImagePair(name, slot["depth"], slot["thermal"]))
            continue
        ((role, path),) = slot.items()
        want = "thermal" if role == "depth" else "depth camera (IR/colour)"
        if rule == "side":
            hint = f"{'right' if role == 'depth' else 'left'}{stem}.*"
        elif role == "depth":
            hint = f"{stem}_thermal.*"
        else:
            hint = f"{stem}_ir.* (or _color, _rgb)"
        unmatched.append((path, f"no {want} image to pair with (expected {hint})"))
    if not pairs:
        raise InputError(f"{folder}: no image pairs found (naming rules: {RULES_TEXT})")
    pairs.sort(key=lambda p: (p.name, str(p.depth_path)))
    unmatched.sort(key=lambda u: str(u[0]))
    return PairListing(tuple(pairs), tuple(unmatched))
