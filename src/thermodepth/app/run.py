"""``thermodepth run``: fuse a stream into measurements, with the outputs the options ask for."""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from .. import sources
from ..calibration import Calibration
from ..errors import FieldError, check_count
from ..frames import parse_depth_mode
from ..pipeline import Pipeline, Settings
from ..session import RunResult, run_session
from ..sinks import MeasurementsSink, MqttSink, RecorderSink, Sink
from ..sinks.mqtt import MqttTarget
from ..sinks.snapshots import SnapshotSink
from ..sinks.viewer import check_viewer_options, viewer_sink
from ..sources.pairing import DEFAULT_MAX_SKEW_S

Warn = Callable[[str], None]
"""Where one-line warnings go (the command line prints them in yellow)."""


@dataclass(frozen=True)
class RunOptions:
    """What a run reads and where it writes.

    source: a source spec (``sim``, ``realsense+lepton``, ``recording:PATH``; see
    :func:`~thermodepth.sources.open_source`); settings: the settings YAML (None: defaults);
    frames: stop after so many pairs (None: at the source's end); out_dir: write the
    measurements there; record: also record everything into this new recording;
    max_skew_s: the pairing threshold (s); thermal_latency_s: subtracted from the Lepton's
    arrival times (s); mqtt: publish alarms, measurements and status to this broker
    (``mqtt://[USER@]HOST[:PORT]/PREFIX``; the settings' ``mqtt`` section says how);
    viewer / viewer_save / viewer_connect: show the run in rerun (a viewer spawned, an
    ``.rrd`` file, a running viewer's address; the settings' ``viewer`` section says how);
    snapshots: with out_dir, an overlay PNG and a PLY every so many frames and at every alarm;
    depth_mode, thermal_camera: the cameras (:class:`SourceChoice`); foxglove: serve the run
    live to Foxglove on this ``HOST:PORT`` (:mod:`~thermodepth.sinks.foxglove`).
    """

    source: str = "sim"
    settings: Path | None = None
    frames: int | None = None
    out_dir: Path | None = None
    record: Path | None = None
    max_skew_s: float = DEFAULT_MAX_SKEW_S
    thermal_latency_s: float = 0.0
    mqtt: str | None = None
    viewer: bool = False
    viewer_save: Path | None = None
    viewer_connect: str | None = None
    snapshots: int | None = None
    depth_mode: str | None = None
    thermal_camera: str | None = None
    foxglove: str | None = None

    def check(self) -> None:
        """One FieldError for an option that cannot be."""
        check_count("frames", self.frames)
        check_count("snapshots", self.snapshots)
        check_source(self)
        if self.mqtt is not None:
            MqttTarget.parse(self.mqtt)
        check_viewer_options(self.viewer, self.viewer_save, self.viewer_connect)
        if self.foxglove is not None:
            from ..sinks.foxglove import parse_address

            parse_address(self.foxglove)
        if self.snapshots is not None and self.out_dir is None:
            raise FieldError("snapshots", "snapshots go into the measurements folder: give --out")


class SourceChoice(Protocol):
    """What every command that opens a source is told: the spec, the pairing of live cameras
    (``max_skew_s``, ``thermal_latency_s``: seconds) and the cameras' modes: ``depth_mode``
    (``WxH[@FPS]``, a RealSense's or the simulator's; None: the camera's recommended one) and
    ``thermal_camera`` (the simulated one; None: the Lepton 3)."""

    @property
    def source(self) -> str: ...
    @property
    def max_skew_s(self) -> float: ...
    @property
    def thermal_latency_s(self) -> float: ...
    @property
    def depth_mode(self) -> str | None: ...
    @property
    def thermal_camera(self) -> str | None: ...


def check_source(choice: SourceChoice) -> None:
    """The parts of a source choice that can be checked before any camera starts: both
    durations >= 0 and a depth mode that reads as one (FieldError otherwise)."""
    for name in ("max_skew_s", "thermal_latency_s"):
        if not getattr(choice, name) >= 0:
            raise FieldError(name, "must be >= 0")
    if choice.depth_mode is not None:
        parse_depth_mode(choice.depth_mode)


def open_choice(
    choice: SourceChoice,
    calibration: Calibration | None,
    warn: Warn | None,
    *,
    frames: int | None = None,
    with_ir: bool = False,
    pairs: bool = True,
) -> sources.Source:
    """:func:`~thermodepth.sources.open_source` of what ``choice`` says; with ``pairs`` a
    source without them (one camera) is refused with one line, and closed."""
    src = sources.open_source(
        choice.source,
        calibration,
        frames=frames,
        max_skew_s=choice.max_skew_s,
        with_ir=with_ir,
        thermal_latency_s=choice.thermal_latency_s,
        warn=warn,
        depth_mode=choice.depth_mode,
        thermal_camera=choice.thermal_camera,
    )
    if pairs:
        try:
            src.require_pairs()
        except BaseException:
            src.close()
            raise
    return src


def spec_of(text: str) -> str:
    """A source spec as it is (``folder:PATH``, ``sim``, ``realsense+lepton``, ...), or a
    path taken as a recording (``recording:PATH``)."""
    kind, arg = sources.split_spec(text)[0]
    named = kind in sources.SOURCE_KINDS and (arg or kind == "sim" or "+" in text)
    return text if named else f"recording:{text}"


def never_ends(spec: str) -> bool:
    """True for a source that gives pairs for ever (the simulator), which a session must be
    told when to stop."""
    return sources.split_spec(spec)[0][0] == "sim"


SinkBuilder = Callable[[RunOptions, Settings, Warn | None], Sink | None]

SINK_BUILDERS: list[SinkBuilder] = [
    lambda o, s, w: MeasurementsSink(o.out_dir) if o.out_dir is not None else None,
    lambda o, s, w: RecorderSink(o.record) if o.record is not None else None,
    lambda o, s, w: MqttSink(o.mqtt, s.mqtt, w) if o.mqtt is not None else None,
    lambda o, s, w: viewer_sink(o.viewer, o.viewer_save, o.viewer_connect, s.viewer, w),
    lambda o, s, w: (
        SnapshotSink(o.out_dir, o.snapshots, s.viewer.fixed_range_c)
        if o.snapshots is not None and o.out_dir is not None
        else None
    ),
    lambda o, s, w: foxglove_sink(o.foxglove) if o.foxglove is not None else None,
]
"""The sinks a run's options ask for, one builder each (None: not asked for), from the
options, the settings and where warnings go."""


def foxglove_sink(address: str) -> Sink:
    """The run as ROS messages to a live Foxglove server on ``address``; the temperature on
    the depth grid as the 16UC1 centikelvin image only: the server's clients are Foxglove
    apps, which show a 32FC1 image white."""
    from ..sinks.bag import BagSink
    from ..sinks.foxglove import MAX_HZ, FoxgloveWriter

    return BagSink(
        None, cloud_points=50_000, open_writer=lambda: FoxgloveWriter(address), max_hz=MAX_HZ,
        temperature_image="16UC1",
    )  # fmt: skip


def provenance(settings_path: Path | None, settings: Settings) -> dict[str, Any]:
    """What a recording made by a run stores of the pipeline: the settings file's path and
    text, and the compensation model's path and SHA-256."""
    out: dict[str, Any] = {"settings_file": None, "settings_yaml": None}
    if settings_path is not None:
        out["settings_file"] = str(settings_path)
        out["settings_yaml"] = Path(settings_path).read_text(encoding="utf-8")
    if settings.compensation is not None:
        out["compensation_model"] = str(settings.compensation)
        out["compensation_sha256"] = hashlib.sha256(
            Path(settings.compensation).read_bytes()
        ).hexdigest()
    return {"pipeline": out}


def run(options: RunOptions, sinks: Sequence[Sink] = (), warn: Warn | None = None) -> RunResult:
    """Check the options and every output (before any camera starts), open the source and
    the pipeline, then :func:`~thermodepth.session.run_session` with the sinks the options
    ask for followed by ``sinks`` (the source is closed in every case)."""
    options.check()
    settings = Settings.load(options.settings) if options.settings else Settings()
    cal = Calibration.load(settings.calibration) if settings.calibration else None
    outputs = [s for build in SINK_BUILDERS if (s := build(options, settings, warn)) is not None]
    all_sinks = [*outputs, *sinks]
    for sink in all_sinks:
        sink.check()
    src = open_choice(options, cal, warn, frames=options.frames)
    try:
        # the source's calibration, else the settings'; Pipeline refuses when neither has one
        pipeline = Pipeline(settings, src.calibration or cal, warn=warn)
        recorded = provenance(options.settings, settings)
    except BaseException:
        src.close()
        raise
    return run_session(src, pipeline, frames=options.frames, sinks=all_sinks, provenance=recorded)
