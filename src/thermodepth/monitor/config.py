"""The monitor's configuration file (``monitor.yaml``): its schema, and loading it with every
problem on a line of its own (docs/monitor.md describes it key by key).

Paths in the file (a rig's settings, the storage folder, the token and password files) are
relative to the file's folder.
"""

from __future__ import annotations

import contextlib
import ipaddress
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Literal, Protocol
from urllib.parse import urlsplit

from pydantic import Field, ValidationError, field_validator

from ..errors import FieldError, InputError, ThermodepthError, repeated
from ..pipeline import MqttSettings, Settings
from ..schema import StrictSchema, read_mapping, validation_lines
from ..sinks.mqtt import MqttTarget, read_password
from ..sources import check_spec
from .auth import TOKEN_ENV
from .logs import Level

RIG_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
MONITOR = "monitor"
"""The name the monitor's own events (storage faults) go under, where a rig's name would."""
PACES = ("recorded", "fast")
DEFAULT_LISTEN = "127.0.0.1:8088"


class RigConfig(StrictSchema):
    """One rig: ``name`` (letters, digits, ``_.-``: it names topics and folders),
    ``source`` (any source spec), ``settings`` (the run settings file), ``location`` (free
    text), ``pace`` (a recording's: ``recorded``, at its recorded pace and again from its
    start when it ends, as a live camera stands in; ``fast``: once, as fast as it goes),
    ``stall_s`` (no new frame for so long is a stall), ``depth_mode``, ``max_skew_s``,
    ``thermal_latency_s`` (as ``run`` takes them)."""

    name: str
    source: str
    settings: Path | None = None
    location: str | None = None
    pace: Literal["recorded", "fast"] | None = None
    stall_s: float = Field(default=3.0, gt=0)
    depth_mode: str | None = None
    max_skew_s: float = Field(default=0.05, ge=0)
    thermal_latency_s: float = Field(default=0.0, ge=0)

    @field_validator("name")
    @classmethod
    def _name(cls, name: str) -> str:
        if not RIG_NAME.match(name):
            raise ValueError("use letters, digits and _.- only (it names topics and folders)")
        if name == MONITOR:
            raise ValueError(f"{MONITOR!r} names the monitor's own events: choose another")
        return name


class StorageConfig(StrictSchema):
    """Where evidence goes and how much is kept: ``path``; ``retention_days`` (older
    recordings and clips are deleted); ``min_free_gb`` (below it the oldest go first);
    ``continuous`` (also keep a rolling recording of everything, in ``segment_s`` pieces);
    ``pre_s`` / ``post_s`` (a clip's seconds before and after its event; a later event
    extends the clip up to ``clip_max_s`` long, then starts a new one); ``pre_max_mb`` (each
    rig's pre-trigger buffer in memory, compressed, at most)."""

    path: Path
    retention_days: float = Field(default=30.0, gt=0)
    min_free_gb: float = Field(default=1.0, ge=0)
    continuous: bool = False
    segment_s: float = Field(default=600.0, gt=0)
    pre_s: float = Field(default=10.0, ge=0)
    post_s: float = Field(default=10.0, ge=0)
    clip_max_s: float = Field(default=120.0, gt=0)
    pre_max_mb: float = Field(default=128.0, gt=0)


class HttpConfig(StrictSchema):
    """The dashboard, API and health server: ``listen`` (``HOST:PORT``, port 0: any free one;
    null: none), ``token_file`` (its first line is the token every route but ``/healthz``
    wants; else ``THERMODEPTH_HTTP_TOKEN``; needed to listen beyond this machine),
    ``tls_cert`` and ``tls_key`` (PEM files: HTTPS), ``public_url`` (where people reach
    it, ``https://monitor.example``, behind a proxy too: the notifications' links)."""

    listen: str | None = DEFAULT_LISTEN
    token_file: Path | None = None
    tls_cert: Path | None = None
    tls_key: Path | None = None
    public_url: str | None = None

    def address(self) -> tuple[str, int]:
        """(host, port) of ``listen``; ValueError if it is not ``HOST:PORT``."""
        assert self.listen is not None
        return listen_address(self.listen, DEFAULT_LISTEN)

    def loopback(self) -> bool:
        return loopback_host(self.address()[0])


def listen_address(listen: str, example: str) -> tuple[str, int]:
    """(host, port) of a ``HOST:PORT``; ValueError (``listen: ...``, with ``example``) if it
    is not one."""
    host, sep, port = listen.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) < 65536:
        raise ValueError(f"listen: {listen!r}: expected HOST:PORT ({example})")
    return host.strip("[]"), int(port)


def loopback_host(host: str) -> bool:
    """Only this machine can reach ``host``."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class ListenSection(Protocol):
    """A server's section that may listen beyond this machine only when told."""

    listen: str
    allow_remote: bool

    def address(self) -> tuple[str, int]: ...


def listen_problems(name: str, section: ListenSection, risk: str) -> list[str]:
    """What is wrong with section ``name``'s ``listen``: not ``HOST:PORT``, or reachable from
    other machines without ``allow_remote`` (``risk``: why that matters, and what to do)."""
    try:
        host = section.address()[0]
    except ValueError as exc:
        return [f"{name}.{exc}"]
    if loopback_host(host) or section.allow_remote:
        return []
    return [f"{name}.listen: {section.listen} is reachable from other machines {risk}"]


class MqttConfig(MqttSettings):
    """The broker: ``url`` (``mqtt://[USER@]HOST[:PORT]/PREFIX``, as ``run --mqtt`` takes
    it; each rig publishes under ``PREFIX/RIG/``), the settings' ``mqtt`` keys,
    ``snapshots_hz`` (each rig's live pictures published at most so often, for a central
    dashboard; 0: none) and ``homeassistant`` (publish Home Assistant's discovery configs
    under ``discovery_prefix``)."""

    url: str
    snapshots_hz: float = Field(default=1.0, ge=0, le=10)
    homeassistant: bool = False
    discovery_prefix: str = Field(default="homeassistant", pattern=r"^[^#+]+$")


Policy = Literal["none", "basic256sha256"]
POLICIES: tuple[Policy, ...] = ("none", "basic256sha256")


class OpcUaConfig(StrictSchema):
    """The OPC UA server (:mod:`.opcua`): ``endpoint`` (``opc.tcp://HOST:PORT/PATH``),
    ``namespace`` (its URI), ``anonymous`` (anonymous sessions allowed), ``users_file`` (a
    YAML mapping of user names to passwords), ``security`` (the policies offered: ``none``,
    ``basic256sha256``: sign and encrypt with the server's own certificate, made on first
    start in ``certificate_dir``, default STORAGE/opcua), ``update_hz`` (measured values
    written at most so often per rig)."""

    endpoint: str = "opc.tcp://127.0.0.1:4840/thermodepth"
    namespace: str = "urn:thermodepth:monitor"
    anonymous: bool = False
    users_file: Path | None = None
    security: list[Policy] = Field(default_factory=lambda: list(POLICIES), min_length=1)
    certificate_dir: Path | None = None
    update_hz: float = Field(default=2.0, gt=0)

    def address(self) -> tuple[str, int]:
        """(host, port) of the endpoint; ValueError if it is not ``opc.tcp://HOST:PORT/...``."""
        m = re.match(r"^opc\.tcp://([^/:]+|\[[^\]]+\]):(\d+)(/.*)?$", self.endpoint)
        if m is None or not 0 < int(m.group(2)) < 65536:
            raise ValueError(
                f"endpoint: {self.endpoint!r}: expected opc.tcp://HOST:PORT/PATH "
                "(opc.tcp://127.0.0.1:4840/thermodepth)"
            )
        return m.group(1).strip("[]"), int(m.group(2))


DEFAULT_MODBUS = "127.0.0.1:5020"


class ModbusConfig(StrictSchema):
    """The Modbus TCP server (:mod:`.outputs.modbus`): ``listen`` (``HOST:PORT``; Modbus has
    no authentication: beyond this machine only with ``allow_remote``), ``unit_id`` (the
    unit it answers as), ``allow_ack`` (a coil per latched rule: writing 1 acknowledges it),
    ``word_order`` of 32-bit values (``big``: high word first)."""

    listen: str = DEFAULT_MODBUS
    unit_id: int = Field(default=1, ge=1, le=255)
    allow_ack: bool = False
    allow_remote: bool = False
    word_order: Literal["big", "little"] = "big"

    def address(self) -> tuple[str, int]:
        """(host, port) of ``listen``; ValueError if it is not ``HOST:PORT``."""
        return listen_address(self.listen, DEFAULT_MODBUS)


# -- live video (MJPEG over HTTP, RTSP) -------------------------------------------------------

DEFAULT_RTSP = "127.0.0.1:8554"
VIDEO_MAX_FPS = 30.0


class MjpegConfig(StrictSchema):
    """Each rig's live picture as MJPEG over the HTTP server (``/api/rigs/RIG/stream.mjpeg``,
    :mod:`.http`): ``fps`` (frames sent a second to each client), ``max_streams`` (streams at
    once over all rigs; one more is answered 503)."""

    fps: float = Field(default=5.0, gt=0, le=VIDEO_MAX_FPS)
    max_streams: int = Field(default=8, ge=1, le=256)


class RtspConfig(StrictSchema):
    """Each rig's live picture as H.264 over RTSP (:mod:`.outputs.rtsp`): ``listen``
    (``HOST:PORT``; beyond this machine only with ``allow_remote``), ``user`` and
    ``password_file`` (its first line: Basic authentication), ``fps``, ``bitrate_kbps`` (the
    encoder's target), ``max_viewers`` (sessions at once; one more is answered 503)."""

    listen: str = DEFAULT_RTSP
    user: str = Field(default="viewer", pattern=r"^[^:\s]+$")
    password_file: Path
    fps: float = Field(default=5.0, gt=0, le=VIDEO_MAX_FPS)
    bitrate_kbps: int = Field(default=2000, ge=100, le=50000)
    max_viewers: int = Field(default=16, ge=1, le=1024)
    allow_remote: bool = False

    def address(self) -> tuple[str, int]:
        """(host, port) of ``listen``; ValueError if it is not ``HOST:PORT``."""
        return listen_address(self.listen, DEFAULT_RTSP)


def _rtsp_problems(rtsp: RtspConfig | None) -> list[str]:
    """What is wrong with the RTSP section: its address, who could reach it, its password."""
    if rtsp is None:
        return []
    problems = listen_problems(
        "rtsp", rtsp, "(RTSP sends its password and pictures unencrypted): set "
        "rtsp.allow_remote: true, or listen on 127.0.0.1"
    )  # fmt: skip
    try:
        read_token(rtsp.password_file, "password")
    except InputError as exc:
        problems.append(f"rtsp.password_file: {exc}")
    return problems


# -- end of live video --------------------------------------------------------------------------


class FailsafeConfig(StrictSchema):
    """When a rig's data cannot be trusted (a ``sensor_fault``): ``vox_margin_c`` beyond the
    VOx range its compensation was fitted on; the shutter closed ``shutter_max_s`` on end, or
    more than ``shutter_max_share`` of the last ``shutter_window_s``; corrupt frames for
    ``corrupt_s``; ``ffc_grace_s`` more before a rig whose shutter is closing counts as
    stalled, ``startup_s`` for a rig's first frame (a camera takes a while to start); a
    fault clears once good for ``clear_s``."""

    vox_margin_c: float = Field(default=2.0, ge=0)
    shutter_max_s: float = Field(default=10.0, gt=0)
    shutter_max_share: float = Field(default=0.5, gt=0, le=1)
    shutter_window_s: float = Field(default=30.0, gt=0)
    corrupt_s: float = Field(default=1.0, ge=0)
    ffc_grace_s: float = Field(default=2.0, ge=0)
    startup_s: float = Field(default=10.0, ge=0)
    clear_s: float = Field(default=2.0, ge=0)


class LogConfig(StrictSchema):
    """The log's levels (:mod:`.logs`): ``level`` (``debug``, ``info``, ``warning``,
    ``error``) for the whole monitor, and ``rigs`` a level of its own for each rig named
    (``{press7: debug}``)."""

    level: Level = "info"
    rigs: dict[str, Level] = Field(default_factory=dict)


class ReportSchedule(StrictSchema):
    """An inspection report the monitor makes by itself (``reports:``; :mod:`.reports`):
    ``every`` ``day``, ``week`` (Monday to Sunday) or ``month`` (UTC), for the period just
    ended; ``to`` (a ``notify`` target's name, ``NAME`` or ``KIND:NAME``; none: only kept under
    the storage path); ``format`` ``pdf`` or ``html``."""

    every: Literal["day", "week", "month"]
    to: str | None = None
    format: Literal["pdf", "html"] = "pdf"


class MonitorConfig(StrictSchema):
    """The whole file (module docstring)."""

    rigs: list[RigConfig] = Field(min_length=1)
    storage: StorageConfig
    http: HttpConfig = HttpConfig()
    mqtt: MqttConfig | None = None
    opcua: OpcUaConfig | None = None
    modbus: ModbusConfig | None = None
    notify: list[NotifyConfig] = Field(default_factory=list)
    mjpeg: MjpegConfig = MjpegConfig()  # live video
    rtsp: RtspConfig | None = None  # live video
    reports: list[ReportSchedule] = Field(default_factory=list)
    failsafe: FailsafeConfig = FailsafeConfig()
    log: LogConfig = LogConfig()


def _relative(base: Path, path: Path | None) -> Path | None:
    return None if path is None else base / path


def _source_in(base: Path, spec: str) -> str:
    """A ``recording:`` or ``folder:`` spec with its path taken relative to ``base``."""
    kind, arg = spec.strip().partition(":")[::2]
    if kind in ("recording", "folder") and arg and not Path(arg).is_absolute():
        return f"{kind}:{base / arg}"
    return spec


def _resolved(config: MonitorConfig, base: Path) -> MonitorConfig:
    """Every path in ``config`` taken relative to ``base`` (the file's folder)."""
    rigs = [
        r.model_copy(
            update={"settings": _relative(base, r.settings), "source": _source_in(base, r.source)}
        )
        for r in config.rigs
    ]
    update: dict[str, object] = {
        "rigs": rigs,
        "storage": config.storage.model_copy(update={"path": base / config.storage.path}),
        "http": config.http.model_copy(
            update={
                name: _relative(base, getattr(config.http, name))
                for name in ("token_file", "tls_cert", "tls_key")
            }
        ),
    }
    if config.opcua is not None:
        update["opcua"] = config.opcua.model_copy(
            update={
                "users_file": _relative(base, config.opcua.users_file),
                "certificate_dir": _relative(base, config.opcua.certificate_dir),
            }
        )
    if config.notify:
        update["notify"] = [_notify_resolved(target, base) for target in config.notify]
    if config.rtsp is not None:  # live video
        update["rtsp"] = config.rtsp.model_copy(
            update={"password_file": base / config.rtsp.password_file}
        )
    if config.mqtt is not None:
        update["mqtt"] = config.mqtt.model_copy(
            update={
                "password_file": _relative(base, config.mqtt.password_file),
                "ca_file": _relative(base, config.mqtt.ca_file),
            }
        )
    return config.model_copy(update=update)


def _rig_problems(i: int, rig: RigConfig) -> list[str]:
    """What is wrong with a rig beyond its schema: its source spec, its settings file."""
    problems = []
    where = f"rigs.{i} ({rig.name})"
    try:
        kind, arg = check_spec(rig.source)[0]
        if rig.pace is not None and kind != "recording":
            problems.append(f"{where}.pace: only a recording: source has a pace to choose")
        if kind in ("recording", "folder") and not Path(arg).exists():
            problems.append(f"{where}.source: {arg}: no such {kind}")
    except FieldError as exc:
        problems.append(f"{where}.source: {exc.message}")
    except ThermodepthError as exc:
        problems.append(f"{where}.source: {exc}")
    if rig.settings is not None:
        try:
            settings = Settings.load(rig.settings)
        except ThermodepthError as exc:
            problems.append(f"{where}.settings: {exc}")
        else:
            problems.extend(f"{where}.settings: {line}" for line in settings_problems(settings))
    return problems


def settings_problems(settings: Settings) -> list[str]:
    """What a rig cannot start with in the files its settings lead to, one line each naming
    the settings file and its key: the calibration and the compensation model, each read
    as the rig will read it."""
    from ..calibration import Calibration
    from ..compensation import load_model

    problems = []
    for key, path, load in (("calibration", settings.calibration, Calibration.load),
                            ("compensation", settings.compensation, load_model)):  # fmt: skip
        if path is None:
            continue
        try:
            load(path)
        except ThermodepthError as exc:
            problems.append(f"{settings.where}: {key}: {exc}")
    return problems


def http_problems(
    http: HttpConfig, key: Callable[[str], str] = lambda name: f"http.{name}"
) -> list[str]:
    """What is wrong with an HTTP server's settings, one line each (``key``: how a setting
    is named to the user, ``http.listen`` in a config): its address, a token where it
    listens beyond this machine, its TLS files, its token file."""
    problems: list[str] = []
    if http.listen is not None:
        try:
            if not http.loopback() and http.token_file is None and not os.environ.get(TOKEN_ENV):
                problems.append(
                    f"{key('listen')}: {http.listen} is reachable from other machines: give "
                    f"{key('token_file')} (or {TOKEN_ENV}), or listen on 127.0.0.1"
                )
        except ValueError as exc:
            problems.append(f"{key('listen')}: {str(exc).removeprefix('listen: ')}")
    if (http.tls_cert is None) != (http.tls_key is None):
        problems.append(f"{key('tls_cert')} and {key('tls_key')} go together")
    for name in ("tls_cert", "tls_key"):
        path = getattr(http, name)
        if path is not None and not path.is_file():
            problems.append(f"{key(name)}: {path}: no such file")
    if http.token_file is not None:
        try:
            read_token(http.token_file)
        except InputError as exc:
            problems.append(f"{key('token_file')}: {exc}")
    if http.public_url is not None and not web_url(http.public_url):
        problems.append(
            f"{key('public_url')}: {http.public_url!r}: expected http(s)://HOST[:PORT][/PATH]"
        )
    return problems


def config_problems(config: MonitorConfig) -> list[str]:
    """Every problem of a valid-looking config, one line each: rig names twice, sources,
    settings files and the calibration and compensation files they name, the listen address,
    a token where one is needed, the broker's URL and password, OPC UA's users, Modbus's
    address and register room, RTSP's address and password, the log's rigs."""
    problems = []
    twice = repeated(r.name for r in config.rigs)
    if twice:
        problems.append(f"rigs: names must differ: {', '.join(map(repr, twice))} twice")
    for i, rig in enumerate(config.rigs):
        problems.extend(_rig_problems(i, rig))
    problems.extend(http_problems(config.http))
    if config.mqtt is not None:
        try:
            MqttTarget.parse(config.mqtt.url)
        except FieldError as exc:
            problems.append(f"mqtt.url: {exc.message}")
        try:
            read_password(config.mqtt)
        except InputError as exc:
            problems.append(f"mqtt.password_file: {exc}")
    problems.extend(_opcua_problems(config.opcua))
    problems.extend(_modbus_problems(config))
    problems.extend(notify_problems(config))
    problems.extend(_rtsp_problems(config.rtsp))  # live video
    problems.extend(report_problems(config))
    names = {r.name for r in config.rigs}
    problems.extend(
        f"log.rigs.{rig}: no rig of that name ({', '.join(sorted(names))})"
        for rig in config.log.rigs
        if rig not in names
    )
    return problems


def read_users(path: Path) -> dict[str, str]:
    """The users and their passwords (a YAML mapping of names to passwords); InputError when
    it is not one."""
    users = read_mapping(path)
    bad = [k for k, v in users.items() if not isinstance(v, str) or not v]
    if bad:
        raise InputError(f"{path}: {', '.join(map(repr, bad))}: give each user a password")
    return {str(k): str(v) for k, v in users.items()}


def _opcua_problems(opcua: OpcUaConfig | None) -> list[str]:
    """What is wrong with the OPC UA section: its endpoint, its users, who could connect."""
    if opcua is None:
        return []
    problems = []
    try:
        opcua.address()
    except ValueError as exc:
        problems.append(f"opcua.{exc}")
    if opcua.users_file is not None:
        try:
            read_users(opcua.users_file)
        except InputError as exc:
            problems.append(f"opcua.users_file: {exc}")
    elif not opcua.anonymous:
        problems.append(
            "opcua: nobody could connect: give users_file (user: password), or anonymous: true"
        )
    return problems


def _modbus_problems(config: MonitorConfig) -> list[str]:
    """What is wrong with the Modbus section: its address, who could reach it (Modbus has no
    authentication), the rigs, ROIs and rules beyond its register map's room."""
    modbus = config.modbus
    if modbus is None:
        return []
    problems = listen_problems(
        "modbus", modbus, "and Modbus has no authentication: set modbus.allow_remote: true "
        "(on a control network only), or listen on 127.0.0.1"
    )  # fmt: skip
    from .outputs.modbus import room_problems  # the register map's room is its module's

    return problems + room_problems(config)


def read_token(path: Path, what: str = "token") -> str:
    """The bearer token (or the ``what`` a file holds): the file's first line (InputError if
    unreadable or empty)."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if not lines or not lines[0].strip():
        raise InputError(f"{path}: empty (the first line is the {what})")
    return lines[0].strip()


def load_config(path: str | Path) -> MonitorConfig:
    """Read and check a monitor config; one InputError whose lines each name the file and one
    problem."""
    p = Path(path)
    data = read_mapping(p)
    try:
        config = _resolved(MonitorConfig.model_validate(data), p.parent)
    except ValidationError as exc:
        raise InputError("\n".join(f"{p}: {line}" for line in validation_lines(exc))) from None
    problems = config_problems(config)
    if problems:
        raise InputError("\n".join(f"{p}: {line}" for line in problems))
    return config


# -- notifications (the notify: list; one output per target, outputs/notify.py) ---------------

NOTIFY_EVENTS = ("alarm", "escalated", "acknowledged", "clear")
"""The event kinds a target's ``events`` may name (besides rule names)."""
FAULT_RULES = ("sensor_fault", "storage_fault")


class NotifyTarget(StrictSchema):
    """What every notification target has: ``name`` (unique; its name in ``/api/status`` and
    its rows' in the outbox: keep it across restarts; default ``KIND-HOST``), ``events``
    (which go: an event goes when its kind, ``alarm``, ``escalated``, ``acknowledged``,
    ``clear``, or its rule, ``hot``, ``sensor_fault``, ``storage_fault``, is listed),
    ``max_per_hour`` (messages at most; beyond it events are held back and sent as one
    digest when the hour allows), ``timeout_s`` (one attempt), ``ca_file`` (a PEM bundle to
    trust instead of the system's: a private CA)."""

    kind: str
    name: str | None = Field(default=None, pattern=r"^[A-Za-z0-9][A-Za-z0-9_.@-]*$")
    events: list[str] = Field(default_factory=lambda: ["alarm", "escalated"], min_length=1)
    max_per_hour: int = Field(default=60, ge=1)
    timeout_s: float = Field(default=10.0, gt=0)
    ca_file: Path | None = None

    def target_name(self) -> str:
        """``KIND:NAME``: its outbox rows' and ``/api/status``'s name."""
        return f"{self.kind}:{self.name or self.default_name()}"

    def default_name(self) -> str:
        raise NotImplementedError

    def goes(self, event: dict[str, object]) -> bool:
        """Whether ``events`` lets an event through (its kind or its rule listed)."""
        return event.get("event") in self.events or event.get("rule") in self.events


class WebhookConfig(NotifyTarget):
    """A webhook: ``url`` (``https://...``) gets a JSON POST of each event, signed with the
    first line of ``secret_file`` (HMAC-SHA256 of the body, ``X-Thermodepth-Signature``)."""

    kind: Literal["webhook"]
    url: str
    secret_file: Path

    def default_name(self) -> str:
        return urlsplit(self.url).hostname or "webhook"


class EmailConfig(NotifyTarget):
    """E-mail: ``smtp`` (``HOST[:PORT]``, port 587 with ``starttls``, else 25), ``starttls``
    (upgrade to TLS before anything is said; the certificate verified), ``user`` and
    ``password_file`` (its first line; AUTH only over TLS), ``from``, ``to`` (addresses)."""

    kind: Literal["email"]
    smtp: str
    starttls: bool = True
    user: str | None = None
    password_file: Path | None = None
    sender: str = Field(alias="from")
    to: list[str] = Field(min_length=1)

    def default_name(self) -> str:
        return self.to[0]

    def address(self) -> tuple[str, int]:
        """(host, port) of ``smtp``; ValueError when it is not ``HOST[:PORT]``."""
        host, sep, port = self.smtp.rpartition(":")
        if not sep:
            host, port = self.smtp, "587" if self.starttls else "25"
        if not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise ValueError(f"{self.smtp!r}: expected HOST[:PORT] (mail.example:587)")
        return host.strip("[]"), int(port)


NotifyConfig = Annotated[WebhookConfig | EmailConfig, Field(discriminator="kind")]


def web_url(url: str) -> bool:
    """``url`` is ``http(s)://HOST...``."""
    parts = urlsplit(url)
    return parts.scheme in ("http", "https") and bool(parts.hostname)


def first_line(path: Path, what: str) -> str:
    """A secret's file's first line (InputError naming the file when unreadable or empty)."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise InputError(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    if not lines or not lines[0].strip():
        raise InputError(f"{path}: empty (the first line is the {what})")
    return lines[0].strip()


def _notify_resolved(
    target: WebhookConfig | EmailConfig, base: Path
) -> WebhookConfig | EmailConfig:
    keys = ("ca_file", "secret_file", "password_file")
    return target.model_copy(
        update={k: _relative(base, getattr(target, k)) for k in keys if hasattr(target, k)}
    )


def report_target(config: MonitorConfig, name: str) -> WebhookConfig | EmailConfig | None:
    """The ``notify`` target a report goes to: by ``KIND:NAME`` or by its ``NAME``."""
    return next(
        (t for t in config.notify if name in (t.target_name(), t.target_name().split(":", 1)[1])),
        None,
    )


def report_problems(config: MonitorConfig) -> list[str]:
    """A scheduled report sent to a target that is not in ``notify``."""
    problems = []
    names = [t.target_name() for t in config.notify]
    for i, r in enumerate(config.reports):
        if r.to is not None and report_target(config, r.to) is None:
            known = ", ".join(names) or "none"
            problems.append(f"reports.{i}.to: {r.to!r}: no notify target of that name ({known})")
    return problems


def notify_problems(config: MonitorConfig) -> list[str]:
    """What is wrong with the ``notify`` list, one line each: names twice, a URL or an SMTP
    address, the secret and password files, ``events`` naming neither an event kind nor a
    rule of any rig."""
    problems = []
    names = [t.target_name() for t in config.notify]
    twice = repeated(names)
    if twice:
        problems.append(
            f"notify: {', '.join(map(repr, twice))} twice: give each target its own name"
        )
    rules = set(FAULT_RULES)
    for rig in config.rigs:
        with contextlib.suppress(ThermodepthError):  # told as the rig's own problem
            rules |= {a.name for a in (Settings.load(rig.settings).alarms if rig.settings else ())}
    for i, t in enumerate(config.notify):
        where = f"notify.{i} ({t.target_name()})"
        unknown = [w for w in t.events if w not in NOTIFY_EVENTS and w not in rules]
        if unknown:
            problems.append(
                f"{where}.events: {', '.join(map(repr, unknown))}: neither an event "
                f"({', '.join(NOTIFY_EVENTS)}) nor a rule ({', '.join(sorted(rules))})"
            )
        if t.ca_file is not None and not t.ca_file.is_file():
            problems.append(f"{where}.ca_file: {t.ca_file}: no such file")
        if isinstance(t, WebhookConfig):
            if not web_url(t.url):
                problems.append(f"{where}.url: {t.url!r}: expected https://HOST[:PORT]/PATH")
            secrets: list[tuple[str, Path | None, str]] = [
                ("secret_file", t.secret_file, "webhook's secret")
            ]
        else:
            try:
                t.address()
            except ValueError as exc:
                problems.append(f"{where}.smtp: {exc}")
            bad = [a for a in (t.sender, *t.to) if "@" not in a]
            if bad:
                problems.append(f"{where}: {', '.join(map(repr, bad))}: not an e-mail address")
            if (t.user is None) != (t.password_file is None):
                problems.append(f"{where}: user and password_file go together")
            if t.user is not None and not t.starttls:
                problems.append(f"{where}: a password is only sent over TLS: set starttls: true")
            secrets = [("password_file", t.password_file, "SMTP password")]
        for key, path, what in secrets:
            if path is not None:
                try:
                    first_line(path, what)
                except InputError as exc:
                    problems.append(f"{where}.{key}: {exc}")
    return problems


MonitorConfig.model_rebuild()  # its notify list's types are defined in the block above
