"""A queue bounded in bytes, for what waits between a rig and its evidence (a clip's pairs,
the pictures to draw): a count of items says little when one item is a 80x60 frame and the
next a 1280x720 one, and memory is what an edge box runs out of.

The policy is the caller's: :meth:`ByteQueue.offer` refuses an item that would take the
queue past its bytes (the caller counts it and goes on: a rig never waits for its
evidence), and an item alone larger than the bound is still taken into an empty queue, so
that a large frame is not lost for ever.
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Any

import numpy as np

MB = 1 << 20


def nbytes_of(item: Any, depth: int = 2) -> int:
    """The bytes of the arrays an item holds, each counted once: itself if an array, else
    its fields' (a tuple's, or an object's attributes, cached ones included), ``depth``
    levels down (a Match's frames; a fused frame's grids and its sampled depth grid).

    >>> frame = np.zeros((120, 160), np.uint16)
    >>> nbytes_of((frame, "label", (frame, np.zeros(3))))
    38424
    """
    seen: set[int] = set()

    def walk(x: Any, left: int) -> int:
        if isinstance(x, np.ndarray | bytes):
            if id(x) in seen:
                return 0
            seen.add(id(x))
            return int(x.nbytes) if isinstance(x, np.ndarray) else len(x)
        if left == 0:
            return 0
        values = x if isinstance(x, tuple | list) else tuple(getattr(x, "__dict__", {}).values())
        return sum(walk(v, left - 1) for v in values)

    return walk(item, depth + 1)


class ByteQueue:
    """A FIFO of at most ``max_bytes`` (each item's size given by the caller), for one or
    more producers and consumers; ``refused`` counts the items :meth:`offer` did not take."""

    def __init__(self, max_bytes: int) -> None:
        self.max_bytes = max_bytes
        self.nbytes = 0
        self.refused = 0
        self._items: deque[tuple[Any, int]] = deque()
        self._ready = threading.Condition()

    def offer(self, item: Any, nbytes: int) -> bool:
        """Queue ``item`` unless it would take the queue past ``max_bytes`` (an empty queue
        takes any one item); False, counted in ``refused``, when it does not."""
        with self._ready:
            if self._items and self.nbytes + nbytes > self.max_bytes:
                self.refused += 1
                return False
            self._items.append((item, nbytes))
            self.nbytes += nbytes
            self._ready.notify()
            return True

    def put(self, item: Any) -> None:
        """Queue a marker or other item of no size, never refused (the end of a stream)."""
        with self._ready:
            self._items.append((item, 0))
            self._ready.notify()

    def get(self, timeout_s: float | None = None) -> Any:
        """The oldest item; TimeoutError when none came within ``timeout_s``."""
        with self._ready:
            if not self._ready.wait_for(lambda: bool(self._items), timeout_s):
                raise TimeoutError("nothing queued")
            item, nbytes = self._items.popleft()
            self.nbytes -= nbytes
            return item

    def __len__(self) -> int:
        with self._ready:
            return len(self._items)
