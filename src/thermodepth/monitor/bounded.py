"""A queue bounded in bytes, for what waits between a rig and its evidence (a clip's pairs,
the pictures to draw): a count of items says little when one item is a 80x60 frame and the
next a 1280x720 one, and memory is what an edge box runs out of.

The policy is the caller's: :meth:`ByteQueue.offer` refuses an item that would take the
queue past its bytes (the caller counts it and goes on: a rig never waits for its
evidence), and an item alone larger than the bound is still taken into an empty queue, so
that a large frame is not lost for ever.

Memory given back: frames of a few MB are allocated and freed many times a second on many
threads; glibc keeps what they freed in its heaps (one per thread, up to 8 per core) for
reuse, scattered among what is still held, so the monitor's resident memory grows with its
rigs and after a burst stays high. :func:`give_back_memory` returns those free pages to the
system (glibc's ``malloc_trim``); the monitor's clock calls it every :data:`GIVE_BACK_S`.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import threading
from collections import deque
from functools import cache
from typing import Any

import numpy as np

MB = 1 << 20
GIVE_BACK_S = 5.0
"""How often the monitor gives the C heap's free memory back (bench_monitor_memory, rigs at
1280x720 after 40 s: 1 rig 479 MB where 564 MB without, 8 rigs 2,198 MB where 2,704 MB)."""


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


@cache
def _malloc_trim() -> Any:
    name = ctypes.util.find_library("c")
    try:
        return ctypes.CDLL(name).malloc_trim if name else None
    except (OSError, AttributeError):  # not glibc (musl, macOS): nothing to call
        return None


def give_back_memory() -> bool:
    """Give the free pages of the C heaps back to the system (glibc's ``malloc_trim(0)``:
    the free memory between chunks still in use too, not only at a heap's top); False where
    the C library has no such call. Takes milliseconds; safe from any thread."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
