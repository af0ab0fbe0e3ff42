"""A function as a sink: ``CallbackSink(print_frame)`` calls it with every fused frame (the
command line's live lines; a script's own handling)."""

from __future__ import annotations

from collections.abc import Callable

from ..pipeline import FusedFrame
from .base import BaseSink


class CallbackSink(BaseSink):
    """Calls ``on_frame(fused)`` for every fused frame."""

    def __init__(self, on_frame: Callable[[FusedFrame], None]) -> None:
        self.on_frame = on_frame

    def frame(self, fused: FusedFrame) -> None:
        self.on_frame(fused)
