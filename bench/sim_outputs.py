"""What the simulator produces, recorded for fixed seeds, to check that a change to it (a
faster kernel) leaves its outputs as they were.

    python -m bench.sim_outputs record before.npz [--full]
    python -m bench.sim_outputs compare before.npz after.npz

``record`` runs every path of the simulator on small cases (board sessions, target captures,
the ``sim`` source, short walks, protocol and sweep, ground truth, noise-free renders of
every scene and camera) and saves each output array under a name; ``--full`` adds the
new-rig guide's board session (10 poses, seed 1). ``compare`` says, per name, whether the
arrays are identical bit for bit (NaN where NaN) and, where not, how many values differ and
by how much. Not a test: a tool for changing the simulator's inner workings.
"""

from __future__ import annotations

import json
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from thermodepth.board import BoardSpec
from thermodepth.camera import RigidTransform
from thermodepth.frames import Match
from thermodepth.sim import Rig, camera_pose, plate_scene
from thermodepth.sim.protocols import (
    ProtocolConfig,
    SweepConfig,
    simulate_board_session,
    simulate_protocol,
    simulate_sweep,
    simulate_targets,
)
from thermodepth.sim.scene import board_pattern, occlusion_scene, target_scene, wall_scene
from thermodepth.sim.walkaround import WalkConfig, machine_scene, room_scene, simulate_walkaround

Outputs = dict[str, NDArray[Any]]

CHECKER = BoardSpec.parse("checkerboard:9x6", 0.03)
CIRCLES = BoardSpec.parse("circles:4x11", 0.02)


def _store(path: Path, prefix: str) -> Outputs:
    """Every array of a zarr store, and its attributes (but the creation time) as JSON."""
    import zarr

    group = zarr.open_group(str(path), mode="r")
    out: Outputs = {}
    attrs = {k: v for k, v in group.attrs.asdict().items() if k != "created_utc"}
    out[f"{prefix}/attrs"] = np.frombuffer(json.dumps(attrs, sort_keys=True).encode(), np.uint8)
    for name, member in group.members(max_depth=None):
        if isinstance(member, zarr.Array):
            out[f"{prefix}/{name}"] = np.asarray(member[...])
    return out


def _images(paths: Iterator[Path], prefix: str) -> Outputs:
    out: Outputs = {}
    for p in paths:
        image = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        assert image is not None, p
        out[f"{prefix}/{p.name}"] = image
    return out


def _renders(name: str, rig: Rig) -> Outputs:
    """A rig's noise-free renders at its pose: the thermal aperture radiance, the depth
    camera's hits and IR albedo."""
    views = rig._depth_views(rig.pose)
    out: Outputs = {f"{name}/aperture": rig.aperture}
    for field in ("z_m", "rect", "s_m", "q_m", "range_m"):
        out[f"{name}/hits_{field}"] = getattr(views.hits, field)
    out[f"{name}/shadow"] = views.shadow
    if views.ir_albedo is not None:
        out[f"{name}/ir_albedo"] = views.ir_albedo
    return out


def _truth(name: str, rig: Rig) -> Outputs:
    t = rig.truth()
    return {f"{name}/{k}": v for k, v in t.__dict__.items() if isinstance(v, np.ndarray)}


def record(full: bool) -> Outputs:
    out: Outputs = {}
    tmp = Path(tempfile.mkdtemp(prefix="sim-outputs-"))
    # board sessions (a moving board, IR) and target captures
    sessions = [
        ("session-checker", CHECKER, "bare", None, 3, 1),
        ("session-circles-mask", CIRCLES, "mask", None, 2, 2),
        ("session-p2pro-plate", CHECKER, "plate", "p2pro", 2, 3),
    ]
    if full:
        sessions.append(("session-guide", CHECKER, "bare", None, 10, 1))
    for name, board, style, cam, poses, seed in sessions:
        path = simulate_board_session(
            tmp / f"{name}.zarr", board, poses, seed, style=style, camera=cam
        )
        out |= _store(path, name)
    targets = [
        ("targets-checker", CHECKER, "bare", "counts", None, None, 3),
        ("targets-circles-plate", CIRCLES, "plate", "counts", None, "848x480", 2),
        ("targets-mask-boson640", CHECKER, "mask", "ironbow", "boson640", None, 2),
        ("targets-lepton2.5", CIRCLES, "bare", "counts", "lepton2.5", "640x480", 2),
    ]
    for name, board, style, fmt, cam, depth, poses in targets:
        caps = simulate_targets(
            tmp / name,
            board,
            poses,
            seed=4,
            style=style,
            thermal_format=fmt,
            camera=cam,
            depth=depth,
        )
        out |= _images((p for pair in caps.pairs for p in pair), name)
    # the sim source: pairs of a held pose
    from thermodepth.sources import open_source

    for name, cam, ir in (("source", None, False), ("source-boson320-ir", "boson320", True)):
        src = open_source("sim", frames=12, thermal_camera=cam, with_ir=ir)
        for k, ev in enumerate(src.events()):
            assert isinstance(ev, Match)
            pair = ev.pair
            out[f"{name}/{k}/depth"] = pair.depth
            out[f"{name}/{k}/thermal"] = pair.thermal
            if pair.ir is not None:
                out[f"{name}/{k}/ir"] = pair.ir
            tel = {**pair.telemetry.__dict__, "t": (pair.depth_time_s, pair.thermal_time_s)}
            out[f"{name}/{k}/telemetry"] = np.frombuffer(repr(tel).encode(), np.uint8)
    # walks: directional and specular surfaces, the bolometer's memory, the truth
    for scene, cam in (("machine", None), ("room", "lepton3.5")):
        config = WalkConfig.of(scene, 1.0, 3, cam, "640x480")
        path = simulate_walkaround(tmp / f"walk-{scene}.zarr", config=config)
        out |= _store(path, f"walk-{scene}")
    # the paper's protocol and sweep
    protocol = ProtocolConfig(distances_m=(0.5, 2.0), pairs_per_distance=3, move_s=20.0)
    out |= _store(simulate_protocol(tmp / "protocol.zarr", protocol), "protocol")
    sweep = simulate_sweep(SweepConfig(distances_m=(0.5, 1.5), samples=200))
    out |= {f"sweep/{k}": v for k, v in sweep.columns.items()}
    # noise-free renders and truth of every scene
    identity = RigidTransform.identity("world", "depth")
    rigs = {
        "plate-chip": Rig(plate_scene(chip_temp_c=70.0), camera_pose(0.8, 10, 5), with_ir=True),
        "occlusion": Rig(occlusion_scene(), identity, with_ir=True),
        "wall": Rig(wall_scene(1.3), identity),
        "target-circles": Rig(
            target_scene(board_pattern(CIRCLES), style="mask"),
            camera_pose(0.5, -20, 15, 5),
            with_ir=True,
        ),
        "machine": Rig.of_cameras(
            machine_scene(), camera_pose(1.6, 30, 20, 0, (-0.2, -0.45, 0.0)), "boson320"
        ),
        "room": Rig.of_cameras(
            room_scene(), camera_pose(1.5, 10, 10, 0, (0.8, -1.0, 2.0)), "p2pro", "848x480"
        ),
    }
    for name, rig in rigs.items():
        out |= _renders(name, rig)
        out |= _truth(name, rig)
    return out


def compare(a: Outputs, b: Outputs) -> bool:
    """Print how ``b`` differs from ``a``; True if identical."""
    same = True
    for name in sorted(set(a) | set(b)):
        if name not in a or name not in b:
            print(f"{name}: only in {'before' if name in a else 'after'}")
            same = False
            continue
        x, y = a[name], b[name]
        if x.shape != y.shape or x.dtype != y.dtype:
            print(f"{name}: {x.dtype}{x.shape} vs {y.dtype}{y.shape}")
            same = False
            continue
        if np.array_equal(x, y, equal_nan=x.dtype.kind in "fc"):
            continue
        same = False
        if x.dtype.kind in "fc":
            bad = ~((x == y) | (np.isnan(x) & np.isnan(y)))
            diff = np.abs(x[bad] - y[bad])
            rel = diff / np.maximum(np.abs(x[bad]), 1e-300)
            print(
                f"{name}: {bad.sum()} of {x.size} differ, max abs {diff.max():.3g}, "
                f"max rel {rel.max():.3g}"
            )
        else:
            bad = x != y
            diff = np.abs(x[bad].astype(np.int64) - y[bad].astype(np.int64))
            print(f"{name}: {bad.sum()} of {x.size} differ, by at most {diff.max()}")
    print(f"{len(a)} outputs: {'identical' if same else 'DIFFERENT'}")
    return same


def main(args: list[str]) -> None:
    if args[:1] == ["record"]:
        out = record("--full" in args)
        np.savez_compressed(args[1], **out)  # type: ignore[arg-type]
        print(f"{len(out)} outputs in {args[1]}")
    elif args[:1] == ["compare"]:
        with np.load(args[1]) as a, np.load(args[2]) as b:
            sys.exit(0 if compare(dict(a), dict(b)) else 1)
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main(sys.argv[1:])
