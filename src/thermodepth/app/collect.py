"""``thermodepth collect-sweep``: the rows of the paper's Tables 1-5 from a session in front of
a reference plate (live cameras or a recording), into the sweep CSV ``fit-compensation``
reads."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from .. import sources
from ..calibration import Calibration
from ..collect import CollectStats
from ..conditions import Conditions
from ..errors import FieldError, InputError, check_count
from ..progress import SILENT, Reporter
from ..session import StreamResult, stream_session
from ..sinks.sweep import SweepRequest, SweepSink
from ..sources.pairing import DEFAULT_MAX_SKEW_S
from ..target import NEAR_REFERENCE_C, TargetSpec
from .run import Warn, check_source, never_ends, open_choice


@dataclass(frozen=True)
class CollectOptions:
    """What to read and where the rows go.

    source: a source spec (``realsense+lepton``, ``recording:PATH``, ``sim``); out: the sweep
    CSV; reference_temp_c: the plate's true temperature (contact thermometer), C (required);
    target: ``auto``, ``rect:U0,V0,U1,V1`` or ``depth-range:NEAR,FAR``
    (:class:`~thermodepth.target.TargetSpec`); average: readings per row; conditions:
    emissivity, air temperature and humidity; append: add rows to an existing CSV;
    calibration: the rig's calibration file (a recording keeps its own); frames: stop after
    so many pairs; max_skew_s, thermal_latency_s: pairing of live cameras (s); depth_mode,
    thermal_camera: the cameras (:class:`~.run.SourceChoice`).
    """

    source: str
    out: Path
    reference_temp_c: float | None
    target: str = "auto"
    average: int = 1
    conditions: Conditions = field(default_factory=Conditions)
    append: bool = False
    calibration: Path | None = None
    frames: int | None = None
    max_skew_s: float = DEFAULT_MAX_SKEW_S
    thermal_latency_s: float = 0.0
    depth_mode: str | None = None
    thermal_camera: str | None = None

    def check(self) -> TargetSpec:
        """One FieldError for an option that cannot be; the parsed target."""
        if self.reference_temp_c is None:
            raise FieldError(
                "reference_temp_c",
                "give the plate's true temperature (C), as its contact thermometer reads it",
            )
        check_count("average", self.average)
        check_count("frames", self.frames)
        if self.frames is None and never_ends(self.source):
            raise FieldError("source", "sim never ends: give frames")
        check_source(self)
        kind = sources.split_spec(self.source)[0][0]
        if self.calibration is None and kind not in ("recording", "sim", "folder"):
            raise FieldError(
                "calibration",
                f"{self.source} needs the rig's calibration file (thermodepth calibrate) to "
                "register depth to thermal pixels",
            )
        return TargetSpec.parse(self.target)


@dataclass(kw_only=True)
class CollectResult(StreamResult):
    """How the collection went (:class:`~thermodepth.session.StreamResult`): the sweep CSV,
    the rows written and what the collector saw."""

    out: Path
    rows: int = 0
    stats: CollectStats = field(default_factory=CollectStats)


def collect_sweep(
    options: CollectOptions,
    reporter: Reporter = SILENT,
    warn: Warn | None = None,
    say: Warn | None = None,
) -> CollectResult:
    """Check the options and the output (before any camera starts), open the source and
    turn its pairs into sweep rows (:class:`~thermodepth.sinks.sweep.SweepSink`), each on disk
    as it is made. ``say`` gets the lines on the target (found, lost, moved), ``warn`` the
    source's warnings. A session in which the target was never found raises an InputError
    after an overlay of the last frame is written (nothing else is written)."""
    target = options.check()
    assert options.reference_temp_c is not None
    request = SweepRequest(target, options.reference_temp_c, options.conditions, options.average)
    sink = SweepSink(options.out, request, options.append, say)
    sink.check()
    cal = Calibration.load(options.calibration) if options.calibration else None
    src = open_choice(options, cal, warn, frames=options.frames)
    result = CollectResult(out=options.out, pairing=src.pairing)
    try:
        stream_session(
            src,
            [sink],
            result,
            frames=options.frames,
            calibration=cal,
            reporter=reporter,
            description=f"collecting {src.name}",
        )
    except InputError as exc:
        if not sink.writer.rows or isinstance(exc, FieldError):
            raise
        raise InputError(
            f"{exc}; {options.out} keeps the {sink.writer.rows} rows before it"
        ) from None
    result.rows, result.stats = sink.writer.rows, sink.stats
    if result.rows == 0 and sink.collector is not None:
        _never_found(sink, src.name)
    return result


def _never_found(sink: SweepSink, source: str) -> None:
    """The one line for a session without a row, after an overlay of what the last frame
    showed (when there was a frame with the shutter open)."""
    from ..figures import plot_target

    assert sink.collector is not None
    s, r = sink.stats, sink.request
    where = ""
    if sink.collector.last_temp_c is not None:
        path = plot_target(
            sink.collector.last_temp_c,
            None,
            f"the last frame: no target {r.target} near {r.reference_temp_c:g} C",
            sink.overlay_path("none"),
        )
        where = f"; the last frame is drawn in {path}"
    hint = (
        f" (a flat region of uniform temperature within {NEAR_REFERENCE_C:g} C of "
        f"{r.reference_temp_c:g} C); "
        "check --reference-temp-c and --emissivity, or choose it with rect:U0,V0,U1,V1 or "
        "depth-range:NEAR,FAR"
        if r.target.kind == "auto"
        else ""
    )
    raise InputError(
        f"{source}: the target {r.target} was never found in {s.pairs} pairs "
        f"({s.ffc_pairs} in FFC){hint}; no rows written{where}"
    )
