"""``thermodepth monitor``: the always-on monitor of a config file, until stopped
(:mod:`thermodepth.monitor`); ``thermodepth dashboard``: one screen for the monitors that
publish to a broker (:mod:`thermodepth.monitor.central`)."""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path
from types import FrameType
from typing import Any

from ..errors import InputError, ThermodepthError
from ..monitor import Monitor, MonitorConfig, load_config
from ..monitor.config import HttpConfig, http_problems
from ..monitor.systemd import notify, reloading
from ..pipeline import MqttSettings


def describe_config(config: MonitorConfig) -> list[str]:
    """What a valid config sets up, a line each (``monitor --check``)."""
    s = config.storage
    lines = [f"{len(config.rigs)} rigs:"]
    for rig in config.rigs:
        where = f" at {rig.location}" if rig.location else ""
        settings = rig.settings or "default settings"
        lines.append(f"  {rig.name}{where}: {rig.source} with {settings}")
    keep = "everything (rolling) and clips" if s.continuous else "clips of events"
    lines.append(
        f"storage {s.path}: {keep}, {s.pre_s:g} s before and {s.post_s:g} s after; kept "
        f"{s.retention_days:g} days, {s.min_free_gb:g} GB left free"
    )
    http = config.http
    lines.append(
        "no HTTP server"
        if http.listen is None
        else f"HTTP on {http.listen}" + (" with a bearer token" if http.token_file else "")
    )
    lines.append("no MQTT" if config.mqtt is None else f"MQTT {config.mqtt.url}")
    return lines


def log_line(line: str) -> None:
    """A line of the monitor's log on stderr, stamped in UTC."""
    now = datetime.now(timezone.utc).isoformat(timespec="milliseconds")
    print(f"{now} {line}", file=sys.stderr, flush=True)


@contextmanager
def until_signalled(on_hangup: Callable[[], None] | None = None) -> Iterator[threading.Event]:
    """An event set by SIGTERM or SIGINT (a second one stops at once: KeyboardInterrupt);
    SIGHUP calls ``on_hangup``. The previous handlers come back after. Main thread only."""
    stop = threading.Event()

    def on_stop(signum: int, frame: FrameType | None) -> None:
        if stop.is_set():
            raise KeyboardInterrupt
        stop.set()

    handlers: dict[signal.Signals, Any] = {signal.SIGTERM: on_stop, signal.SIGINT: on_stop}
    if on_hangup is not None:
        handlers[signal.SIGHUP] = lambda signum, frame: on_hangup()
    previous = {sig: signal.signal(sig, handler) for sig, handler in handlers.items()}
    try:
        yield stop
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def run_monitor(path: Path, log: Callable[[str], None] = log_line) -> None:
    """Run the monitor of the config at ``path`` until SIGTERM or SIGINT (Ctrl-C); SIGHUP
    reloads the config (a bad one is refused with its lines and the running one goes on).
    Tells systemd when it is ready, reloading and stopping. Call it from the main thread."""
    monitor = Monitor(load_config(path), log)
    reload = threading.Event()
    with until_signalled(reload.set) as stop:
        try:
            monitor.start()
            notify("READY=1", f"STATUS=watching {len(monitor.runners)} rigs")
            while not stop.wait(0.2):
                if reload.is_set():
                    reload.clear()
                    _reload(monitor, path, log)
            log("monitor: stopping")
        finally:
            notify("STOPPING=1")
            monitor.stop()
    log("monitor: stopped")


def run_dashboard(
    url: str,
    folder: Path,
    http: HttpConfig,
    mqtt: MqttSettings,
    log: Callable[[str], None] = log_line,
) -> None:
    """Serve the dashboard of every rig publishing under the broker ``url``'s prefix
    (:mod:`thermodepth.monitor.central`), keeping its events in ``folder``, until SIGTERM or
    SIGINT. One InputError with every problem of ``http`` (the options) first."""
    from ..monitor.central import CentralDashboard
    from ..monitor.http import HttpServer

    problems = http_problems(http, lambda name: f"--{name.replace('_', '-')}")
    if http.listen is None:
        problems.append("--listen: the dashboard needs an address to serve")
    if problems:
        raise InputError("\n".join(problems))
    central = CentralDashboard(url, folder, mqtt, log)
    server = HttpServer(central, http)
    with until_signalled() as stop:
        central.start()
        try:
            server.start()
            where = f"{central.target.where}/{central.prefix}"
            log(f"dashboard: {server.url} for the rigs under {where}")
            notify("READY=1")
            stop.wait()
            log("dashboard: stopping")
        finally:
            notify("STOPPING=1")
            server.stop()
            central.stop()
    log("dashboard: stopped")


def _reload(monitor: Monitor, path: Path, log: Callable[[str], None]) -> None:
    reloading()
    try:
        monitor.reload(load_config(path))
        log(f"monitor: reloaded {path}")
    except ThermodepthError as exc:
        log(f"monitor: {path} not reloaded, the running config goes on:\n{exc}")
    notify("READY=1", f"STATUS=watching {len(monitor.runners)} rigs")
