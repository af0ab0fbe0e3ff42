"""The monitor's live video as H.264 over RTSP (GStreamer's RTSP server through PyGObject, its
GLib main loop on a supervised worker of its own; the ``rtsp:`` section of the monitor's
config), for NVRs (Frigate, go2rtc), VLC and ffmpeg.

Each rig is ``rtsp://HOST:PORT/RIG`` (its overlay, as the dashboard draws it, with its title,
the frame's time and the colour scale beside it) and ``rtsp://HOST:PORT/RIG/thermal`` (its
thermal image, 4 times larger, with the same). A stream is encoded once whatever the number
of viewers (a shared media per mount): an ``appsrc`` fed ``fps`` times a second with the
rig's latest picture (:meth:`~..live.LiveView.video`, as BGRx), converted to I420, encoded to H.264
(:data:`ENCODERS`: none under the GPL; x264enc is) and payloaded as RTP; its SDP declares the
rate (``a=framerate``). A mount's size is its rig's picture size when the first viewer comes
(rounded up to even: H.264's 4:2:0); later pictures of another size are scaled to it. Nothing
queues: ``appsrc`` holds at most two frames and drops the older.

Access: Basic authentication, one user (``user``, the first line of ``password_file``); at
most ``max_viewers`` sessions at once (one more is answered 503). RTSP is not encrypted: the
monitor refuses to listen beyond loopback unless ``allow_remote: true``.
"""

from __future__ import annotations

import contextlib
import ctypes
import threading
import time
from fractions import Fraction
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ...errors import InputError
from ..config import RtspConfig, read_token
from ..logs import logger
from ..workers import Worker
from .base import Output, OutputContext, RigEntities, check_port

INSTALL = (
    "rtsp: the monitor's RTSP server needs PyGObject and GStreamer's RTSP server: Debian's "
    "gir1.2-gst-rtsp-server-1.0, gstreamer1.0-plugins-base, gstreamer1.0-plugins-good, "
    "gstreamer1.0-plugins-bad, and python3-gi or pip install 'thermodepth[video]' (which "
    "builds PyGObject: libgirepository1.0-dev, libcairo2-dev, pkg-config)"
)
ENCODERS = {
    "openh264enc": (
        "gstreamer1.0-plugins-bad",
        "openh264enc rate-control=bitrate bitrate={bps} gop-size={gop} complexity=low "
        "usage-type=camera",
    ),
}
"""The H.264 encoders tried, in order: their Debian package and their settings (``bps``: bits a
second, ``gop``: frames between key frames). None may be under the GPL (x264enc is)."""
ELEMENTS = {
    "appsrc": "gstreamer1.0-plugins-base",
    "videoconvert": "gstreamer1.0-plugins-base",
    "rtph264pay": "gstreamer1.0-plugins-good",
}
"""The other elements a stream needs, and their Debian package."""
VIEWS = {"": "overlay", "/thermal": "thermal"}
"""Each rig's mounts: ``/RIG`` + this, and the picture it shows."""
ROLE = "viewer"
KEY_FRAME_S = 2.0
"""A new viewer of a playing stream waits at most this long for a key frame."""
FIRST_FRAME_S = 10.0
"""How long a first viewer waits for its rig's first picture (a running rig's comes within a
quarter of a second of being asked for) before it is refused."""
CLIENT_THREADS = 4
"""The RTSP server's threads for its clients (GStreamer's default: one for all)."""
BEAT_S = 0.5
WORKER_LIMIT_S = 30.0


def gstreamer() -> tuple[Any, Any, Any]:
    """GStreamer, its RTSP server and GLib (``Gst``, ``GstRtspServer``, ``GLib``), initialised;
    InputError (:data:`INSTALL`, one line) when PyGObject or a typelib is not there."""
    # GStreamer brings libunwind, whose _Unwind_Resume, once global, takes the place of
    # libgcc's for every library bound after: the next C++ exception anywhere in the process
    # (matplotlib's fonts, OpenCV's cv::Exception) aborted it. libgcc first keeps its own.
    with contextlib.suppress(OSError):
        ctypes.CDLL("libgcc_s.so.1", mode=ctypes.RTLD_GLOBAL)
    try:
        import gi

        gi.require_version("Gst", "1.0")
        gi.require_version("GstRtspServer", "1.0")
        from gi.repository import GLib, Gst, GstRtspServer
    except (ImportError, ValueError):
        raise InputError(INSTALL) from None
    Gst.init(None)
    return Gst, GstRtspServer, GLib


def pick_encoder(gst: Any) -> str:
    """The first of :data:`ENCODERS` this machine has, after checking :data:`ELEMENTS`;
    InputError naming the Debian package when one is missing."""
    missing = {pkg for name, pkg in ELEMENTS.items() if gst.ElementFactory.find(name) is None}
    if missing:
        raise InputError(f"rtsp: GStreamer elements missing: install {', '.join(sorted(missing))}")
    for name in ENCODERS:
        if gst.ElementFactory.find(name) is not None:
            return name
    packages = sorted({pkg for pkg, _ in ENCODERS.values()})
    raise InputError(
        f"rtsp: no H.264 encoder without the GPL ({', '.join(ENCODERS)}): install "
        f"{', '.join(packages)}"
    )


def even(size: tuple[int, int]) -> tuple[int, int]:
    """A picture size (W, H) rounded up to even numbers (H.264's 4:2:0 wants them)."""
    return size[0] + size[0] % 2, size[1] + size[1] % 2


def fit(image: NDArray[np.uint8], size: tuple[int, int]) -> NDArray[np.uint8]:
    """A BGR picture made ``size`` (W, H): scaled to fit inside it (keeping its shape, when it
    is another size) and padded at the right and bottom."""
    w, h = size
    ih, iw = image.shape[:2]
    if iw > w or ih > h or (iw < w - 1 and ih < h - 1):
        scale = min(w / iw, h / ih)
        iw, ih = max(1, min(w, round(iw * scale))), max(1, min(h, round(ih * scale)))
        image = np.asarray(cv2.resize(image, (iw, ih), interpolation=cv2.INTER_AREA))
    if (iw, ih) == (w, h):
        return image
    out = np.zeros((h, w, 3), np.uint8)
    out[:ih, :iw] = image
    return out


_FACTORY: list[type] = []


def factory_class(rtsp: Any) -> type:
    """The media factory whose pipeline ``make()`` gives (a GObject type: registered once)."""
    if not _FACTORY:

        class Factory(rtsp.RTSPMediaFactory):
            def __init__(self, make: Any) -> None:
                super().__init__()
                self.make = make

            def do_create_element(self, url: Any) -> Any:
                return self.make()

        _FACTORY.append(Factory)
    return _FACTORY[0]


class Mount:
    """A rig's stream as the server plays it: its picture (``rig``, ``view``), its size (set
    by its first viewer) and its playing media's ``appsrc`` s (one while it plays: shared)."""

    def __init__(self, rig: str, view: str) -> None:
        self.rig, self.view = rig, view
        self.size: tuple[int, int] | None = None
        self.sources: list[Any] = []
        self.media: list[Any] = []
        self.made = 0  # media made: once a stream plays, whatever its viewers
        self.pushed = 0


class RtspOutput(Output):
    """The RTSP server of a monitor's rigs (module docstring); ``start`` binds its address
    (one InputError line when it cannot) and serves on a worker of its own (restarted when
    it fails)."""

    name = "rtsp"

    def __init__(self, config: RtspConfig, context: OutputContext) -> None:
        self.gst, self.rtsp, self.glib = gstreamer()
        self.encoder = pick_encoder(self.gst)
        self.config, self.rigs, self.context = config, context.rigs, context
        self.password = read_token(config.password_file, "password")
        self.log = logger("rtsp")
        self.host, self.port = config.address()
        self.mounts = {
            f"/{rig.name}{suffix}": Mount(rig.name, view)
            for rig in self.rigs
            for suffix, view in VIEWS.items()
        }
        self._lock = threading.Lock()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self.serving = False
        self.worker = Worker("rtsp", self._main, BEAT_S * 4, WORKER_LIMIT_S, self.log)
        self.gst.parse_launch(self._launch((64, 48)))  # the encoder's settings hold: fail now

    def describe(self) -> str:
        return describe(self.config) + f", encoder {self.encoder}"

    def workers(self) -> list[Worker]:
        return [self.worker]

    def fits(self, rigs: list[RigEntities]) -> bool:
        return [r.name for r in rigs] == [r.name for r in self.rigs]

    def start(self, timeout_s: float = 30.0) -> None:
        check_port(self.host, self.port, f"rtsp.listen: {self.config.listen}")
        self.worker.start()
        if not self._ready.wait(timeout_s) or self._error is not None:
            self.worker.stop()
            raise InputError(f"rtsp: the server did not start ({self._error or 'no answer'})")

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"rtsp://{host}:{self.port}"

    # -- a stream's pipeline -------------------------------------------------------------------

    def _launch(self, size: tuple[int, int]) -> str:
        """The pipeline of a stream of pictures of ``size`` (W, H) up to its payloader."""
        rate = Fraction(self.config.fps).limit_denominator(1001)
        settings = ENCODERS[self.encoder][1].format(
            bps=self.config.bitrate_kbps * 1000,
            gop=max(1, round(self.config.fps * KEY_FRAME_S)),
        )
        return (
            "appsrc name=src is-live=true format=time do-timestamp=true max-buffers=2 "
            "leaky-type=downstream caps=video/x-raw,format=BGRx,"
            f"width={size[0]},height={size[1]},framerate={rate.numerator}/{rate.denominator} "
            f"! videoconvert ! video/x-raw,format=I420 ! {settings} name=encoder"
        )

    def _element(self, mount: Mount) -> Any:
        """A new stream of ``mount`` (its first viewer's thread): None (the viewer refused)
        while its rig has no picture."""
        end = time.monotonic() + FIRST_FRAME_S
        frame = self.context.video(mount.rig, mount.view, self.config.fps)
        while frame is None and time.monotonic() < end and not self.worker.stopping.is_set():
            time.sleep(0.1)
            frame = self.context.video(mount.rig, mount.view, self.config.fps)
        if frame is None:
            self.log.warning("rtsp: %s: no picture yet, viewer refused", mount.rig)
            return None
        if mount.size is None:
            mount.size = even((frame.image.shape[1], frame.image.shape[0]))
        pipeline = self.gst.parse_launch(self._launch(mount.size))
        # the payloader in a bin of its own, so that its caps carry the SDP's a=framerate
        rate = f"{self.config.fps:g}"
        pay = self.gst.parse_bin_from_description(
            "rtph264pay pt=96 config-interval=-1 ! capsfilter "
            f"caps=application/x-rtp,a-framerate=(string){rate}",
            True,
        )
        pay.set_name("pay0")
        pipeline.add(pay)
        pipeline.get_by_name("encoder").link(pay)
        return pipeline

    def _configured(self, mount: Mount, media: Any) -> None:
        """A stream's media made: its ``appsrc`` fed until it is let go."""
        source = media.get_element().get_child_by_name("src")
        with self._lock:
            mount.sources.append(source)
            mount.media.append(media)
            mount.made += 1

        def let_go(_: Any) -> None:
            with self._lock:
                if source in mount.sources:
                    mount.sources.remove(source)
                    mount.media.remove(media)

        media.connect("unprepared", let_go)

    def _feed(self) -> None:
        """Each playing stream's latest picture (the loop's thread, ``fps`` times a second)."""
        gst = self.gst
        with self._lock:
            playing = [(m, list(m.sources)) for m in self.mounts.values() if m.sources]
        for mount, sources in playing:
            frame = self.context.video(mount.rig, mount.view, self.config.fps)
            if frame is None or mount.size is None:
                continue
            # 4 bytes a pixel: GStreamer's rows of 3 would be padded to 4-byte multiples
            data = cv2.cvtColor(fit(frame.image, mount.size), cv2.COLOR_BGR2BGRA).tobytes()
            for source in sources:
                source.emit("push-buffer", gst.Buffer.new_wrapped(data))
            mount.pushed += 1

    # -- the server's own worker ---------------------------------------------------------------

    def _server(self) -> Any:
        """The RTSP server: its address, its mounts (each a shared factory), its one user."""
        rtsp = self.rtsp
        server = rtsp.RTSPServer()
        server.set_address(self.host)
        server.set_service(str(self.port))
        server.get_session_pool().set_max_sessions(self.config.max_viewers)
        # a first viewer waits on its client thread for its rig's first picture: with the
        # default one thread, every other client would wait with it
        server.get_thread_pool().set_max_threads(CLIENT_THREADS)
        token = rtsp.RTSPToken()
        token.set_string(rtsp.RTSP_TOKEN_MEDIA_FACTORY_ROLE, ROLE)
        auth = rtsp.RTSPAuth()
        auth.add_basic(rtsp.RTSPAuth.make_basic(self.config.user, self.password), token)
        server.set_auth(auth)
        permissions = rtsp.RTSPPermissions()
        for permission in (rtsp.RTSP_PERM_MEDIA_FACTORY_ACCESS,
                           rtsp.RTSP_PERM_MEDIA_FACTORY_CONSTRUCT):  # fmt: skip
            permissions.add_permission_for_role(ROLE, permission, True)
        points = server.get_mount_points()
        for path, mount in self.mounts.items():
            factory = factory_class(rtsp)(lambda m=mount: self._element(m))
            factory.set_shared(True)
            factory.set_permissions(permissions)
            factory.connect("media-configure", lambda _, media, m=mount: self._configured(m, media))
            points.add_factory(path, factory)
        return server

    def _main(self, worker: Worker) -> None:
        glib = self.glib
        context = glib.MainContext.new()
        loop = glib.MainLoop.new(context, False)
        server = self._server()
        try:
            source = server.create_source(None)
        except glib.Error as exc:
            if self._ready.is_set():  # a restart
                raise RuntimeError(f"cannot listen: {exc.message}") from None
            self._error = exc.message  # told by start()
            self._ready.set()
            return
        source.attach(context)
        self.port = server.get_bound_port()

        failed: list[BaseException] = []

        def beat() -> bool:
            worker.beat()
            if worker.stopping.is_set():
                loop.quit()
            return True

        def feed() -> bool:
            # an exception in a GLib callback is printed and removes its timer: every stream
            # would freeze while the beat went on; the loop ends instead and the worker
            # restarts it (supervised, logged)
            try:
                self._feed()
            except Exception as exc:
                failed.append(exc)
                loop.quit()
                return False
            return True

        for every_s, call in ((BEAT_S, beat), (1.0 / self.config.fps, feed)):
            timer = glib.timeout_source_new(max(1, round(every_s * 1000)))
            timer.set_callback(lambda *_, call=call: call())
            timer.attach(context)
        self.serving = True
        self._ready.set()
        try:
            loop.run()
        finally:
            self.serving = False
            self._release(server, source)
        if failed:
            raise failed[0]

    def _release(self, server: Any, source: Any) -> None:
        """However the loop ended: the viewers let go, every stream's pipeline stopped and the
        port closed (for a restart, or another program, to bind it)."""
        remove = self.rtsp.RTSPFilterResult.REMOVE
        with contextlib.suppress(Exception):
            server.client_filter(lambda *_: remove)
            server.get_session_pool().filter(lambda *_: remove)
        with self._lock:
            media = [m for mount in self.mounts.values() for m in mount.media]
            for mount in self.mounts.values():
                mount.sources.clear()
                mount.media.clear()
        for one in media:
            with contextlib.suppress(Exception):
                one.unprepare()
        source.destroy()

    def status(self) -> dict[str, Any]:
        with self._lock:
            playing = {
                path.lstrip("/"): {"made": m.made, "pushed": m.pushed, "playing": bool(m.sources)}
                for path, m in self.mounts.items()
                if m.made
            }
        return {"url": self.url, "serving": self.serving, "encoder": self.encoder,
                "streams": playing}  # fmt: skip


def describe(config: RtspConfig) -> str:
    """The output of an ``rtsp`` section in one line."""
    host, port = config.address()
    where = f"[{host}]" if ":" in host else host
    return (
        f"RTSP rtsp://{where}:{port}/RIG and /RIG/thermal (H.264, {config.fps:g} fps, "
        f"{config.bitrate_kbps} kbit/s; user {config.user}; at most {config.max_viewers} viewers)"
    )
