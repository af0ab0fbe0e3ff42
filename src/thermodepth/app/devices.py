"""``thermodepth devices``: what cameras are attached, and the source spec of each."""

from __future__ import annotations

from typing import Any

from ..sources import list_devices

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
    if found["purethermal"]:
        for d in found["purethermal"]:
            lines.append(
                f"PureThermal (Lepton) /dev/video{d['index']} {d['name']!r}  "
                f"-> --source lepton:{d['index']}"
            )
    else:
        others = [
            f"/dev/video{d['index']} ({d['name'] or 'unnamed'})"
            for d in found["video"]
            if not d["purethermal"]
        ]
        lines.append(
            "no PureThermal (Lepton) found"
            + (f"; other video devices: {', '.join(others)}" if others else "")
        )
    return lines
