"""``thermodepth monitor``: the always-on monitor of a config file, until stopped
(:mod:`thermodepth.monitor`); ``thermodepth dashboard``: one screen for the monitors that
publish to a broker (:mod:`thermodepth.monitor.central`)."""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import FrameType
from typing import Any

from ..errors import InputError, ThermodepthError
from ..monitor import Monitor, MonitorConfig, load_config
from ..monitor.config import HttpConfig, http_problems
from ..monitor.logs import install_handler, logger
from ..monitor.outputs import describe_outputs
from ..monitor.systemd import notify, reloading
from ..pipeline import MqttSettings, Settings


def describe_config(config: MonitorConfig) -> list[str]:
    """What a valid config would start, a line each (``monitor --check``): each rig with its
    source, settings, ROIs and alarm rules; the storage; the HTTP server; every output
    (Home Assistant discovery on or off); the log's levels."""
    s = config.storage
    lines = [f"{len(config.rigs)} rig{'s' if len(config.rigs) > 1 else ''}:"]
    for rig in config.rigs:
        where = f" at {rig.location}" if rig.location else ""
        lines.append(f"  {rig.name}{where}: {rig.source} with {rig.settings or 'default settings'}")
        settings = Settings.load(rig.settings) if rig.settings else Settings()
        rois = ", ".join(r.name for r in settings.rois) or "none"
        rules = ", ".join(
            f"{a.name} ({a.rule().condition()}{', latched until acknowledged' * a.latch})"
            for a in settings.alarms
        )
        lines.append(f"    ROIs: {rois}; alarm rules: {rules or 'none'}")
        for key in ("calibration", "compensation"):
            path = getattr(settings, key)
            lines.append(f"    {key}: {path if path else 'none'}")
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
    outputs = describe_outputs(config)
    lines.extend(
        outputs
        or [
            "no outputs (MQTT, OPC UA, Modbus, RTSP, notifications): the dashboard and the log only"
        ]
    )
    rig_levels = ", ".join(f"{k} {v}" for k, v in config.log.rigs.items())
    lines.append(f"log level {config.log.level}" + (f" ({rig_levels})" if rig_levels else ""))
    return lines


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


def run_monitor(path: Path) -> None:
    """Run the monitor of the config at ``path`` until SIGTERM or SIGINT (Ctrl-C); SIGHUP
    reloads the config (a bad one is refused with its lines and the running one goes on).
    Tells systemd when it is ready, reloading and stopping; logs on stderr
    (:mod:`thermodepth.monitor.logs`). Call it from the main thread."""
    install_handler()
    log = logger()
    monitor = Monitor(load_config(path))
    reload = threading.Event()
    with until_signalled(reload.set) as stop:
        try:
            monitor.start()
            notify("READY=1", f"STATUS=watching {len(monitor.runners)} rigs")
            while not stop.wait(0.2):
                if reload.is_set():
                    reload.clear()
                    _reload(monitor, path)
            log.info("monitor: stopping")
        finally:
            notify("STOPPING=1")
            monitor.stop()
    log.info("monitor: stopped")


def run_dashboard(
    url: str,
    folder: Path,
    http: HttpConfig,
    mqtt: MqttSettings,
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
    install_handler()
    log = logger("central")
    central = CentralDashboard(url, folder, mqtt)
    server = HttpServer(central, http)
    with until_signalled() as stop:
        central.start()
        try:
            server.start()
            where = f"{central.target.where}/{central.prefix}"
            log.info("dashboard: %s for the rigs under %s", server.url, where)
            notify("READY=1")
            stop.wait()
            log.info("dashboard: stopping")
        finally:
            notify("STOPPING=1")
            server.stop()
            central.stop()
    log.info("dashboard: stopped")


def _reload(monitor: Monitor, path: Path) -> None:
    reloading()
    log = logger()
    try:
        monitor.reload(load_config(path))
        log.info("monitor: reloaded %s", path)
    except ThermodepthError as exc:
        log.error("monitor: %s not reloaded, the running config goes on:\n%s", path, exc)
    notify("READY=1", f"STATUS=watching {len(monitor.runners)} rigs")
