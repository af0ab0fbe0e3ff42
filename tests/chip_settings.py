"""Settings for runs of the simulated rig whose alarm trips and clears often (helpers for the
sink and batch tests)."""

from __future__ import annotations

from pathlib import Path

HOT_CHIP = """\
hotspots:
  threshold_c: 50
alarms:
  - name: hot
    above_c: 67.48
    for_frames: {for_frames}
"""
"""The simulated chip (70 C, 1 m) reads 67.42-67.59 C: above 67.48 C its alarm trips and
clears every few frames."""


def chip_settings(folder: Path, extra: str = "", for_frames: int = 1) -> Path:
    """``folder/s.yaml``: :data:`HOT_CHIP` with ``for_frames`` and ``extra`` YAML after it."""
    path = folder / "s.yaml"
    path.write_text(HOT_CHIP.format(for_frames=for_frames) + extra, encoding="utf-8")
    return path
