"""Measurement protocols on the simulated rig: the paper's sweep, calibration-target captures
and frame sets with ground truth, each written where users' tools expect them."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..board import BoardSpec
from ..calibration import Calibration
from ..camera import RigidTransform
from ..conditions import Conditions, Radiometry
from ..errors import InputError
from ..palettes import PALETTES, apply_palette
from ..progress import Progress
from ..radiometry import ZERO_C_IN_K
from ..sweep import COLUMNS, SweepTable
from .cameras import ThermalCamera, depth_mode, rig_calibration, thermal_camera
from .d435 import DepthCameraModel
from .lepton import FpaProfile, LeptonModel, LeptonSensor, ramp_fpa, steps_fpa
from .rig import Rig, Trajectory
from .scene import Scene, board_pattern, camera_pose, plate_scene, target_scene


@dataclass(frozen=True)
class SweepConfig:
    """The paper's protocol (section 4): a plate at known temperatures, read at several
    distances while the sensor's VOx temperature moves across a range.

    distances_m, plate_temps_c: the grid; vox_min_c / vox_max_c: FPA range, swept by a
    linear ramp over the samples (as a camera warming up), or vox_steps_c: FPA held at each
    of these temperatures in turn for an equal share of the samples; samples: readings per
    distance and
    plate temperature (the paper takes 6000); roi_half_px: ROI of (2 h + 1)^2 thermal pixels
    at the plate centre; emissivity: used by the radiometry of measured_temp_c;
    thermal_camera: the simulated camera (:data:`~.cameras.THERMAL_CAMERAS`; its readings are
    its own kind, counts or kelvin; one that tells no VOx temperature leaves vox_temp_c
    empty).
    """

    distances_m: tuple[float, ...] = (0.5, 1.0, 1.5, 2.0, 2.5)
    plate_temps_c: tuple[float, ...] = (39.0,)
    vox_min_c: float = 25.0
    vox_max_c: float = 40.0
    samples: int = 6000
    ambient_temp_c: float = 25.0
    humidity_pct: float = 50.0
    emissivity: float = 0.95
    roi_half_px: int = 2
    seed: int = 0
    vox_steps_c: tuple[float, ...] | None = None
    thermal_camera: str = "lepton3"

    def fpa_profile(self, fps: float) -> FpaProfile:
        """FPA temperature (K) over the ``samples`` frames of one distance."""
        duration_s = self.samples / fps
        k = ZERO_C_IN_K
        if self.vox_steps_c:
            n = len(self.vox_steps_c)
            return steps_fpa(
                [i * duration_s / n for i in range(n)], [t + k for t in self.vox_steps_c]
            )
        return ramp_fpa(self.vox_min_c + k, self.vox_max_c + k, duration_s)


def scaled_supersample(supersample: int, camera: ThermalCamera) -> int:
    """Rays per pixel side that keep about as many rays per image as ``supersample`` gives a
    160-wide camera (a 640-wide camera's pixels need fewer, an 80-wide one's more)."""
    return max(2, round(supersample * 160 / camera.width))


def plate_roi(rig: Rig, half: int) -> tuple[slice, slice]:
    """Thermal-pixel slices of a (2 half + 1)^2 ROI centred where the plate centre projects."""
    centre = rig.thermal_from_world.apply(rig.scene.rects[rig.scene.index("plate")].center_m)
    u, v = np.rint(rig.calibration.thermal.project(centre)).astype(int)
    return slice(v - half, v + half + 1), slice(u - half, u + half + 1)


def simulate_sweep(
    config: SweepConfig | None = None,
    lepton: LeptonModel | None = None,
    progress: Progress | None = None,
) -> SweepTable:
    """Readings of the plate-centre ROI (one row per frame; FFC frames left out).

    For each plate temperature and distance the noise-free aperture radiance is rendered once;
    each of ``samples`` frames then goes through the sensor (VOx effect, FPN, FFC, NETD,
    14-bit counts) on the ROI pixels, and the ROI mean reading is the radiometry of the
    counts with the plate's emissivity, without distance correction.
    """
    config = config or SweepConfig()
    lepton = lepton or thermal_camera(config.thermal_camera).sensor
    radiometry = Radiometry(
        Conditions(config.emissivity, config.ambient_temp_c, humidity_pct=config.humidity_pct),
        lepton.planck,
        output=lepton.output,
    )
    blocks: list[dict[str, NDArray[np.float64]]] = []  # one per plate temperature and distance
    rng = np.random.default_rng(config.seed)
    for plate_c in config.plate_temps_c:
        scene = plate_scene(
            plate_temp_c=plate_c,
            ambient_temp_c=config.ambient_temp_c,
            relative_humidity=config.humidity_pct / 100.0,
        )
        for d in config.distances_m:
            rig = Rig.of_cameras(scene, camera_pose(d), config.thermal_camera, lepton=lepton)
            roi = rig.aperture[plate_roi(rig, config.roi_half_px)]
            sensor = LeptonSensor(lepton, roi.shape, config.fpa_profile(lepton.fps), rng)
            counts, vox = [], []
            for i in range(config.samples):  # one at a time: the sensor carries state
                c, tel = sensor.read(i / lepton.fps, roi)
                if not tel.in_ffc:
                    counts.append(c)
                    vox.append(tel.fpa_temp_c)
            n = len(counts)
            stack = np.array(counts, dtype=np.float64).reshape(n, roi.size)
            blocks.append(
                {
                    "distance_m": np.full(n, d),
                    "vox_temp_c": np.array(vox),
                    "measured_temp_c": radiometry.celsius(stack).mean(axis=1),
                    "reference_temp_c": np.full(n, plate_c),
                    "ambient_temp_c": np.full(n, config.ambient_temp_c),
                    "humidity_pct": np.full(n, config.humidity_pct),
                    "emissivity": np.full(n, config.emissivity),
                    "raw_counts": stack.mean(axis=1),
                    "n": np.ones(n),
                }
            )
            if progress:
                progress(1)
    columns = {c: np.concatenate([np.empty(0)] + [b[c] for b in blocks]) for c in COLUMNS}
    return SweepTable(columns, source="simulated sweep")


def aggregate_by_vox(table: SweepTable, step_c: float = 1.0) -> SweepTable:
    """Average rows per (placement of the target, reference, VOx bin of ``step_c``), as the
    paper's Tables 1-5 do; rows are weighted by ``n`` and the result's ``n`` counts the
    readings in each row. vox_temp_c becomes the bin centre."""
    vox_bin = np.round(table["vox_temp_c"] / step_c) * step_c
    groups = table.distance_groups()[0]
    keys = np.stack([groups, table["reference_temp_c"], vox_bin], axis=1)
    uniq, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    weights = table.get("n", 1.0)
    total = np.bincount(inverse, weights=weights, minlength=len(uniq))
    out = {
        name: np.bincount(inverse, weights=col * weights, minlength=len(uniq)) / total
        for name, col in table.columns.items()
    }
    out["vox_temp_c"] = uniq[:, 2]
    out["n"] = total.astype(np.float64)
    return SweepTable(out, source=table.source)


# -- calibration-target captures ----------------------------------------------------------


def random_board_poses(
    board: BoardSpec,
    n: int,
    calibration: Calibration,
    rng: np.random.Generator,
    distance_m: tuple[float, float] = (0.4, 0.65),
    tilt_deg: tuple[float, float] = (15.0, 45.0),
    margin_px: float | None = None,
    edge_bias: float = 0.35,
) -> list[RigidTransform]:
    """``n`` poses ``depth_from_board`` of a board seen whole by both cameras, spread over the
    thermal image as a careful calibration would be.

    Each pose aims the board's centre at a random thermal pixel, pushed towards the image's
    edges (offset from the centre ~ sign(a) |a|^edge_bias, a uniform in -1..1, so that the
    board's corners reach the image corners where distortion is largest), at a distance
    drawn from ``distance_m`` (metres, along the thermal ray). The board is tilted by an angle
    drawn from ``tilt_deg`` in a random direction (tilt is what determines focal length and
    principal point; past ~50 degrees a 160x120 view of a 3 cm board is not detected) and
    rolled by up to 10 degrees. A pose is kept when the whole board (squares plus 7.5 %)
    projects inside both images by ``margin_px`` (None: 4 pixels of a 160-wide thermal image,
    scaled to its own). A board that fits in no pose is an InputError.
    """
    pattern = board_pattern(board)
    w, h = pattern.size_m
    corners = (
        np.array([[-w / 2, -h / 2, 0], [w / 2, -h / 2, 0], [w / 2, h / 2, 0], [-w / 2, h / 2, 0]])
        * 1.15
    )
    thermal = calibration.thermal
    margin = 4.0 * thermal.width / 160 if margin_px is None else margin_px
    depth_from_thermal = calibration.thermal_from_depth.inverse()
    poses: list[RigidTransform] = []
    batch = 512  # candidates drawn and tested at once (most fall partly outside a view)
    for _ in range(max(1, 20 * n)):
        d = rng.uniform(*distance_m, batch)
        tilt = np.radians(rng.uniform(*tilt_deg, batch))
        azimuth = rng.uniform(0.0, 2.0 * np.pi, batch)
        roll = np.radians(rng.uniform(-10.0, 10.0, batch))
        a = rng.uniform(-1.0, 1.0, (batch, 2))
        a = np.sign(a) * np.abs(a) ** edge_bias
        # tilt about the in-plane axis at `azimuth` (turn to it, tilt about x, turn back),
        # after a roll about the board's normal
        rot = _rot_z(azimuth) @ _rot_x(tilt) @ _rot_z(roll - azimuth)
        px = np.stack(
            [
                (thermal.width - 1) / 2 + a[:, 0] * thermal.width / 2,
                (thermal.height - 1) / 2 + a[:, 1] * thermal.height / 2,
            ],
            axis=-1,
        )
        centre = depth_from_thermal.apply(thermal.deproject(px, d))
        pts_d = np.einsum("bij,kj->bki", rot, corners) + centre[:, None, :]
        ok = np.ones(batch, dtype=bool)
        for intr, pts in (
            (calibration.depth, pts_d),
            (thermal, calibration.thermal_from_depth.apply(pts_d)),
        ):
            q = intr.project(pts)
            inside = (
                (q[..., 0] >= margin)
                & (q[..., 0] <= intr.width - 1 - margin)
                & (q[..., 1] >= margin)
                & (q[..., 1] <= intr.height - 1 - margin)
            )
            ok &= np.all(inside, axis=1)
        for i in np.flatnonzero(ok)[: n - len(poses)]:
            poses.append(RigidTransform(rot[i], centre[i], "depth", "board"))
        if len(poses) == n:
            return poses
    raise InputError(
        f"{board}: the board does not fit whole in both views at {distance_m[0]:g}-"
        f"{distance_m[1]:g} m; choose a smaller one (--board, --square-m)"
    )


def _rot_x(angle: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotations (..., 3, 3) about x by ``angle`` (...) radians."""
    c, s = np.cos(angle), np.sin(angle)
    o, i = np.zeros_like(c), np.ones_like(c)
    return np.stack([i, o, o, o, c, -s, o, s, c], axis=-1).reshape(*np.shape(c), 3, 3)


def _rot_z(angle: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotations (..., 3, 3) about z by ``angle`` (...) radians."""
    c, s = np.cos(angle), np.sin(angle)
    o, i = np.zeros_like(c), np.ones_like(c)
    return np.stack([c, -s, o, s, c, o, o, o, i], axis=-1).reshape(*np.shape(c), 3, 3)


@dataclass(frozen=True)
class TargetCaptures:
    """What :func:`simulate_targets` wrote: image pairs, the true calibration and poses."""

    pairs: list[tuple[Path, Path]]
    calibration_path: Path
    poses: list[RigidTransform]


def simulate_targets(
    out_dir: str | Path,
    board: BoardSpec,
    n_poses: int = 20,
    seed: int = 0,
    board_temp_c: float = 45.0,
    ambient_temp_c: float = 25.0,
    thermal_supersample: int = 8,
    progress: Progress | None = None,
    style: str = "bare",
    margin_m: float | None = None,
    thermal_format: str = "counts",
    camera: str | None = None,
    depth: str | None = None,
) -> TargetCaptures:
    """Heated-board captures for ``thermodepth calibrate``: ``poseNN_ir.png`` (8-bit IR of
    the depth camera) and ``poseNN_thermal.png`` per pose, plus ``truth_calibration.yaml``
    and ``truth_poses.json`` (``depth_from_board``).

    style: how the board is made (:data:`~thermodepth.sim.scene.BOARD_STYLES`), with a
    margin ``margin_m`` wide (None: the style's); thermal_format: ``counts`` (16-bit PNG of
    the raw counts) or a palette of :data:`~thermodepth.palettes.PALETTES` (8-bit RGB, as
    viewer tools save frames: :func:`~thermodepth.palettes.apply_palette`); camera, depth: the
    simulated thermal camera and depth mode (None: the Lepton 3, 1280x720), whose supersampling
    is scaled to keep about as many rays per image as a 160-wide camera's
    ``thermal_supersample``."""
    if thermal_format != "counts" and thermal_format not in PALETTES:
        raise ValueError(
            f"unknown thermal format {thermal_format!r}; choose counts or one of {PALETTES}"
        )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cam = thermal_camera(camera)
    cal = rig_calibration(cam, depth_mode(depth))
    rng = np.random.default_rng(seed)
    poses = random_board_poses(board, n_poses, cal, rng)
    lepton = replace(cam.sensor, supersample=scaled_supersample(thermal_supersample, cam))
    identity = RigidTransform.identity("world", "depth")
    pairs = []
    for i, pose in enumerate(poses):
        world_from_board = RigidTransform(pose.rotation, pose.translation_m, "world", "board")
        scene = target_scene(
            board_pattern(board), board_temp_c, ambient_temp_c, margin_m, world_from_board, style
        )
        rig = Rig(
            scene,
            identity,
            calibration=cal,
            lepton=lepton,
            depth_model=DepthCameraModel(fps=depth_mode(depth).fps),
            with_ir=True,
            seed=seed * 1000 + i,
            start_s=1.0,
        )  # after the start-up FFC
        frame = rig.frame()
        assert frame.ir is not None
        ir_path, th_path = out / f"pose{i:02d}_ir.png", out / f"pose{i:02d}_thermal.png"
        cv2.imwrite(str(ir_path), frame.ir)
        if thermal_format == "counts":
            cv2.imwrite(str(th_path), frame.thermal)
        else:  # RGB, written as OpenCV's BGR
            cv2.imwrite(str(th_path), apply_palette(frame.thermal, thermal_format)[..., ::-1])
        pairs.append((ir_path, th_path))
        if progress:
            progress(1)
    cal_path = out / "truth_calibration.yaml"
    cal.save(cal_path)
    (out / "truth_poses.json").write_text(
        json.dumps(
            [
                {"rotation": p.rotation.tolist(), "translation_m": p.translation_m.tolist()}
                for p in poses
            ],
            indent=1,
        )
    )
    return TargetCaptures(pairs, cal_path, poses)


# -- a board moved in front of the rig --------------------------------------------------------


def held_and_moved(
    poses: list[RigidTransform], hold_s: float, move_s: float, start_s: float = 0.0
) -> Trajectory:
    """A trajectory through ``poses`` (each ``world_from_depth``): each held for ``hold_s``,
    then moved to the next over ``move_s`` (rotation about one axis at a constant rate,
    translation in a straight line), as a person holds a board still, then moves it."""
    step = hold_s + move_s

    def pose_at(t: float) -> RigidTransform:
        k, into = divmod(max(t - start_s, 0.0), step)
        i = min(int(k), len(poses) - 1)
        if i == len(poses) - 1 or into <= hold_s:
            return poses[i]
        a, b = poses[i], poses[i + 1]
        f = (into - hold_s) / move_s
        rvec = cv2.Rodrigues(a.rotation.T @ b.rotation)[0].ravel()
        rot = a.rotation @ cv2.Rodrigues(rvec * f)[0]
        return RigidTransform(
            rot, (1 - f) * a.translation_m + f * b.translation_m, "world", "depth"
        )

    return pose_at


def session_frames(n_poses: int, hold_s: float, move_s: float, fps: float) -> int:
    """Thermal frames (pairs) of a board session: from the first pose's hold to the end of
    the last one's."""
    return int(((n_poses - 1) * (hold_s + move_s) + hold_s) * fps) + 1


def simulate_board_session(
    out: str | Path,
    board: BoardSpec,
    n_poses: int = 12,
    seed: int = 0,
    style: str = "bare",
    hold_s: float = 0.7,
    move_s: float = 0.35,
    ffc_interval_s: float = 180.0,
    board_temp_c: float = 45.0,
    progress: Progress | None = None,
    camera: str | None = None,
    depth: str | None = None,
) -> Path:
    """A recording of someone showing a board to the rig: ``n_poses`` poses spread as
    :func:`random_board_poses` spreads them, each held ``hold_s`` then moved to the next over
    ``move_s``, seen by both cameras (with the IR image), each at its own exposure time, so
    pairs taken while the board moves show it in two places. Only the depth frames that pair
    with a thermal frame are recorded (the ones ``capture-board`` reads). The recording's
    calibration is the rig's truth. ``ffc_interval_s``: the Lepton's timed shutter (FFC
    frames are recorded, marked as such); camera, depth: the simulated cameras (None: the
    Lepton 3, 1280x720)."""
    cam = thermal_camera(camera)
    cal = rig_calibration(cam, depth_mode(depth))
    rng = np.random.default_rng(seed)
    held = [p.inverse() for p in random_board_poses(board, n_poses, cal, rng)]  # board frame
    world = [RigidTransform(p.rotation, p.translation_m, "world", "depth") for p in held]
    trajectory = held_and_moved(world, hold_s, move_s, start_s=1.0)  # after power-on FFC
    rig = Rig(
        target_scene(board_pattern(board), board_temp_c, style=style),
        world[0],
        calibration=cal,
        lepton=replace(
            cam.sensor, supersample=scaled_supersample(8, cam), ffc_interval_s=ffc_interval_s
        ),
        depth_model=DepthCameraModel(fps=depth_mode(depth).fps),
        seed=seed,
        with_ir=True,
        start_s=1.0,
        trajectory=trajectory,
    )
    n_frames = session_frames(n_poses, hold_s, move_s, rig.lepton.fps)
    settings = {
        "source": "sim:board-session",
        "board": str(board),
        "style": style,
        "thermal_camera": cam.name,
        "depth_mode": depth_mode(depth).name,
    }
    return _record(out, rig, n_frames, settings, progress)


@dataclass(frozen=True)
class ProtocolConfig:
    """The paper's session (section 4) as a user runs it in front of the rig: the plate at
    each distance in turn while the camera warms up through its VOx range, recorded.

    distances_m: the plate's distances (Z, metres) in order; plate_temp_c: its temperature;
    vox_min_c / vox_max_c: the FPA warms from one to the other while the plate stays at a
    distance, and cools back while it is moved to the next (a sawtooth); pairs_per_distance:
    pairs recorded at each distance; interval_s: time between recorded pairs (the camera runs
    at 8.7 fps; a protocol keeps one pair every so often, so the warm-up takes minutes, as a
    real one does, and the Lepton's FFCs come as often as on a real camera); move_s: time the
    plate takes to reach the next distance (pairs are recorded while it moves);
    ambient_temp_c, humidity_pct: the room; seed: all randomness; thermal_camera,
    depth_mode: the simulated cameras (:mod:`.cameras`).
    """

    distances_m: tuple[float, ...] = (0.5, 1.0, 1.5, 2.0, 2.5)
    plate_temp_c: float = 39.0
    vox_min_c: float = 25.0
    vox_max_c: float = 40.0
    pairs_per_distance: int = 30
    interval_s: float = 20.0
    move_s: float = 60.0
    ambient_temp_c: float = 25.0
    humidity_pct: float = 50.0
    seed: int = 0
    thermal_camera: str = "lepton3"
    depth_mode: str = "1280x720"

    @property
    def hold_s(self) -> float:
        """Time the plate stays at each distance (s)."""
        return self.pairs_per_distance * self.interval_s

    @property
    def start_s(self) -> float:
        """Time of the first pair: after the power-on FFC."""
        return 1.0

    @property
    def pairs(self) -> int:
        """Pairs recorded: at the distances and while moving between them."""
        duration = len(self.distances_m) * self.hold_s + (len(self.distances_m) - 1) * self.move_s
        return round(duration / self.interval_s)

    def fpa_k(self, time_s: float) -> float:
        """The FPA temperature (K) at ``time_s``: up from vox_min_c to vox_max_c at each
        distance, down again while the plate moves."""
        k, into = divmod(max(time_s - self.start_s, 0.0), self.hold_s + self.move_s)
        if k >= len(self.distances_m) - 1:  # no move after the last distance: warm it stays
            into = min(into if k == len(self.distances_m) - 1 else np.inf, self.hold_s)
        lo, hi = self.vox_min_c, self.vox_max_c
        if into <= self.hold_s:
            c = lo + (hi - lo) * into / self.hold_s
        else:
            c = hi - (hi - lo) * (into - self.hold_s) / self.move_s
        return c + ZERO_C_IN_K


def simulate_protocol(
    out: str | Path, config: ProtocolConfig | None = None, progress: Progress | None = None
) -> Path:
    """Record the paper's session (:class:`ProtocolConfig`) on the simulated rig into the
    recording ``out``: pairs (depth and thermal, with telemetry; FFC frames included, marked
    as such), the rig's true calibration, and the config in the recording's settings."""
    from dataclasses import asdict

    config = config or ProtocolConfig()
    poses = [camera_pose(d) for d in config.distances_m]
    rig = Rig.of_cameras(
        plate_scene(
            plate_temp_c=config.plate_temp_c,
            ambient_temp_c=config.ambient_temp_c,
            relative_humidity=config.humidity_pct / 100.0,
        ),
        poses[0],
        config.thermal_camera,
        config.depth_mode,
        fpa=config.fpa_k,
        seed=config.seed,
        start_s=config.start_s,
        trajectory=held_and_moved(poses, config.hold_s, config.move_s, config.start_s),
        frame_interval_s=config.interval_s,
    )
    settings = {"source": "sim:protocol", "protocol": asdict(config)}
    return _record(out, rig, config.pairs, settings, progress)


def _record(
    out: str | Path, rig: Rig, n: int, settings: dict[str, Any], progress: Progress | None
) -> Path:
    """``n`` frame pairs of ``rig`` into a new recording at ``out``, with the rig's
    calibration and ``settings`` (its ``source`` named as the recording's)."""
    from ..io.recording import RecordingWriter  # the simulator stands below io

    with RecordingWriter(out, rig.calibration, settings, source=settings["source"]) as writer:
        for pair in rig.frames(n):
            writer.add_pair(pair)
            if progress:
                progress(1)
    return Path(out)


# -- frame sets with ground truth ---------------------------------------------------------

SCENES: dict[str, Callable[[], Scene]] = {
    "plate": plate_scene,
    "inspection": lambda: plate_scene(chip_temp_c=70.0),
}


def write_frames(
    out_dir: str | Path,
    scene: Scene,
    distance_m: float,
    n_frames: int,
    seed: int = 0,
    progress: Progress | None = None,
    camera: str | None = None,
    depth: str | None = None,
) -> list[Path]:
    """Write ``n_frames`` frame pairs of the simulated cameras ``camera`` and ``depth`` (None:
    the Lepton 3, 1280x720) with ground truth: ``calibration.yaml``, then per frame
    ``frame_NNNNNN.npz`` holding depth (uint16), thermal (uint16), times, telemetry (JSON) and
    the truth on both grids (float32; depth_z_m, depth_temp_k, thermal_pixel_of_depth,
    visible_in_thermal, thermal_temp_k, thermal_range_m)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rig = Rig.of_cameras(scene, camera_pose(distance_m), camera, depth, seed=seed, start_s=1.0)
    rig.calibration.save(out / "calibration.yaml")
    truth = rig.truth()  # one pose: the same truth in every frame, converted once
    truth_f32: dict[str, Any] = {
        "depth_z_m": _f32(truth.depth_z_m),
        "depth_temp_k": _f32(truth.depth_temp_k),
        "thermal_pixel_of_depth": _f32(truth.thermal_pixel_of_depth),
        "visible_in_thermal": truth.visible_in_thermal,
        "thermal_temp_k": _f32(truth.thermal_temp_k),
        "thermal_range_m": _f32(truth.thermal_range_m),
    }
    written = []
    for frame in rig.frames(n_frames):
        path = out / f"frame_{frame.index:06d}.npz"
        tel = {
            k: (v.name if hasattr(v, "name") else v) for k, v in frame.telemetry.__dict__.items()
        }
        np.savez_compressed(
            path,
            depth=frame.depth,
            thermal=frame.thermal,
            depth_time_s=frame.depth_time_s,
            thermal_time_s=frame.thermal_time_s,
            telemetry=json.dumps(tel),
            **truth_f32,
        )
        written.append(path)
        if progress:
            progress(1)
    return written


def _f32(a: NDArray[np.float64]) -> NDArray[np.float32]:
    return np.where(np.isfinite(a), a, np.nan).astype(np.float32)
