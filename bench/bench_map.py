"""``thermodepth map`` on the simulated walk-arounds, both scenes, against their truth: the
trajectory (ATE), the geometry (Chamfer, F-score at 2 cm), the temperature on surfaces seen in
3 views or more (MAE and p95, the fused model against plain averaging of the same views),
coverage, the hotspots, and the time against the walk's own duration on this machine.

Each walk is simulated once (1280x720 depth at 30 fps, the Lepton 3 at 8.7 Hz; machine 30 s,
room 40 s, seed 0; kept in bench-out/walks/ for the next run), then mapped at 1 cm voxels with
depth odometry (15 of the 30 fps) and the default fusion. The settings give the ambient
temperature the thermographer measured in the scene (its air's) and the emissivity of most of
the surface seen (its paint's: :func:`scene_emissivity`); surfaces of another emissivity read
off by the difference, as they do with any one setting, and are left out of the temperature
errors (metrics.py). The rows' times are one run
each (median of one); numba's compile happens in an untimed 3 s walk first.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from thermodepth.app.map import MapOptions, build_map
from thermodepth.radiometry import ZERO_C_IN_K
from thermodepth.sim.walk_truth import WalkTruth, read_walk_truth
from thermodepth.sim.walkaround import simulate_walkaround

from .common import OUT, Timing, report

WALKS = {"machine": 30.0, "room": 40.0}


def walk(scene: str, duration_s: float, mode: str = "1280x720") -> Path:
    """The simulated walk, made once and kept."""
    path = OUT / "walks" / f"{scene}-{duration_s:g}s-{mode}.zarr"
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        simulate_walkaround(path, scene, duration_s, seed=0, depth=mode)
    return path


def scene_emissivity(truth: WalkTruth) -> float:
    """The emissivity of most of the surface the thermal camera saw: what a thermographer
    sets for a scene's paint (machine 0.94, room 0.93)."""
    samples = truth.seen_samples()[0][truth.seen_thermal >= 1]
    values, counts = np.unique(
        np.round(truth.emissivity[truth.nearest(samples)[2]], 3), return_counts=True
    )
    return float(values[np.argmax(counts)])


def mapped(path: Path, out: Path) -> dict[str, Any]:
    """The map of a walk with the scene's air and its paint's emissivity as the settings,
    its report."""
    truth = read_walk_truth(path)
    assert truth is not None
    settings = out.parent / f"{out.name}.yaml"
    settings.write_text(
        "radiometry:\n"
        f"  ambient_temp_c: {truth.ambient_temp_k - ZERO_C_IN_K:.2f}\n"
        f"  humidity_pct: {truth.relative_humidity * 100:.1f}\n"
        f"  emissivity: {scene_emissivity(truth)}\n"
    )
    return build_map(MapOptions(str(path), out, settings)).report


def _summary(r: dict[str, Any]) -> str:
    """One line of a map's figures against its truth."""
    t = r["against_truth"]
    g, temp = t["geometry"], t["temperature"]
    fused, plain = temp["fused"], temp["plain_average"]
    hot = ", ".join(
        f"{h['name']} {h.get('distance_m', float('nan')) * 100:.1f} cm "
        f"{h.get('peak_error_c', float('nan')):+.2f} C (eps {h.get('emissivity', '?')})"
        for h in t["hotspots"]
    )
    return (
        f"x{r['speed_vs_real_time']:.2f} real time; "
        f"ATE {t['trajectory']['rmse_m'] * 100:.2f} cm; "
        f"Chamfer {g['chamfer_m'] * 100:.2f} cm (accuracy {g['accuracy_m'] * 100:.2f}, "
        f"completeness {g['completeness_m'] * 100:.2f}); F-score@2cm {g['f_score']:.3f}; "
        f"coverage {t['coverage']:.1%}; temperature on {temp['vertices']} vertices: "
        f"MAE {fused.get('mae_c')} C / p95 {fused.get('p95_c')} C "
        f"(beyond bias {fused.get('mae_beyond_bias_c')} / {fused.get('p95_beyond_bias_c')}), "
        f"plain averaging {plain.get('mae_c')} / {plain.get('p95_c')}: "
        f"{temp.get('mae_lower_than_plain', float('nan')):.0%} lower; "
        f"hotspots (distance, peak error): {hot}; stages {r['seconds']}"
    )


def main() -> None:
    rows: list[Timing] = []
    notes: dict[str, object] = {}
    with tempfile.TemporaryDirectory() as tmp:
        mapped(walk("machine", 3.0, "848x480"), Path(tmp) / "warm")  # numba's compile
        for scene, duration_s in WALKS.items():
            out = Path(tmp) / scene
            r = mapped(walk(scene, duration_s), out)
            shutil.copy(out / "views.png", OUT / f"map_{scene}_views.png")
            (OUT / f"map_{scene}_report.json").write_text(json.dumps(r, indent=2))
            rows.append(
                Timing.of(f"{scene}: map of a {duration_s:g} s walk", [r["seconds"]["total"]])
            )
            notes[scene] = _summary(r)
    report("thermodepth map: simulated walk-arounds at 1 cm", rows, notes=notes)


if __name__ == "__main__":
    main()
