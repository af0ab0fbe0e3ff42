"""``monitor`` and ``dashboard``: the always-on monitor, and one screen for many; ``compile``:
numba's kernels into their cache before them."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .base import app, console, one_line_errors


@app.command("monitor")
@one_line_errors
def monitor_cmd(
    config: Annotated[Path, typer.Argument(help="The monitor's config (monitor.yaml).")],
    check: Annotated[
        bool, typer.Option("--check", help="Only check the config and say what it sets up.")
    ] = False,
    modbus_map: Annotated[
        bool,
        typer.Option(
            "--modbus-map",
            help="Only print the Modbus server's register map as CSV "
            "(address,table,type,scale,unit,rig,name; addresses from 0).",
        ),
    ] = False,
) -> None:
    """Watch rigs day and night (docs/monitor.md): each rig reopened when its camera fails,
    sensor faults raised when data cannot be trusted, every event kept with its evidence
    (a clip, an overlay, a point cloud), storage bounded, health on HTTP, MQTT, OPC UA and
    Modbus, live video as MJPEG and RTSP. Runs until SIGTERM or Ctrl-C; SIGHUP reloads the
    config."""
    from ..app.monitor import describe_config, run_monitor
    from ..monitor import load_config

    if modbus_map:
        from ..monitor.outputs.modbus import config_map_csv

        typer.echo(config_map_csv(load_config(config)), nl=False)
        return
    if check:
        for line in describe_config(load_config(config)):
            console.print(line, markup=False, highlight=False, soft_wrap=True)
        console.print(f"{config}: OK", markup=False, highlight=False)
        return
    run_monitor(config)


@app.command("compile")
@one_line_errors
def compile_cmd(
    only: Annotated[
        str | None, typer.Option(help="One part: pipeline (registration) or sim (simulator).")
    ] = None,
) -> None:
    """Compile the numba kernels into their cache on disk now (after an install, in an
    image's build), so that no later command or rig compiles them as it starts."""
    from ..app.kernels import PARTS, compile_kernels
    from ..errors import FieldError

    if only is not None and only not in PARTS:
        raise FieldError("only", f"{only!r} is not one of {', '.join(PARTS)}")
    for line in compile_kernels(PARTS if only is None else (only,)):
        console.print(line, markup=False, highlight=False)


@app.command("dashboard")
@one_line_errors
def dashboard_cmd(
    mqtt: Annotated[
        str,
        typer.Option(
            "--mqtt",
            help="The broker and the prefix the monitors publish under: "
            "mqtt://[USER@]HOST[:PORT]/PREFIX (password: THERMODEPTH_MQTT_PASSWORD or "
            "--password-file).",
        ),
    ],
    listen: Annotated[
        str, typer.Option(help="HOST:PORT to serve on (beyond this machine: a token).")
    ] = "127.0.0.1:8090",
    token_file: Annotated[
        Path | None,
        typer.Option(help="A file whose first line is the token (else THERMODEPTH_HTTP_TOKEN)."),
    ] = None,
    tls_cert: Annotated[Path | None, typer.Option(help="PEM certificate: HTTPS.")] = None,
    tls_key: Annotated[Path | None, typer.Option(help="PEM key of --tls-cert.")] = None,
    data: Annotated[
        Path, typer.Option(help="Where its events and their snapshots are kept.")
    ] = Path("thermodepth-dashboard"),
    password_file: Annotated[
        Path | None, typer.Option(help="A file whose first line is the broker's password.")
    ] = None,
    ca_file: Annotated[Path | None, typer.Option(help="The CA of an mqtts:// broker.")] = None,
) -> None:
    """One screen for many monitors (docs/monitor.md): the dashboard's pages for every rig
    that publishes under the broker's prefix (status, readings, alarms, events and live
    pictures), acknowledging through the rigs' command topics; no access to the monitors'
    disks. Runs until SIGTERM or Ctrl-C."""
    from ..app.monitor import run_dashboard
    from ..monitor.config import HttpConfig
    from ..pipeline import MqttSettings

    http = HttpConfig(listen=listen, token_file=token_file, tls_cert=tls_cert, tls_key=tls_key)
    run_dashboard(mqtt, data, http, MqttSettings(password_file=password_file, ca_file=ca_file))
