"""The simulated rig as a source (``sim``): FramePairs from :class:`thermodepth.sim.Rig`."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from ..frames import StreamEvent, match_of
from ..sim import Rig, camera_pose, plate_scene
from .base import Source


class SimSource(Source):
    """Pairs from a simulated rig: the paper's plate with a 70 C chip, 1 m away, by default.

    rig: any :class:`~thermodepth.sim.Rig` (its true calibration is the source's); thermal,
    depth: the default rig's cameras (a name of
    :data:`~thermodepth.sim.cameras.THERMAL_CAMERAS`, a depth mode ``WxH[@FPS]``; None: the
    Lepton 3 beside a D435 at 1280x720); frames: stop after so many pairs (None: never).
    """

    name = "sim"
    paired_by = "the simulator"

    def __init__(
        self,
        rig: Rig | None = None,
        frames: int | None = None,
        thermal: str | None = None,
        depth: str | None = None,
    ) -> None:
        self.rig = rig or Rig.of_cameras(
            plate_scene(chip_temp_c=70.0), camera_pose(1.0), thermal, depth
        )
        self.cameras = {"thermal": thermal or "lepton3", "depth": depth or "1280x720"}
        self.frames = frames
        self.calibration = self.rig.calibration

    def events(self) -> Iterator[StreamEvent]:
        for pair in self.rig.frames(self.frames):
            yield match_of(pair)

    def settings(self) -> dict[str, Any]:
        return {
            "source": "sim",
            "seed": self.rig.seed,
            "with_ir": self.rig.with_ir,
            **self.cameras,
        }
