"""The monitor as a Modbus TCP server (pymodbus, on a thread and event loop of its own; the
``modbus:`` section of the monitor's config), for PLCs.

Every rig has a block of its own in each table, in the config's order (rig ``r`` counted from
0): registers ``256·r`` to ``256·r + 255``, bits ``64·r`` to ``64·r + 63``, so that a rig, ROI
or rule added at the end moves no other. ROIs and rules are numbered by their order in the
rig's settings (``i``, ``j`` from 0); a rig has room for :data:`MAX_ROIS` ROIs and
:data:`MAX_RULES` rules (a config with more is refused). Addresses are the protocol's, from 0:

=============  ============  =========  ==========================================  =========
offset         table         type       what                                        scale
=============  ============  =========  ==========================================  =========
0              input         uint16     heartbeat: +1 each fused frame (wraps)      1
1              input         uint16     health: 0 ok, 1 stale, 2 fault              1
2              input         int16      the hottest hotspot's max, C                0.1
4              input         float32    the same, C                                 1
6              input         uint32     fused frames since the server started       1
16 + 10·i      input         int16      ROI i's max, mean, min (3 registers), C     0.1
19 + 10·i      input         uint16     ROI i's severity class: its priority (1     1
                                        most urgent); 0 below its table's first
                                        row; 65535 no class (no severity, no
                                        reading)
20 + 10·i      input         float32    ROI i's max, mean, min (6 registers), C     1
0              discrete      bool       a sensor fault is raised                    1
1 + j          discrete      bool       rule j is raised                            1
1 + j          coil          bool       latched rule j is acknowledged; write 1 to  1
                                        acknowledge it (only with ``allow_ack``)
=============  ============  =========  ==========================================  =========

The holding registers (function 3) read as the input registers (function 4), for clients
that read only those; none can be written (exception 01). Health: 2 while a sensor fault is
raised (its ``no_data`` too, once a rig has sent nothing for its ``stall_s``), else 1 while
the rig has no fresh data (``/api/status``'s ``stale``), else 0. No value (no hotspot, an ROI
without a valid pixel, before the first frame): int16 -32768 and float32 NaN; an int16 beyond
its range is held at -32767 or 32767. 32-bit values are high word first (``word_order:
little``: low word first). Unused offsets read 0; an address beyond the last rig's block
answers exception 02; another unit id than ``unit_id`` answers exception 0B. The map is
:func:`register_map` (``thermodepth monitor CONFIG --modbus-map`` prints it as CSV).
"""

from __future__ import annotations

import asyncio
import contextlib
import csv
import io
import logging
import math
import struct
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple

from ...errors import InputError
from ...pipeline import FusedFrame
from ..config import ModbusConfig, MonitorConfig
from ..failsafe import SENSOR_FAULT
from ..logs import logger
from ..supervisor import AckRefusedError
from ..workers import Worker
from .base import Output, OutputContext, RigEntities, check_port, entities_of

if TYPE_CHECKING:
    from pymodbus.server import ModbusTcpServer

INSTALL = "the monitor's Modbus server needs the modbus extra: pip install 'thermodepth[modbus]'"
RIG_REGISTERS = 256
RIG_BITS = 64
MAX_RIGS = 65536 // RIG_REGISTERS
ROI_BASE = 16
ROI_STRIDE = 10
MAX_ROIS = (RIG_REGISTERS - ROI_BASE) // ROI_STRIDE
RULE_BASE = 1
MAX_RULES = 48
STATS = ("max", "mean", "min")
NO_INT16 = -32768
NO_CLASS = 65535
"""An ROI's priority register without a class (no severity set, no reading)."""
HEALTH = {"ok": 0, "stale": 1, "fault": 2}
STATUS_EVERY_S = 1.0
BEAT_S = 0.5
WORKER_LIMIT_S = 30.0
TABLES = ("input", "holding", "coil", "discrete")
CSV_COLUMNS = ("address", "table", "type", "scale", "unit", "rig", "name")
READ_ONLY = {6, 16, 22, 23}
"""The functions that would write holding registers."""


class Register(NamedTuple):
    """One entry of the register map: where (``address``, ``table``), how (``type``, the value
    is raw x ``scale`` in ``unit``), what (``rig``, ``name``; ``key``: the value it shows)."""

    address: int
    table: str
    type: str
    scale: float
    unit: str
    rig: str
    name: str
    key: tuple[Any, ...]


def register_map(rigs: list[RigEntities], allow_ack: bool) -> list[Register]:
    """Every register and bit the server serves for ``rigs`` (in the config's order), by
    table then address (module docstring). The one map the server and ``--modbus-map``
    use."""
    regs: list[Register] = []
    for r, rig in enumerate(rigs):
        base, bits = r * RIG_REGISTERS, r * RIG_BITS

        def reg(offset: int, kind: str, scale: float, unit: str, name: str, *key: Any) -> None:
            regs.append(Register(base + offset, "input", kind, scale, unit, rig.name, name, key))  # noqa: B023

        reg(0, "uint16", 1, "", "heartbeat", "heartbeat")
        reg(1, "uint16", 1, "", "health", "health")
        reg(2, "int16", 0.1, "C", "hottest_c_x10", "hottest")
        reg(4, "float32", 1, "C", "hottest_c", "hottest")
        reg(6, "uint32", 1, "", "frames", "frames")
        for i, roi in enumerate(rig.rois):
            at = ROI_BASE + ROI_STRIDE * i
            for k, stat in enumerate(STATS):
                reg(at + k, "int16", 0.1, "C", f"roi.{roi}.{stat}_c_x10", "roi", i, k)
            for k, stat in enumerate(STATS):
                reg(at + 4 + 2 * k, "float32", 1, "C", f"roi.{roi}.{stat}_c", "roi", i, k)
            reg(at + 3, "uint16", 1, "", f"roi.{roi}.priority", "priority", i)
        regs.append(Register(bits, "discrete", "bool", 1, "", rig.name, SENSOR_FAULT, ("fault",)))
        for j, rule in enumerate(rig.rules):
            at = bits + RULE_BASE + j
            key = ("raised", rule)
            regs.append(Register(at, "discrete", "bool", 1, "", rig.name, f"rule.{rule}", key))
            if allow_ack and rule in rig.latched:
                name, key = f"rule.{rule}.ack", ("acked", rule)
                regs.append(Register(at, "coil", "bool", 1, "", rig.name, name, key))
    return sorted(regs, key=lambda g: (TABLES.index(g.table), g.address))


def map_csv(rigs: list[RigEntities], allow_ack: bool) -> str:
    """The register map as CSV (``--modbus-map``): ``address,table,type,scale,unit,rig,name``
    (address: the protocol's, from 0)."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for g in register_map(rigs, allow_ack):
        writer.writerow([g.address, g.table, g.type, f"{g.scale:g}", g.unit, g.rig, g.name])
    return out.getvalue()


def config_map_csv(config: MonitorConfig) -> str:
    """The register map of a config's rigs (its settings files read), as CSV; without a
    ``modbus`` section, the map one with its defaults would serve (a PLC's tags can be made
    before the server is turned on)."""
    return map_csv(entities_of(config), (config.modbus or ModbusConfig()).allow_ack)


def room_problems(config: MonitorConfig) -> list[str]:
    """The rigs, ROIs and rules beyond the register map's room, one line each (settings
    that cannot be read are told elsewhere)."""
    from ...errors import ThermodepthError
    from ...pipeline import Settings

    problems = []
    if len(config.rigs) > MAX_RIGS:
        problems.append(
            f"modbus: {len(config.rigs)} rigs: the register map has room for {MAX_RIGS}"
        )
    for i, rig in enumerate(config.rigs):
        try:
            settings = Settings.load(rig.settings) if rig.settings else Settings()
        except ThermodepthError:
            continue
        for what, n, room in (("ROIs", len(settings.rois), MAX_ROIS),
                              ("alarm rules", len(settings.alarms), MAX_RULES)):  # fmt: skip
            if n > room:
                problems.append(
                    f"rigs.{i} ({rig.name}).settings: {n} {what}: the Modbus register map "
                    f"has room for {room} per rig"
                )
    return problems


def int16_raw(value_c: float, scale: float) -> int:
    """A value as an int16 register of ``scale`` (NaN: -32768; beyond its range: held at
    -32767 or 32767), as the 16 bits sent."""
    if math.isnan(value_c):
        return NO_INT16 & 0xFFFF
    raw = value_c / scale
    held = -32767 if raw < -32767 else 32767 if raw > 32767 else round(raw)
    return held & 0xFFFF


def priority_raw(severity: dict[str, Any] | None) -> int:
    """An ROI's severity class as its priority register: the priority, 0 below the table's
    first row, :data:`NO_CLASS` without a class (no severity, no reading)."""
    if not severity or severity.get("delta_t_c") is None:
        return NO_CLASS
    return 0 if severity.get("priority") is None else int(severity["priority"])


def words(value: float | int, kind: str, big: bool) -> list[int]:
    """A 32-bit value (``float32`` or ``uint32``) as two registers, high word first when
    ``big``."""
    packed = struct.pack(">f", value) if kind == "float32" else struct.pack(">I", int(value))
    hi, lo = struct.unpack(">HH", packed)
    return [hi, lo] if big else [lo, hi]


@dataclass
class RigValues:
    """What the server shows of one rig (written by the monitor's threads, read by the
    server's)."""

    frames: int = 0
    hottest_c: float = math.nan
    rois_c: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    priorities: dict[str, int] = field(default_factory=dict)
    health: int = HEALTH["stale"]
    raised: set[str] = field(default_factory=set)
    acked: set[str] = field(default_factory=set)


class ModbusOutput(Output):
    """The Modbus server of a monitor's rigs (module docstring); ``start`` binds its port (one
    InputError line when it cannot) and serves on a worker of its own (restarted when it
    fails); ``measured`` and the rest only store values, the server encodes them when read."""

    name = "modbus"

    def __init__(self, config: ModbusConfig, context: OutputContext) -> None:
        try:
            import pymodbus  # noqa: F401
        except ImportError:
            raise InputError(INSTALL) from None
        self.config, self.rigs, self.context = config, context.rigs, context
        self.log = logger("modbus")
        self.map = register_map(self.rigs, config.allow_ack)
        self.values = {rig.name: RigValues() for rig in self.rigs}
        self._rois = {rig.name: rig.rois for rig in self.rigs}
        self._last_status = float("-inf")
        self._lock = threading.Lock()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self.server: ModbusTcpServer | None = None
        self.acknowledged = 0
        self.worker = Worker("modbus", self._main, BEAT_S * 4, WORKER_LIMIT_S, self.log)

    def describe(self) -> str:
        return describe(self.config)

    # -- what the monitor tells it (any thread: values stored, nothing waits) -------------------

    def measured(self, rig: str, fused: FusedFrame) -> None:
        hot = fused.hotspots[0].max_c if fused.hotspots else math.nan
        rois = {
            r.name: (r.max_c, r.mean_c, r.min_c) if r.n else (math.nan,) * 3 for r in fused.rois
        }
        priorities = {r.name: priority_raw(r.severity) for r in fused.rois}
        with self._lock:
            v = self.values.get(rig)
            if v is not None:
                v.frames += 1
                v.hottest_c, v.rois_c, v.priorities = float(hot), rois, priorities

    def announce(self, raised: dict[str, set[str]]) -> None:
        with self._lock:
            for rig, rules in raised.items():
                if rig in self.values:
                    self.values[rig].raised = set(rules)

    def events(self, rig: str, events: list[dict[str, Any]], raised: set[str]) -> None:
        with self._lock:
            v = self.values.get(rig)
            if v is None:
                return
            v.raised = set(raised)
            for event in events:
                if event["event"] == "acknowledged":
                    v.acked.add(event["rule"])
            v.acked &= v.raised

    def tick(self, now_mono: float) -> None:
        """Every rig's health and acknowledgements from its status, each second."""
        if now_mono - self._last_status < STATUS_EVERY_S:
            return
        self._last_status = now_mono
        for rig in self.context.rig_status():
            self.rig_status(rig)

    def rig_status(self, rig: dict[str, Any]) -> None:
        """A rig's health (module docstring: a sensor fault before staleness) and its rules
        raised and acknowledged (``Monitor.status``'s entry)."""
        active = rig["active_alarms"]
        fault = any(a["rule"] == SENSOR_FAULT for a in active)
        health = HEALTH["fault"] if fault else HEALTH[rig["health"]]
        with self._lock:
            v = self.values.get(rig["name"])
            if v is not None:
                v.health = health
                v.raised = {a["rule"] for a in active}
                v.acked = {a["rule"] for a in active if a.get("acknowledged")}

    def fits(self, rigs: list[RigEntities]) -> bool:
        return rigs == self.rigs

    def status(self) -> dict[str, Any]:
        return {
            "listen": self.config.listen,
            "serving": self.server is not None,
            "acknowledged": self.acknowledged,
        }

    # -- the tables, as read -------------------------------------------------------------------

    def _value(self, v: RigValues, rig: str, key: tuple[Any, ...]) -> float | int | bool:
        what = key[0]
        if what == "heartbeat":
            return v.frames & 0xFFFF
        if what == "frames":
            return v.frames & 0xFFFFFFFF
        if what == "health":
            return v.health
        if what == "hottest":
            return v.hottest_c
        if what == "roi":
            stats = v.rois_c.get(self._rois[rig][key[1]])
            return math.nan if stats is None else stats[key[2]]
        if what == "priority":
            return v.priorities.get(self._rois[rig][key[1]], NO_CLASS)
        if what == "fault":
            return SENSOR_FAULT in v.raised
        if what == "raised":
            return key[1] in v.raised
        return key[1] in v.acked  # "acked"

    def registers(self) -> list[int]:
        """The input registers (and holding, the same) as they are now, every rig's block."""
        out = [0] * (RIG_REGISTERS * len(self.rigs))
        big = self.config.word_order == "big"
        with self._lock:
            for g in self.map:
                if g.table != "input":
                    continue
                value = self._value(self.values[g.rig], g.rig, g.key)
                if g.type in ("float32", "uint32"):
                    out[g.address : g.address + 2] = words(value, g.type, big)
                elif g.type == "int16":
                    out[g.address] = int16_raw(float(value), g.scale)
                else:
                    out[g.address] = int(value)
        return out

    def bits(self, table: str) -> list[bool]:
        """The discrete inputs or the coils as they are now, every rig's block."""
        out = [False] * (RIG_BITS * len(self.rigs))
        with self._lock:
            for g in self.map:
                if g.table == table:
                    out[g.address] = bool(self._value(self.values[g.rig], g.rig, g.key))
        return out

    def coil(self, address: int) -> Register | None:
        return next((g for g in self.map if g.table == "coil" and g.address == address), None)

    async def _action(
        self,
        function: int,
        start: int,
        address: int,
        count: int,
        current: list[int],
        written: list[int] | list[bool] | None,
    ) -> Any:
        """pymodbus asks before each request is served: the registers (or the 16-bit words
        bits are packed in, bit 0 first) filled from the values now, a write refused or
        acknowledged."""
        from pymodbus.constants import ExcCodes

        if function in READ_ONLY:
            return ExcCodes.ILLEGAL_FUNCTION
        if function in (3, 4):
            now = self.registers()
            current[address - start : address - start + count] = now[address : address + count]
            return None
        if function in (1, 5, 15) and not self.config.allow_ack:
            return ExcCodes.ILLEGAL_ADDRESS  # no coils
        if written is not None:  # coils 5, 15
            coils = [self.coil(address + k) for k in range(len(written))]
            if any(g is None for g in coils):
                return ExcCodes.ILLEGAL_ADDRESS
            for g, value in zip(coils, written, strict=True):
                if value and g is not None:
                    await asyncio.to_thread(self._acknowledge, g)
            return None
        if function in (1, 2):  # a write's echo (5) keeps what was written
            now_bits = self.bits("coil" if function == 1 else "discrete")
            for k in range(min(len(current), len(now_bits) // 16)):
                chunk = now_bits[16 * k : 16 * k + 16]
                current[k] = sum(1 << b for b, on in enumerate(chunk) if on)
        return None

    def _acknowledge(self, g: Register) -> None:
        rule = g.key[1]
        try:
            self.context.acknowledge(g.rig, rule, "modbus")
        except AckRefusedError as exc:  # not raised, or acknowledged already: nothing to do
            self.log.debug("modbus: %s %s not acknowledged: %s", g.rig, rule, exc.message)
            return
        self.acknowledged += 1
        with self._lock:
            self.values[g.rig].acked.add(rule)

    # -- the server's own worker ---------------------------------------------------------------

    def start(self, timeout_s: float = 30.0) -> None:
        check_port(*self.config.address(), f"modbus.listen: {self.config.listen}")
        self.worker.start()
        if not self._ready.wait(timeout_s) or self._error is not None:
            self.worker.stop()
            why = self._error if self._error is not None else "no answer"
            raise InputError(f"modbus.listen: {self.config.listen}: cannot listen ({why})")

    def workers(self) -> list[Worker]:
        return [self.worker]

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
            server, self.server = self.server, None
            if server is not None:  # however it ended: the port let go for the restart
                with contextlib.suppress(BaseException):
                    loop.run_until_complete(server.shutdown())
            loop.close()

    def _device(self, unit: int, action: Callable[..., Any]) -> Any:
        from pymodbus.simulator import DataType, SimData, SimDevice

        n = len(self.rigs)

        def block(count: int, kind: DataType) -> list[SimData]:
            value: bool | int = False if kind == DataType.BITS else 0
            return [SimData(0, count=count, values=value, datatype=kind)]

        tables = (
            block(RIG_BITS * n, DataType.BITS),  # coils
            block(RIG_BITS * n, DataType.BITS),  # discrete inputs
            block(RIG_REGISTERS * n, DataType.REGISTERS),  # holding
            block(RIG_REGISTERS * n, DataType.REGISTERS),  # input
        )
        return SimDevice(unit, simdata=tables, action=action)

    async def _serve(self, worker: Worker) -> None:
        from pymodbus.constants import ExcCodes
        from pymodbus.server import ModbusTcpServer

        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)

        async def elsewhere(*args: Any) -> Any:  # another unit id: no such unit behind us
            return ExcCodes.GATEWAY_NO_RESPONSE

        devices = [self._device(self.config.unit_id, self._action), self._device(0, elsewhere)]
        server = ModbusTcpServer(devices, address=self.config.address())
        await server.serve_forever(background=True)  # RuntimeError when it cannot listen
        self.server = server
        self._ready.set()
        while not worker.stopping.is_set():
            worker.beat()
            await asyncio.sleep(BEAT_S)


def describe(config: ModbusConfig) -> str:
    """The output of a ``modbus`` section in one line."""
    ack = "coils acknowledge latched rules" if config.allow_ack else "read only"
    return (
        f"Modbus TCP {config.listen} (unit {config.unit_id}; {ack}; word order {config.word_order})"
    )
