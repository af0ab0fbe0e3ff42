"""What the live video costs the monitor, and how old a picture is when a client has it: one
rig replaying a recording at its recorded pace (as bench_monitor: a D435 at 1280x720 beside a
Lepton 3, 8.7 pairs/s, the chip cold for 5 s, hot for 5 s), its HTTP server (MJPEG) and its
RTSP server (H.264 by openh264enc), both at 5 frames a second, read by Debian's ffmpeg.

CPU: the monitor's process (every thread: the rig, the pictures, uvicorn, GStreamer) in cores,
over phases of nobody looking, MJPEG streams and RTSP viewers (medians of the phases); the
clients are processes of their own, not counted. Age, MJPEG: from the capture time of a
part's frame (its X-Capture-Time) to the moment the client has the part decoded. Age, RTSP
(H.264 carries no capture time): the moment ffmpeg has decoded the first picture of each hot
or cold phase of the chip, later than the MJPEG client had the same change by this much,
added to the MJPEG age of that change's part: rough (the two streams may sample frames up to
one frame apart).
"""

from __future__ import annotations

import json
import shutil
import statistics
import subprocess
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import cv2
import httpx
import numpy as np
import yaml

from thermodepth.monitor import Monitor, load_config
from thermodepth.monitor.live import LEGEND_PX, TITLE_PX
from thermodepth.monitor.outputs.rtsp import RtspOutput

from .bench_dashboard import cores_over, quantile
from .bench_monitor import SETTINGS, write_take
from .common import OUT, console

WARMUP_S = 10.0
PHASE_S = 20.0
ROUNDS = 2
AGE_S = 40.0
PASSWORD = "bench"


def scene_mean(img: np.ndarray) -> float:
    """The mean of a thermal view's picture without its title and scale: the hot chip
    lifts it."""
    return float(img[TITLE_PX:, : img.shape[1] - LEGEND_PX].mean())


def mjpeg_reader(url: str, seconds: float, got: list[tuple[float, float, float]]) -> None:
    """(received, capture time, scene mean) of each part of an MJPEG stream."""
    end = time.monotonic() + seconds
    with httpx.stream("GET", url, timeout=30) as r:
        buf = b""
        for chunk in r.iter_bytes():
            buf += chunk
            while True:
                head_end = buf.find(b"\r\n\r\n")
                if head_end < 0:
                    break
                head = buf[:head_end].decode(errors="replace")
                fields = dict(line.split(": ", 1) for line in head.splitlines() if ": " in line)
                size = int(fields["Content-Length"])
                if len(buf) < head_end + 4 + size + 2:
                    break
                data = buf[head_end + 4 : head_end + 4 + size]
                buf = buf[head_end + 4 + size + 2 :]
                img = np.asarray(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR))
                got.append((time.time(), float(fields["X-Capture-Time"]), scene_mean(img)))
            if time.monotonic() > end:
                return


def rtsp_reader(
    url: str, size: tuple[int, int], seconds: float, got: list[tuple[float, float]]
) -> None:
    """(received, scene mean) of each picture ffmpeg decodes of an RTSP stream."""
    w, h = size
    proc = subprocess.Popen(
        ["ffmpeg", "-v", "error", "-rtsp_transport", "tcp", "-fflags", "nobuffer", "-flags",
         "low_delay", "-i", url, "-f", "rawvideo", "-pix_fmt", "bgr24", "-"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    assert proc.stdout is not None
    end = time.monotonic() + seconds
    try:
        while time.monotonic() < end:
            data = proc.stdout.read(w * h * 3)
            if len(data) < w * h * 3:
                return
            got.append((time.time(), scene_mean(np.frombuffer(data, np.uint8).reshape(h, w, 3))))
    finally:
        proc.kill()
        proc.wait()


def changes(means: list[float]) -> list[int]:
    """Where the chip's phase changes (the scene's mean crosses the midpoint)."""
    mid = (min(means) + max(means)) / 2
    hot = [m > mid for m in means]
    return [i for i in range(1, len(hot)) if hot[i] != hot[i - 1]]


def viewers(args: list[str], n: int) -> list[subprocess.Popen[bytes]]:
    return [
        subprocess.Popen(
            ["ffmpeg", "-v", "error", *args, "-f", "null", "-"],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        for _ in range(n)
    ]


def main() -> None:
    from rich.table import Table

    if shutil.which("ffmpeg") is None:
        console.print("bench_video: skipped: needs Debian's ffmpeg")
        return
    with tempfile.TemporaryDirectory(prefix="bench-video-") as tmp:
        folder = Path(tmp)
        take = folder / "take.zarr"
        write_take(take)
        (folder / "s.yaml").write_text(SETTINGS)
        (folder / "rtsp.pass").write_text(f"{PASSWORD}\n")
        config = {
            "rigs": [{"name": "r0", "source": f"recording:{take}", "settings": "s.yaml"}],
            "storage": {"path": "store"},
            "http": {"listen": "127.0.0.1:0"},
            "rtsp": {"listen": "127.0.0.1:0", "password_file": "rtsp.pass"},
        }
        (folder / "monitor.yaml").write_text(yaml.safe_dump(config))
        monitor = Monitor(load_config(folder / "monitor.yaml"))
        monitor.start()
        rtsp = monitor.output("rtsp")
        assert isinstance(rtsp, RtspOutput)
        mjpeg = f"{monitor.http.url}/api/rigs/r0/stream.mjpeg"
        rtsp_url = f"rtsp://viewer:{PASSWORD}@{rtsp.url.removeprefix('rtsp://')}/r0"
        phases: dict[str, list[float]] = {}
        plan = {
            "nobody": [],
            "1 MJPEG stream": ["-f", "mpjpeg", "-i", mjpeg],
            "3 MJPEG streams": ["-f", "mpjpeg", "-i", mjpeg],
            "1 RTSP viewer": ["-rtsp_transport", "tcp", "-i", rtsp_url],
            "3 RTSP viewers": ["-rtsp_transport", "tcp", "-i", rtsp_url],
        }
        try:
            time.sleep(WARMUP_S)
            for _ in range(ROUNDS):
                for name, args in plan.items():
                    clients = viewers(args, int(name[0]) if args else 0)
                    time.sleep(8.0)  # the clients connected, the pictures wanted
                    phases.setdefault(name, []).append(cores_over(PHASE_S))
                    console.print(f"  {name}: {phases[name][-1]:.3f} cores")
                    for c in clients:
                        c.kill()
                        c.wait()
                    time.sleep(2.0)
            parts: list[tuple[float, float, float]] = []
            pictures: list[tuple[float, float]] = []
            size = monitor.video("r0", "thermal", 5.0)
            assert size is not None
            wh = (size.image.shape[1], size.image.shape[0])
            readers = [
                threading.Thread(target=mjpeg_reader, args=(f"{mjpeg}?view=thermal", AGE_S, parts)),
                threading.Thread(
                    target=rtsp_reader, args=(f"{rtsp_url}/thermal", wh, AGE_S, pictures)
                ),
            ]
            for r in readers:
                r.start()
            for r in readers:
                r.join()
        finally:
            monitor.stop()
    cost = {name: statistics.median(v) for name, v in phases.items()}
    table = Table(title="live video: the monitor's CPU (cores, median of phases)")
    for col in ("clients", "cores", "more than nobody"):
        table.add_column(col, justify="right")
    for name, value in cost.items():
        table.add_row(name, f"{value:.3f}", f"{value - cost['nobody']:+.3f}")
    console.print(table)
    ages = [received - captured for received, captured, _ in parts]
    m_changes = changes([m for *_, m in parts])
    r_changes = changes([m for _, m in pictures])
    rtsp_ages = []
    for i in m_changes:  # each change as MJPEG had it, and RTSP's nearest after it
        later = [
            pictures[j][0] - parts[i][0] for j in r_changes if pictures[j][0] > parts[i][0] - 1
        ]
        if later:
            rtsp_ages.append(ages[i] + min(later))
    table = Table(title="a picture's age when the client has it decoded (ms)")
    for col in ("stream", "median", "p99", "n"):
        table.add_column(col, justify="right")
    for name, values in (("MJPEG (every part)", ages), ("RTSP (each phase change)", rtsp_ages)):
        ms = [1e3 * v for v in values]
        if ms:
            table.add_row(
                name, f"{statistics.median(ms):.0f}", f"{quantile(ms, 0.99):.0f}", str(len(ms))
            )
    console.print(table)
    OUT.mkdir(exist_ok=True)
    result: dict[str, Any] = {"cores": phases, "mjpeg_ages_s": ages, "rtsp_ages_s": rtsp_ages}
    (OUT / "video.json").write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
