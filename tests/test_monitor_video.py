"""The monitor's live video read by real clients: Debian's ffprobe and ffmpeg open the MJPEG
stream over HTTP and the RTSP stream (H.264), get pictures of the size the docs state (the
overlay or the thermal image with its title and colour scale), pictures that change with the
simulated scene and differ between the views, the declared rate; the token and the RTSP
password are asked for (401 without); one more MJPEG stream than allowed gets 503; the RTSP
stream is encoded once for two viewers; both stop with the monitor, the ports let go. No rate
is measured: the rate checked is the one the streams declare."""

from __future__ import annotations

import functools
import re
import shutil
import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from monitor_helpers import PATIENCE_S, monitor_config, settings_file, wait_for
from mqtt_broker import free_port
from thermodepth.errors import InputError
from thermodepth.monitor import Monitor, load_config
from thermodepth.monitor.live import LEGEND_PX, TITLE_PX, video_size
from thermodepth.sim import default_calibration

FFMPEG, FFPROBE = shutil.which("ffmpeg"), shutil.which("ffprobe")
needs_ffmpeg = pytest.mark.skipif(
    FFMPEG is None or FFPROBE is None, reason="needs Debian's ffmpeg (ffmpeg and ffprobe)"
)
TOKEN, PASSWORD = "s3cret", "pa55word"
CAL = default_calibration()
SIZES = {
    view: video_size(
        (CAL.depth.width, CAL.depth.height), (CAL.thermal.width, CAL.thermal.height), view
    )
    for view in ("overlay", "thermal")
}
"""The pictures' sizes as docs/monitor.md states them: the depth image (1280 x 720) or the
thermal image 4 times larger (640 x 480), 150 px wider for the colour scale and 26 px taller
for the title."""


@functools.cache
def gstreamer_rtsp() -> bool:
    """Whether the RTSP output can start here: asked in a process of its own, so that a test
    process that collects this file without running it never loads GStreamer."""
    probe = (
        "from thermodepth.monitor.outputs.rtsp import gstreamer, pick_encoder\n"
        "pick_encoder(gstreamer()[0])"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, timeout=300)
    return done.returncode == 0


needs_rtsp = pytest.mark.skipif(
    not gstreamer_rtsp(),
    reason="needs PyGObject with GStreamer's RTSP server and openh264enc (Debian: "
    "gir1.2-gst-rtsp-server-1.0, gstreamer1.0-plugins-bad, python3-gi)",
)


def start(folder: Path, **sections: Any) -> tuple[Monitor, int]:
    """A monitor of one simulated rig ``t`` with its token, an RTSP server on a free port
    (where GStreamer's RTSP server is installed: the MJPEG tests run without it) and
    ``sections``; once its first picture is there."""
    (folder / "token").write_text(f"{TOKEN}\n", encoding="utf-8")
    (folder / "rtsp.pass").write_text(f"{PASSWORD}\n", encoding="utf-8")
    settings_file(folder)
    port = free_port()
    if gstreamer_rtsp():
        sections["rtsp"] = {"listen": f"127.0.0.1:{port}", "password_file": "rtsp.pass"}
    path = monitor_config(
        folder,
        [{"name": "t", "source": "sim", "settings": "s.yaml"}],
        http={"token_file": "token"},
        **sections,
    )
    monitor = Monitor(load_config(path))
    monitor.start()
    try:
        wait_for(lambda: monitor.picture("t", "overlay", None))
    except BaseException:
        monitor.stop()
        raise
    return monitor, port


@pytest.fixture(scope="module")
def running(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Monitor, int]]:
    monitor, port = start(tmp_path_factory.mktemp("video"))
    try:
        yield monitor, port
    finally:
        monitor.stop()


def probe(url: str, *before: str) -> dict[str, Any]:
    """ffprobe's stream of ``url`` (its first video stream) and its log (``log``)."""
    assert FFPROBE is not None
    args = [FFPROBE, "-v", "debug", *before, "-show_entries", "stream=codec_name,width,height",
            "-of", "default=noprint_wrappers=1", url]  # fmt: skip
    done = subprocess.run(args, capture_output=True, text=True, timeout=PATIENCE_S)
    assert done.returncode == 0, done.stderr[-2000:]
    found = dict(line.split("=", 1) for line in done.stdout.splitlines() if "=" in line)
    return {**found, "log": done.stderr}


def frames(url: str, count: int, size: tuple[int, int], *before: str) -> np.ndarray:
    """``count`` pictures of ``url`` as ffmpeg decodes them, RGB (count, H, W, 3)."""
    assert FFMPEG is not None
    args = [FFMPEG, "-v", "error", *before, "-i", url, "-frames:v", str(count),
            "-f", "rawvideo", "-pix_fmt", "rgb24", "-"]  # fmt: skip
    done = subprocess.run(args, capture_output=True, timeout=PATIENCE_S)
    assert done.returncode == 0, done.stderr.decode(errors="replace")[-2000:]
    w, h = size
    assert len(done.stdout) == count * h * w * 3, (len(done.stdout), count, size)
    return np.frombuffer(done.stdout, np.uint8).reshape(count, h, w, 3)


def scene(picture: np.ndarray, view: str) -> np.ndarray:
    """The picture without its title and colour scale (the title holds the time)."""
    return picture[TITLE_PX:, : SIZES[view][0] - LEGEND_PX].astype(np.int16)


def changes(pictures: np.ndarray, view: str) -> None:
    """The first and last of ``pictures`` (seconds apart) show the scene differently: a live
    sensor's noise, the hotspot's label; and each shows a scene (not a blank)."""
    first, last = scene(pictures[0], view), scene(pictures[-1], view)
    assert first.std() > 5 and last.std() > 5
    assert np.abs(first - last).mean() > 0.05, "the pictures did not change"


@needs_ffmpeg
def test_mjpeg_wants_the_token_and_gives_each_view_at_its_size(
    running: tuple[Monitor, int],
) -> None:
    monitor, _ = running
    url = f"{monitor.http.url}/api/rigs/t/stream.mjpeg"
    with httpx.Client(timeout=30) as client:
        assert client.get(url).status_code == 401
        wrong = client.get(url, params={"token": "nope"})
        assert wrong.status_code == 401 and wrong.json() == {"error": "wrong token"}
        # the query is taken on the live pictures only, never elsewhere
        assert client.get(f"{monitor.http.url}/api/status?token={TOKEN}").status_code == 401
        assert client.get(url, params={"token": TOKEN, "view": "x"}).status_code == 400
        with client.stream("GET", url, params={"token": TOKEN}) as got:
            assert got.status_code == 200
            assert got.headers["content-type"].startswith("multipart/x-mixed-replace")
            assert got.headers["x-frame-rate"] == "5"  # the rate it declares: mjpeg.fps
    # a camera's client as Home Assistant's: the token as a query
    seen = probe(f"{url}?token={TOKEN}", "-f", "mpjpeg")
    assert (seen["codec_name"], int(seen["width"]), int(seen["height"])) == (
        "mjpeg",
        *SIZES["overlay"],
    )
    overlay = frames(f"{url}?token={TOKEN}", 20, SIZES["overlay"], "-f", "mpjpeg")
    changes(overlay, "overlay")
    # ffmpeg with the token as a header
    bearer = ("-headers", f"Authorization: Bearer {TOKEN}\r\n", "-f", "mpjpeg")
    thermal = frames(f"{url}?view=thermal", 20, SIZES["thermal"], *bearer)
    changes(thermal, "thermal")
    assert SIZES["overlay"] != SIZES["thermal"]


@needs_ffmpeg
@needs_rtsp
def test_rtsp_is_h264_at_its_size_and_rate_and_wants_the_password(
    running: tuple[Monitor, int],
) -> None:
    _, port = running
    base = f"rtsp://viewer:{PASSWORD}@127.0.0.1:{port}"
    tcp = ("-rtsp_transport", "tcp")
    seen = probe(f"{base}/t", *tcp)
    assert (seen["codec_name"], int(seen["width"]), int(seen["height"])) == (
        "h264",
        *SIZES["overlay"],
    )
    assert re.search(r"^a=framerate:5$", seen["log"], re.M), "the SDP declares its rate"
    changes(frames(f"{base}/t", 20, SIZES["overlay"], *tcp), "overlay")
    thermal = frames(f"{base}/t/thermal", 20, SIZES["thermal"], *tcp)
    changes(thermal, "thermal")
    assert FFPROBE is not None
    for who in (f"viewer:wrong@127.0.0.1:{port}", f"127.0.0.1:{port}"):
        refused = subprocess.run([FFPROBE, "-v", "error", *tcp, f"rtsp://{who}/t"],
                                 capture_output=True, text=True, timeout=PATIENCE_S)  # fmt: skip
        assert refused.returncode != 0 and "401" in refused.stderr, refused.stderr


@needs_ffmpeg
@needs_rtsp
def test_rtsp_encodes_once_for_two_viewers(running: tuple[Monitor, int]) -> None:
    monitor, port = running
    url = f"rtsp://viewer:{PASSWORD}@127.0.0.1:{port}/t"
    rtsp = monitor.output("rtsp")
    assert rtsp is not None
    # an earlier test's viewers gone (a UDP session's end may wait for its timeout): the
    # media this test counts is made for it
    wait_for(lambda: not rtsp.status()["streams"].get("t", {}).get("playing"))
    made = rtsp.status()["streams"].get("t", {}).get("made", 0)
    assert FFMPEG is not None
    first = subprocess.Popen(  # a viewer that stays
        [FFMPEG, "-v", "error", "-rtsp_transport", "tcp", "-i", url, "-f", "null", "-"],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        wait_for(lambda: rtsp.status()["streams"].get("t", {}).get("playing"))
        frames(url, 3, SIZES["overlay"], "-rtsp_transport", "udp")  # a second, over UDP
        assert first.poll() is None
        assert rtsp.status()["streams"]["t"]["made"] == made + 1  # one encoder for both
    finally:
        first.kill()
        first.wait()


def read_stream(url: str, told: dict[str, Any]) -> None:
    """Read an MJPEG stream to its end (``told``: its status, bytes read, how it ended)."""
    try:
        with httpx.stream("GET", url, timeout=PATIENCE_S) as got:
            told["status"] = got.status_code
            for chunk in got.iter_bytes():
                told["bytes"] = told.get("bytes", 0) + len(chunk)
        told["ended"] = "closed"
    except httpx.HTTPError as exc:
        told["ended"] = repr(exc)


def bindable(port: int) -> bool:
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
            return True
        except OSError:
            return False


@needs_ffmpeg
def test_one_stream_more_than_allowed_is_refused_and_streams_end_with_the_monitor(
    tmp_path: Path,
) -> None:
    monitor, rtsp_port = start(tmp_path, mjpeg={"max_streams": 1})
    url = f"{monitor.http.url}/api/rigs/t/stream.mjpeg?token={TOKEN}"
    http_port = monitor.http.port
    told: dict[str, Any] = {}
    reader = threading.Thread(target=read_stream, args=(url, told), daemon=True)
    viewer = None
    try:
        reader.start()
        wait_for(lambda: told.get("bytes", 0) > 0)
        busy = httpx.get(url, timeout=30)
        assert busy.status_code == 503 and busy.headers["retry-after"]
        assert monitor.status()["mjpeg"] == {"open": 1, "max": 1, "refused": 1}
        if gstreamer_rtsp():
            assert FFMPEG is not None
            viewer = subprocess.Popen(
                [FFMPEG, "-v", "error", "-rtsp_transport", "tcp", "-i",
                 f"rtsp://viewer:{PASSWORD}@127.0.0.1:{rtsp_port}/t", "-f", "null", "-"],
                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            )  # fmt: skip
            rtsp = monitor.output("rtsp")
            assert rtsp is not None
            wait_for(lambda: rtsp.status()["streams"].get("t", {}).get("playing"))
    finally:
        monitor.stop()
    reader.join(PATIENCE_S)
    assert not reader.is_alive() and told["status"] == 200 and "ended" in told
    assert bindable(http_port)
    if viewer is not None:
        try:
            assert viewer.wait(PATIENCE_S) is not None  # the server let it go: it ends
        finally:
            viewer.kill()
        assert bindable(rtsp_port)


def test_rtsp_config_problems_are_one_line_each(tmp_path: Path) -> None:
    settings_file(tmp_path)
    rigs = [{"name": "t", "source": "sim", "settings": "s.yaml"}]
    path = monitor_config(
        tmp_path, rigs, rtsp={"listen": "0.0.0.0:8554", "password_file": "missing.pass"}
    )
    with pytest.raises(InputError) as err:
        load_config(path)
    lines = str(err.value).splitlines()
    assert len(lines) == 2
    assert "rtsp.listen: 0.0.0.0:8554 is reachable from other machines" in lines[0]
    assert "allow_remote: true" in lines[0]
    assert "rtsp.password_file:" in lines[1] and "missing.pass: cannot read" in lines[1]
    (tmp_path / "rtsp.pass").write_text("\n", encoding="utf-8")
    path = monitor_config(
        tmp_path,
        rigs,
        rtsp={
            "listen": "0.0.0.0:8554",
            "password_file": "rtsp.pass",
            "allow_remote": True,
        },
    )
    with pytest.raises(InputError, match=r"rtsp.pass: empty \(the first line is the password\)"):
        load_config(path)


def test_without_pygobject_or_an_encoder_rtsp_is_refused_naming_the_packages(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from thermodepth.monitor.outputs import rtsp

    settings_file(tmp_path)
    (tmp_path / "rtsp.pass").write_text("pw\n", encoding="utf-8")
    path = monitor_config(
        tmp_path,
        [{"name": "t", "source": "sim", "settings": "s.yaml"}],
        http={"listen": None},
        rtsp={"listen": f"127.0.0.1:{free_port()}", "password_file": "rtsp.pass"},
    )
    config = load_config(path)
    monkeypatch.setitem(sys.modules, "gi", None)  # import gi fails
    with pytest.raises(InputError) as err:
        Monitor(config)
    (line,) = str(err.value).splitlines()
    for package in ("gir1.2-gst-rtsp-server-1.0", "gstreamer1.0-plugins-bad", "python3-gi",
                    "libgirepository1.0-dev", "libcairo2-dev", "pkg-config"):  # fmt: skip
        assert package in line
    monkeypatch.undo()
    if not gstreamer_rtsp():
        return
    monkeypatch.setattr(rtsp, "ENCODERS", {"nosuchh264enc": ("gstreamer1.0-plugins-bad", "")})
    with pytest.raises(InputError) as err:
        Monitor(config)
    (line,) = str(err.value).splitlines()
    assert "no H.264 encoder without the GPL" in line and "gstreamer1.0-plugins-bad" in line


AFTER_GSTREAMER = """
import numba  # numba's LLVM first, as in the monitor
from thermodepth.monitor.outputs.rtsp import gstreamer
gstreamer()
import cv2, numpy as np
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
plt.figure().savefig("/dev/null", format="png")  # matplotlib's fonts throw in C++ inside
try:
    cv2.resize(np.zeros((0, 0), np.uint8), (2, 2))  # a cv::Exception
except cv2.error:
    print("survived")
"""


@needs_rtsp
def test_cpp_exceptions_survive_gstreamer_in_the_process() -> None:
    # GStreamer's libunwind once took the place of libgcc's unwinder: the process aborted at
    # the next C++ exception (matplotlib's first figure, an OpenCV error)
    done = subprocess.run(
        [sys.executable, "-c", AFTER_GSTREAMER], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0 and done.stdout.split() == ["survived"], done.stderr[-2000:]
