"""Configs and settings for the monitor's tests: simulated rigs whose alarms trip often, a
model fitted over a known VOx range, a monitor config written as a user would, and waiting
for a condition (helpers for tests/test_monitor*.py)."""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import yaml

from thermodepth.compensation import preset
from thermodepth.compensation.files import save_model

FLAPPING = """\
hotspots:
  threshold_c: 50
alarms:
  - {name: hot, above_c: 67.48}
  - {name: latched, above_c: 60, latch: true}
"""
"""The simulated chip (70 C, 1 m) reads 67.42-67.59 C: ``hot`` trips and clears every few
frames; ``latched`` is raised from the first frame and stays until acknowledged."""

PAPER_MODEL = """\
compensation: paper.json
hotspots:
  threshold_c: 50
alarms:
  - {name: hot, above_c: 64.655}
"""
"""With the paper's published model (fitted over VOx 25-40 C) the chip reads 64.64-64.67 C."""


def settings_file(folder: Path, text: str = FLAPPING, name: str = "s.yaml") -> Path:
    path = folder / name
    if "paper.json" in text:
        save_model(preset("paper2022"), folder / "paper.json")
    path.write_text(text, encoding="utf-8")
    return path


def monitor_config(folder: Path, rigs: list[dict[str, Any]], **sections: Any) -> Path:
    """``folder/monitor.yaml`` with ``rigs``, storage in ``folder/store`` (short clips) and
    HTTP on a free loopback port unless ``sections`` say otherwise."""
    data: dict[str, Any] = {
        "rigs": rigs,
        "storage": {"path": "store", "pre_s": 1, "post_s": 1, "clip_max_s": 3},
        "http": {"listen": "127.0.0.1:0"},
    }
    for key, value in sections.items():
        data[key] = {**data.get(key, {}), **value} if isinstance(value, dict) else value
    path = folder / "monitor.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


PATIENCE_S = 120.0
"""How long a test waits for what it expects: far beyond what any machine needs (a machine
three times slower than ours, busy, with numba compiling, still gets there)."""


@contextmanager
def log_lines(level: int = logging.DEBUG) -> Iterator[list[str]]:
    """Every line the monitor logs (``thermodepth.monitor`` and its parts) while inside, its
    traceback after it; for fixtures wider than a test (a test itself uses caplog)."""
    lines: list[str] = []

    class Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            text = record.getMessage()
            if record.exc_info:
                text += "\n" + logging.Formatter().formatException(record.exc_info)
            lines.append(text)

    root = logging.getLogger("thermodepth.monitor")
    handler, before = Collect(level), root.level
    root.addHandler(handler)
    root.setLevel(min(level, root.getEffectiveLevel()))
    try:
        yield lines
    finally:
        root.removeHandler(handler)
        root.setLevel(before)


def wait_for(
    condition: Callable[[], Any], timeout_s: float = PATIENCE_S, every_s: float = 0.05
) -> Any:
    """``condition()``'s first true value within ``timeout_s``; AssertionError otherwise."""
    end = time.monotonic() + timeout_s
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > end:
            raise AssertionError(f"not within {timeout_s} s")
        time.sleep(every_s)


class Notifications:
    """A datagram socket standing for systemd's notify socket, read as systemd reads it: all
    the time, on a thread of its own (``got``: what came, in order)."""

    def __init__(self, path: Path) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(str(path))
        self.sock.settimeout(0.1)
        self.path = path
        self.got: list[str] = []
        self._closed = threading.Event()
        threading.Thread(target=self._listen, daemon=True).start()

    def _listen(self) -> None:
        while not self._closed.is_set():
            try:
                self.got.append(self.sock.recv(4096).decode())
            except TimeoutError:
                continue
            except OSError:
                return

    def read(self) -> list[str]:
        return list(self.got)

    def has(self, text: str) -> bool:
        return any(text in g for g in self.read())

    def close(self) -> None:
        self._closed.set()
