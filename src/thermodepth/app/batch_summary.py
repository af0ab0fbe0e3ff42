"""A batch's summary: one row per recording from its measurement files (frames, time span,
alarms by rule, the hottest reading and where, hotspots, flags), as ``summary.parquet``,
``summary.csv`` and ``summary.md`` with one plot (``summary.png``: the hottest reading over
time, per recording)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ..alarms import RAISED
from ..csvfile import write_csv
from ..io.measurements import FILES
from ..plotting import distinct_styles, pyplot, save_figure

COLUMNS = (
    "recording",
    "source",
    "status",
    "frames",
    "shutter_frames",
    "start_s",
    "end_s",
    "span_s",
    "alarms",
    "hotspots",
    "hottest_c",
    "hottest_frame",
    "hottest_time_s",
    "hottest_x_m",
    "hottest_y_m",
    "hottest_z_m",
    "flags",
)
"""The summary's columns; then one ``alarms:<rule>`` column per alarm rule (alarms raised)."""


def read_jsonl(path: Path) -> list[dict[str, Any]]:
    """The records of a JSON-lines file (a recording's ``measurements.jsonl``: its frames;
    ``alarms.jsonl``: its events)."""
    return [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines()]


def recording_row(
    name: str, source: str, folder: Path, rules: list[str], frames: list[dict[str, Any]]
) -> dict[str, Any]:
    """The summary row of a recording measured into ``folder``: times are the thermal
    frames' (s, host clock); the hottest reading is the hottest hotspot of any frame (C, its
    centroid in the depth camera's frame, m); flags: the OR of every hotspot's and ROI's."""
    events = read_jsonl(folder / FILES[1])
    raised = [e for e in events if e["event"] in RAISED]
    times = [f["thermal_time_s"] for f in frames]
    hottest: dict[str, Any] | None = None
    hottest_frame: dict[str, Any] | None = None
    flags = 0
    n_hotspots = 0
    for f in frames:
        n_hotspots += len(f["hotspots"])
        for item in [*f["hotspots"], *f["rois"]]:
            flags |= int(item.get("flags") or 0)
        if f["hotspots"] and (hottest is None or f["hotspots"][0]["max_c"] > hottest["max_c"]):
            hottest, hottest_frame = f["hotspots"][0], f
    x, y, z = hottest["centroid_m"] if hottest else (None, None, None)
    row: dict[str, Any] = {
        "recording": name,
        "source": source,
        "status": "ok",
        "frames": len(frames),
        "shutter_frames": sum(bool(f["in_ffc"]) for f in frames),
        "start_s": min(times) if times else None,
        "end_s": max(times) if times else None,
        "span_s": (max(times) - min(times)) if times else None,
        "alarms": len(raised),
        "hotspots": n_hotspots,
        "hottest_c": hottest["max_c"] if hottest else None,
        "hottest_frame": hottest_frame["frame"] if hottest_frame else None,
        "hottest_time_s": hottest_frame["thermal_time_s"] if hottest_frame else None,
        "hottest_x_m": x,
        "hottest_y_m": y,
        "hottest_z_m": z,
        "flags": flags,
    }
    for rule in rules:
        row[f"alarms:{rule}"] = sum(e["rule"] == rule for e in raised)
    return row


def failed_row(name: str, source: str, message: str, rules: list[str]) -> dict[str, Any]:
    """The row of a recording that could not be measured: its status is the error line."""
    row: dict[str, Any] = dict.fromkeys((*COLUMNS, *(f"alarms:{r}" for r in rules)))
    row.update(recording=name, source=source, status=f"failed: {message}")
    return row


def write_tables(
    out: Path, names: list[str], sources: tuple[str, ...], failed: dict[str, str], rules: list[str]
) -> list[dict[str, Any]]:
    """Write the summary of the recordings ``names`` (from ``sources``) in ``out``; a
    recording in ``failed``, or without a complete folder, gets a failed row."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    rows, series = [], {}
    for name, source in zip(names, sources, strict=True):
        folder = out / name
        if name in failed or not folder.is_dir():
            why = failed.get(name, "no complete results (the batch was stopped)")
            rows.append(failed_row(name, source, why, rules))
            continue
        frames = read_jsonl(folder / FILES[0])
        rows.append(recording_row(name, source, folder, rules, frames))
        series[name] = [
            (f["thermal_time_s"], f["hotspots"][0]["max_c"]) for f in frames if f["hotspots"]
        ]
    columns = [*COLUMNS, *(f"alarms:{r}" for r in rules)]
    table = pa.Table.from_pylist(rows, schema=_schema(pa, columns))
    pq.write_table(table, out / "summary.parquet")
    write_csv(out / "summary.csv", columns, rows)
    plot_hottest(series, out / "summary.png")
    (out / "summary.md").write_text(_markdown(rows), encoding="utf-8")
    return rows


def _schema(pa: Any, columns: list[str]) -> Any:
    """Parquet types: text, whole numbers, and floats (nulls where unknown)."""
    text = {"recording", "source", "status"}
    whole = {"frames", "shutter_frames", "alarms", "hotspots", "hottest_frame", "flags"}
    return pa.schema(
        [
            (
                c,
                pa.string()
                if c in text
                else pa.int64()
                if c in whole or ":" in c
                else pa.float64(),
            )
            for c in columns
        ]
    )


def plot_hottest(series: dict[str, list[tuple[float, float]]], path: Path) -> Path:
    """The hottest hotspot's max (C) over time since each recording's first hot frame,
    one line per recording, told apart by colour and marker."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.0, 4.0))
    for (name, points), (color, marker) in zip(
        series.items(), distinct_styles(len(series)), strict=True
    ):
        if not points:
            continue
        t0 = points[0][0]
        t = [p[0] - t0 for p in points]
        ax.plot(t, [p[1] for p in points], marker=marker, color=color, markersize=3,
                linewidth=1, markevery=max(1, len(t) // 20), label=name)  # fmt: skip
    ax.set_xlabel("time since the recording's first hotspot (s)")
    ax.set_ylabel("hottest hotspot max (C)")
    ax.set_title("Hottest reading over time, per recording", fontsize=10)
    ax.grid(True, alpha=0.3)
    if any(series.values()):
        ax.legend(fontsize=8)
    else:
        ax.text(0.5, 0.5, "no hotspot above the threshold", ha="center", transform=ax.transAxes)
    return save_figure(fig, path)


def _markdown(rows: list[dict[str, Any]]) -> str:
    """summary.md: the table's main columns and the plot."""
    keep = ("recording", "status", "frames", "span_s", "alarms", "hotspots", "hottest_c",
            "hottest_time_s", "flags")  # fmt: skip
    lines = [
        "# Batch summary",
        "",
        f"{len(rows)} recordings, {sum(r['status'] == 'ok' for r in rows)} measured. "
        "All columns: summary.csv, summary.parquet.",
        "",
        "| " + " | ".join(keep) + " |",
        "|" + "---|" * len(keep),
    ]
    for r in rows:
        cells = [_cell(r[k]) for k in keep]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "![hottest reading over time](summary.png)", ""]
    return "\n".join(lines)


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.2f}"
    return str(value).replace("|", "\\|")
