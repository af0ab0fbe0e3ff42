"""``thermodepth emissivity``: a target ROI's emissivity from a reference ROI on a live rig or a
recording (:mod:`thermodepth.emissivity`), written into the settings file on request."""

from __future__ import annotations

import os
from dataclasses import dataclass
from itertools import islice
from pathlib import Path

import yaml

from ..calibration import Calibration
from ..emissivity import EmissivityEstimate, check_reference, estimate_emissivity
from ..errors import FieldError, InputError, check_count, read_text
from ..pipeline import Settings
from ..sources.pairing import DEFAULT_MAX_SKEW_S
from .run import Warn, check_source, open_choice, spec_of

DECIMALS = 3
"""The emissivity written into the settings is rounded to so many decimals (far below any
estimate's uncertainty)."""


@dataclass(frozen=True)
class EmissivityOptions:
    """What ``thermodepth emissivity`` reads: ``source`` (a source spec or a recording's
    path), ``settings`` (a YAML holding both ROIs), the ``reference`` and ``target`` ROIs'
    names, the reference's emissivity and its stated ``tolerance`` (+-), ``frames`` to use;
    ``write``: write the result into the settings file's target ROI. The source's pairing
    and cameras as :class:`~thermodepth.app.run.SourceChoice`."""

    source: str
    settings: Path
    reference: str
    target: str
    reference_emissivity: float
    tolerance: float = 0.02
    frames: int = 10
    write: bool = False
    max_skew_s: float = DEFAULT_MAX_SKEW_S
    thermal_latency_s: float = 0.0
    depth_mode: str | None = None
    thermal_camera: str | None = None


@dataclass(frozen=True)
class EmissivityResult:
    """The estimate and, when written, the one line saying what changed in the settings."""

    estimate: EmissivityEstimate
    written: str | None


def measure_emissivity(options: EmissivityOptions, warn: Warn | None = None) -> EmissivityResult:
    """Read ``options.frames`` pairs from the source, estimate the target's emissivity
    (:func:`~thermodepth.emissivity.estimate_emissivity`) and, with ``write``, set it in the
    settings file (:func:`write_roi_emissivity`)."""
    check_count("frames", options.frames)
    check_reference(options.reference_emissivity, options.tolerance)
    check_source(options)
    settings = Settings.load(options.settings)
    by_name = {r.name for r in settings.rois}
    for option, name in (("reference", options.reference), ("target", options.target)):
        if name not in by_name:
            raise FieldError(option, f"{name!r} is no ROI of {settings.where}")
    cal = Calibration.load(settings.calibration) if settings.calibration else None
    choice = _Choice(options, spec_of(options.source))
    with open_choice(choice, cal, warn, frames=options.frames) as src:
        calibration = src.calibration or cal
        if calibration is None:
            raise InputError(
                "no calibration: give one in the settings (calibration: FILE) or use a "
                "source that carries one"
            )
        pairs = list(islice(src.pairs(), options.frames))
    estimate = estimate_emissivity(
        settings,
        calibration,
        pairs,
        options.reference,
        options.target,
        options.reference_emissivity,
        options.tolerance,
    )
    written = None
    if options.write:
        written = write_roi_emissivity(options.settings, options.target, estimate.emissivity)
    return EmissivityResult(estimate, written)


@dataclass(frozen=True)
class _Choice:
    options: EmissivityOptions
    source: str

    @property
    def max_skew_s(self) -> float:
        return self.options.max_skew_s

    @property
    def thermal_latency_s(self) -> float:
        return self.options.thermal_latency_s

    @property
    def depth_mode(self) -> str | None:
        return self.options.depth_mode

    @property
    def thermal_camera(self) -> str | None:
        return self.options.thermal_camera


def write_roi_emissivity(path: Path, roi: str, emissivity: float) -> str:
    """Set ``emissivity`` (rounded to :data:`DECIMALS`) on the ROI named ``roi`` of a settings
    YAML, the rest of the file's text (comments, order, style) as it was: the ROI's
    ``emissivity:`` value replaced, or the key added as its first. The new text is validated
    as settings before it replaces the file (atomically). Returns one line saying what
    changed."""
    text = read_text(path)
    value = f"{round(emissivity, DECIMALS):.{DECIMALS}f}"
    try:
        root = yaml.compose(text)
    except yaml.YAMLError as exc:
        raise InputError(f"{path}: not valid YAML: {str(exc).splitlines()[0]}") from None
    node = _roi_node(root, roi, path)
    old = next((v for k, v in node.value if k.value == "emissivity"), None)
    if old is not None:
        start, end = old.start_mark.index, old.end_mark.index
        new_text = text[:start] + value + text[end:]
        what = f"{path}: roi {roi!r}: emissivity {old.value} -> {value}"
    else:
        first = node.value[0][0].start_mark
        sep = ", " if node.flow_style else "\n" + " " * first.column
        new_text = text[: first.index] + f"emissivity: {value}{sep}" + text[first.index :]
        what = f"{path}: roi {roi!r}: emissivity {value} added"
    tmp = path.with_name(f".{path.name}.emissivity")
    tmp.write_text(new_text, encoding="utf-8")
    try:
        written = Settings.load(tmp)
        got = next(r.emissivity for r in written.rois if r.name == roi)
        if got != float(value):
            raise InputError(f"{path}: roi {roi!r}: the edit did not take (reads {got})")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return what


def _roi_node(root: yaml.Node | None, roi: str, path: Path) -> yaml.MappingNode:
    """The mapping node of the ROI named ``roi`` in a settings document."""
    if isinstance(root, yaml.MappingNode):
        for key, value in root.value:
            if key.value == "rois" and isinstance(value, yaml.SequenceNode):
                for item in value.value:
                    if isinstance(item, yaml.MappingNode) and any(
                        k.value == "name" and v.value == roi for k, v in item.value
                    ):
                        return item
    raise FieldError("target", f"{path} has no ROI named {roi!r} under rois")
