"""``thermodepth devices``: what cameras are attached, and the source spec of each (thermal
cameras found by their USB vendor:product: PureThermal 1e4e:0100, InfiRay P2 Pro 0bda:5830,
FLIR Boson 09cb:4007)."""

from __future__ import annotations

from typing import Any

from ..sources import list_devices
from ..sources.uvc import CAMERA_TITLES

__all__ = ["describe_devices", "list_devices"]


def describe_devices(found: dict[str, Any]) -> list[str]:
    """Lines for ``thermodepth devices``: each device with its source spec, a clear
    "no ... found" for each kind missing, and why RealSense devices cannot be listed when
    pyrealsense2 is unavailable."""
    lines = []
    if found.get("realsense_unavailable"):
        lines.append(f"RealSense devices cannot be listed: {found['realsense_unavailable']}")
    elif found["realsense"]:
        for d in found["realsense"]:
            lines.append(
                f"RealSense {d['name']}  serial {d['serial']}  firmware {d['firmware']}  "
                f"USB {d['usb']}  -> --source realsense:{d['serial']}"
            )
    else:
        lines.append("no RealSense device found")
    for d in found["thermal"]:
        lines.append(
            f"{CAMERA_TITLES[d['kind']]} /dev/video{d['index']} {d['name']!r}  "
            f"-> --source {d['kind']}:{d['index']} (with a depth camera: "
            f"realsense+{d['kind']}:{d['index']})"
        )
    if not found["thermal"]:
        others = [f"/dev/video{d['index']} ({d['name'] or 'unnamed'})" for d in found["video"]]
        lines.append(
            "no thermal camera found (PureThermal Lepton, InfiRay P2 Pro / Topdon TC001, FLIR "
            "Boson)" + (f"; other video devices: {', '.join(others)}" if others else "")
        )
    return lines
