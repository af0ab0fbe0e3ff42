"""The monitor as an OPC UA server (asyncua, on a thread and event loop of its own; the
``opcua:`` section of the monitor's config), for a plant's SCADA and historians.

Its namespace (``opcua.namespace``, default ``urn:thermodepth:monitor``) holds, under
Objects, one object ``Thermodepth`` and in it one object per rig; node ids are strings in
the namespace, the path joined by dots (``ns=2;s=line1.Rois.plate.Max``):

===================================  =========================================================
node                                 what
===================================  =========================================================
``RIG.Health``                       String: ``ok``, ``stale`` (no fresh data) or ``fault`` (a
                                     sensor fault)
``RIG.Up``                           Boolean: fresh data
``RIG.FramesPerSecond``              Double
``RIG.VoxTemperature``               Double, C: the thermal camera's sensor (NaN: not told)
``RIG.Hottest``                      Double, C: the hottest hotspot's max (NaN: none)
``RIG.Rois.ROI.Max`` / ``Mean`` /    Double, C: each ROI's statistics (NaN: no valid pixel)
``Min``
``RIG.Rois.ROI.Priority``            Double: the ROI's severity class (thermodepth.severity):
                                     its priority (1 most urgent), 0 below its table's first
                                     row, NaN no class (no severity set, no reading)
``RIG.Rois.ROI.Severity`` /          String: the class's words; Double, C: its delta-T (NaN:
``DeltaT``                           none)
``RIG.Alarms.RULE.Raised``           Boolean; ``.Level`` (``warning``, ``alarm``) and
                                     ``.State`` (the rule's last event: ``alarm``,
                                     ``escalated``, ``acknowledged``, ``clear``)
``RIG.SensorFault``                  Boolean: a sensor fault is raised
===================================  =========================================================

Measured values carry their frame's capture time as source timestamp and are written at most
``update_hz`` a second per rig (the last frame of a session always). Every event of a rig is
also an OPC UA event (BaseEventType) emitted by the rig's object: its ``SourceName`` is the
rule, its ``Message`` the event's line, its ``Severity`` 800 for an alarm, 500 for a warning,
300 for an acknowledgement, 100 for a clear.

Access: anonymous only when ``anonymous: true``; users and passwords from ``users_file`` (a
YAML mapping); security policies ``none`` and ``basic256sha256`` (sign and encrypt, with the
server's own certificate, made on first start in ``certificate_dir``).
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import logging
import math
import socket
import threading
import time
from collections.abc import Coroutine
from datetime import timezone
from typing import TYPE_CHECKING, Any

from ...errors import InputError
from ...pipeline import FusedFrame
from ..config import OpcUaConfig, read_users
from ..failsafe import SENSOR_FAULT
from ..logs import logger
from ..workers import Worker
from .base import Output, OutputContext, RigEntities, check_port

if TYPE_CHECKING:
    from asyncua import Node, Server

INSTALL = "the monitor's OPC UA server needs the opcua extra: pip install 'thermodepth[opcua]'"
SEVERITY = {"alarm": 800, "escalated": 800, "acknowledged": 300, "clear": 100}
STATS = ("Max", "Mean", "Min")
STATUS_EVERY_S = 1.0
BEAT_S = 0.5
WORKER_LIMIT_S = 30.0
RELEASE_S = 10.0
"""How long the end of a server's loop waits for its tasks and its stop, at most."""


async def _none() -> None:
    """Nothing to wait for."""


class OpcUaOutput(Output):
    """The server of a monitor's rigs (module docstring); ``start`` binds its endpoint (one
    InputError line when it cannot) and serves on a worker of its own (restarted when it
    fails); the rest may come from any thread and never waits for the server."""

    name = "opcua"

    def __init__(self, config: OpcUaConfig, context: OutputContext) -> None:
        try:
            import asyncua  # noqa: F401
        except ImportError:
            raise InputError(INSTALL) from None
        self.config, self.rigs, self.context = config, context.rigs, context
        self.log = logger("opcua")
        self.certificates = config.certificate_dir or context.config.storage.path / "opcua"
        self.users = read_users(config.users_file) if config.users_file else {}
        self.nodes: dict[str, Node] = {}
        self.emitters: dict[str, Any] = {}
        self.loop: asyncio.AbstractEventLoop | None = None
        self.server: Server | None = None
        self.namespace = 0
        self._last: dict[str, float] = {}
        self._last_status = float("-inf")
        self._pending: dict[str, FusedFrame] = {}  # a rig's newest frame not yet written
        self._lock = threading.Lock()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self.worker = Worker("opcua", self._main, BEAT_S * 4, WORKER_LIMIT_S, self.log)

    def describe(self) -> str:
        return describe(self.config)

    # -- the server's own worker ---------------------------------------------------------------

    def start(self, timeout_s: float = 30.0) -> None:
        check_port(*self.config.address(), f"opcua.endpoint: {self.config.endpoint}")
        self.worker.start()
        if not self._ready.wait(timeout_s) or self._error is not None:
            self.worker.stop()
            raise InputError(f"opcua: the server did not start ({self._error or 'no answer'})")

    def workers(self) -> list[Worker]:
        return [self.worker]

    def fits(self, rigs: list[RigEntities]) -> bool:
        return rigs == self.rigs

    def _main(self, worker: Worker) -> None:
        loop = asyncio.new_event_loop()
        try:
            loop.run_until_complete(self._serve(worker))
        except BaseException as exc:
            if not self._ready.is_set():  # told by start()
                self._error = exc
                self._ready.set()
                return
            raise
        finally:
            self.loop = None
            self._release(loop)

    def _release(self, loop: asyncio.AbstractEventLoop) -> None:
        """However the serving ended (its loop stopped under it, say), the server stopped,
        its port let go for the restart to bind again, and the loop closed."""
        tasks = asyncio.all_tasks(loop)
        for task in tasks:
            task.cancel()
        with contextlib.suppress(BaseException):  # bounded: a task may ignore its cancelling
            loop.run_until_complete(asyncio.wait(tasks, timeout=RELEASE_S) if tasks else _none())
        server, self.server = self.server, None
        if server is not None:
            with contextlib.suppress(BaseException):
                loop.run_until_complete(asyncio.wait_for(server.stop(), RELEASE_S))
        loop.close()

    async def _serve(self, worker: Worker) -> None:
        from asyncua import Server, ua
        from asyncua.crypto.permission_rules import SimpleRoleRuleset
        from asyncua.server.user_managers import User, UserManager, UserRole

        logging.getLogger("asyncua").setLevel(logging.ERROR)
        users, anonymous = self.users, self.config.anonymous
        # asyncua opens an unsecured channel whatever the endpoints offer: without policy
        # "none", a session is refused unless its channel carries the client's certificate
        secure_only = "none" not in self.config.security

        class Users(UserManager):
            def get_user(
                self,
                iserver: Any,
                username: str | None = None,
                password: str | None = None,
                certificate: Any = None,
            ) -> User | None:
                if secure_only and certificate is None:
                    return None
                if username is None:
                    return User(role=UserRole.User, name="anonymous") if anonymous else None
                known = users.get(username)
                ok = known is not None and hmac.compare_digest(known, password or "")
                return User(role=UserRole.User, name=username) if ok else None

        server = Server(user_manager=Users())
        await server.init()
        server.set_endpoint(self.config.endpoint)
        server.set_server_name("thermodepth monitor")
        tokens: list[type] = [ua.UserNameIdentityToken]
        if anonymous:
            tokens.append(ua.AnonymousIdentityToken)
        server.set_identity_tokens(tokens)
        policies = []
        if "none" in self.config.security:
            policies.append(ua.SecurityPolicyType.NoSecurity)
        if "basic256sha256" in self.config.security:
            policies.append(ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt)
            await self._certificate(server)
        server.set_security_policy(policies, permission_ruleset=SimpleRoleRuleset())
        self.nodes, self.emitters = {}, {}
        self.namespace = await server.register_namespace(self.config.namespace)
        await self._address_space(server)
        self.server = server
        async with server:
            self.loop = asyncio.get_running_loop()
            self._ready.set()
            while not worker.stopping.is_set():
                worker.beat()
                await asyncio.sleep(BEAT_S)
        self.server = None  # stopped by the block's end

    async def _certificate(self, server: Server) -> None:
        """The server's key and self-signed certificate, made on first start."""
        from asyncua.crypto.cert_gen import setup_self_signed_certificate
        from cryptography.x509.oid import ExtendedKeyUsageOID

        self.certificates.mkdir(parents=True, exist_ok=True)
        key, cert = self.certificates / "server-key.pem", self.certificates / "server-cert.der"
        host = socket.gethostname()
        await setup_self_signed_certificate(
            key,
            cert,
            server.get_application_uri(),
            host,
            [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH],
            {"commonName": f"thermodepth monitor on {host}", "organizationName": "thermodepth"},
        )
        await server.load_certificate(str(cert))
        await server.load_private_key(str(key))

    def _id(self, path: str) -> Any:
        """The node id of a path in our namespace (a string id)."""
        from asyncua import ua

        return ua.NodeId(ua.String(path), ua.Int16(self.namespace))

    async def _address_space(self, server: Server) -> None:
        from asyncua import ua

        root = await server.nodes.objects.add_object(self._id("Thermodepth"), "Thermodepth")

        async def variable(parent: Node, path: str, name: str, value: Any, kind: Any) -> None:
            node = await parent.add_variable(self._id(path), name, ua.Variant(value, kind))
            self.nodes[path] = node

        d, s, b = ua.VariantType.Double, ua.VariantType.String, ua.VariantType.Boolean
        for rig in self.rigs:
            obj = await root.add_object(self._id(rig.name), rig.name)
            if rig.location:
                await obj.write_attribute(
                    ua.AttributeIds.Description,
                    ua.DataValue(ua.Variant(ua.LocalizedText(rig.location))),
                )
            self.emitters[rig.name] = await server.get_event_generator(emitting_node=obj.nodeid)
            await variable(obj, f"{rig.name}.Health", "Health", "stale", s)
            await variable(obj, f"{rig.name}.Up", "Up", False, b)
            await variable(obj, f"{rig.name}.FramesPerSecond", "FramesPerSecond", 0.0, d)
            await variable(obj, f"{rig.name}.VoxTemperature", "VoxTemperature", math.nan, d)
            await variable(obj, f"{rig.name}.Hottest", "Hottest", math.nan, d)
            await variable(obj, f"{rig.name}.SensorFault", "SensorFault", False, b)
            rois = await obj.add_object(self._id(f"{rig.name}.Rois"), "Rois")
            for roi in rig.rois:
                folder = await rois.add_object(self._id(f"{rig.name}.Rois.{roi}"), roi)
                for stat in STATS:
                    await variable(folder, f"{rig.name}.Rois.{roi}.{stat}", stat, math.nan, d)
                for name, start, kind in SEVERITY_NODES:
                    await variable(folder, f"{rig.name}.Rois.{roi}.{name}", name, start, kind(ua))
            alarms = await obj.add_object(self._id(f"{rig.name}.Alarms"), "Alarms")
            for rule in rig.rules:
                node = await alarms.add_object(self._id(f"{rig.name}.Alarms.{rule}"), rule)
                await variable(node, f"{rig.name}.Alarms.{rule}.Raised", "Raised", False, b)
                await variable(node, f"{rig.name}.Alarms.{rule}.Level", "Level", "", s)
                await variable(node, f"{rig.name}.Alarms.{rule}.State", "State", "", s)

    # -- what the monitor tells it (any thread) ------------------------------------------------

    def _submit(self, work: Coroutine[Any, Any, None]) -> None:
        if self.loop is None or self.loop.is_closed():
            work.close()
            return
        asyncio.run_coroutine_threadsafe(work, self.loop)

    async def _write(self, values: dict[str, Any], time_s: float | None) -> None:
        from asyncua import ua

        stamp = None if time_s is None else ua.DateTime.fromtimestamp(time_s, timezone.utc)
        for path, value in values.items():
            node = self.nodes.get(path)
            if node is None:
                continue
            kind = (
                ua.VariantType.Boolean
                if isinstance(value, bool)
                else ua.VariantType.String
                if isinstance(value, str)
                else ua.VariantType.Double
            )
            await node.write_value(ua.DataValue(ua.Variant(value, kind), SourceTimestamp=stamp))

    def measured(self, rig: str, fused: FusedFrame) -> None:
        """A rig's fused frame: its readings, at most ``update_hz`` a second; a frame held
        back is written by :meth:`flush` once its time comes, unless a newer one was."""
        with self._lock:
            self._pending[rig] = fused
        self.flush(rig)

    def flush(self, only: str | None = None) -> None:
        """Write the frames held back whose time has come (the monitor's clock calls it, so
        that a rig's last frame is always written)."""
        now = time.monotonic()
        with self._lock:
            due = [
                (rig, fused)
                for rig, fused in self._pending.items()
                if (only is None or rig == only)
                and now - self._last.get(rig, -math.inf) >= 1.0 / self.config.update_hz
            ]
            for rig, _ in due:
                self._last[rig] = now
                del self._pending[rig]
        for rig, fused in due:
            self._write_frame(rig, fused)

    def _write_frame(self, rig: str, fused: FusedFrame) -> None:
        hot = fused.hotspots[0].max_c if fused.hotspots else math.nan
        values: dict[str, Any] = {
            f"{rig}.Hottest": float(hot),
            f"{rig}.VoxTemperature": float(fused.vox_temp_c),
        }
        for roi in fused.rois:
            for stat in STATS:
                value = getattr(roi, f"{stat.lower()}_c") if roi.n else math.nan
                values[f"{rig}.Rois.{roi.name}.{stat}"] = float(value)
            values.update(severity_values(f"{rig}.Rois.{roi.name}", roi.severity))
        self._submit(self._write(values, fused.thermal_time_s))

    def tick(self, now_mono: float) -> None:
        """The frames held back whose time has come; every rig's figures each second."""
        self.flush()
        if now_mono - self._last_status >= STATUS_EVERY_S:
            self._last_status = now_mono
            for rig in self.context.rig_status():
                self.rig_status(rig)

    def rig_status(self, rig: dict[str, Any]) -> None:
        """A rig's figures (``Monitor.status``'s entry)."""
        values = {
            f"{rig['name']}.Health": rig["health"],
            f"{rig['name']}.Up": bool(rig["up"]),
            f"{rig['name']}.FramesPerSecond": float(rig["fps"]),
            f"{rig['name']}.SensorFault": any(
                a["rule"] == "sensor_fault" for a in rig["active_alarms"]
            ),
        }
        self._submit(self._write(values, None))

    def events(self, rig: str, events: list[dict[str, Any]], raised: set[str]) -> None:
        for event in events:
            rule = event["rule"]
            self.event({**event, "rig": rig}, None if rule == SENSOR_FAULT else rule in raised)

    def event(self, event: dict[str, Any], raised: bool | None) -> None:
        """An event of a rig: its rule's state (``raised``: whether it is raised now; None
        for a sensor fault), and an OPC UA event."""
        rig, rule = event["rig"], event["rule"]
        values: dict[str, Any] = {}
        if raised is not None:
            values = {
                f"{rig}.Alarms.{rule}.Raised": raised,
                f"{rig}.Alarms.{rule}.Level": event.get("level", ""),
                f"{rig}.Alarms.{rule}.State": event["event"],
            }
        self._submit(self._emit(event, values))

    async def _emit(self, event: dict[str, Any], values: dict[str, Any]) -> None:
        from asyncua import ua

        from ...alarms import event_line

        await self._write(values, event.get("time_s"))
        emitter = self.emitters.get(event["rig"])
        if emitter is None:
            return
        emitter.event.SourceName = event["rule"]
        emitter.event.Severity = SEVERITY.get(event["event"], 500) - (
            300 if event.get("level") == "warning" and event["event"] != "clear" else 0
        )
        emitter.event.Message = ua.LocalizedText(event_line(event))
        await emitter.trigger()

    def status(self) -> dict[str, Any]:
        return {"endpoint": self.config.endpoint, "serving": self.loop is not None}


SEVERITY_NODES: tuple[tuple[str, Any, Any], ...] = (
    ("Priority", math.nan, lambda ua: ua.VariantType.Double),
    ("Severity", "", lambda ua: ua.VariantType.String),
    ("DeltaT", math.nan, lambda ua: ua.VariantType.Double),
)
"""Each ROI's severity nodes: name, first value, type (module docstring)."""


def severity_values(path: str, severity: dict[str, Any] | None) -> dict[str, Any]:
    """The values of an ROI's severity nodes (``path``: the ROI's node path) for its class."""
    if not severity or severity.get("delta_t_c") is None:
        return {f"{path}.Priority": math.nan, f"{path}.Severity": "", f"{path}.DeltaT": math.nan}
    priority = severity.get("priority")
    return {
        f"{path}.Priority": 0.0 if priority is None else float(priority),
        f"{path}.Severity": str(severity.get("label", "")),
        f"{path}.DeltaT": float(severity["delta_t_c"]),
    }


def describe(config: OpcUaConfig) -> str:
    """The output of an ``opcua`` section in one line."""
    users = "users from " + str(config.users_file) if config.users_file else "no users"
    who = f"anonymous and {users}" if config.anonymous else users
    return f"OPC UA {config.endpoint} (security {', '.join(config.security)}; {who})"
