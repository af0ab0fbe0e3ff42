"""The monitor's Modbus TCP server read by two independent clients (pymodbus's, and Debian's
mbpoll on libmodbus): values equal the measurements of the same frame computed apart, both
word orders decoded from the raw registers, writes to read-only tables refused with a Modbus
exception, a coil acknowledging a latched rule, a stopped rig's health, the register map's
CSV stable when a rig is added, the config's problems one line each."""

from __future__ import annotations

import csv
import io
import math
import shutil
import socket
import struct
import subprocess
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("pymodbus", reason="the Modbus server needs the modbus extra (pymodbus)")

from pymodbus.client import ModbusTcpClient
from typer.testing import CliRunner

from monitor_helpers import FLAPPING, monitor_config, settings_file, wait_for
from mqtt_broker import free_port
from thermodepth.cli import app
from thermodepth.errors import InputError
from thermodepth.monitor import Monitor, load_config
from thermodepth.pipeline import Pipeline, Settings
from thermodepth.session import record_session
from thermodepth.sources import open_source

ROIS = "rois:\n  - {name: plate, rect: [560, 280, 720, 440]}\n  - {name: nothing, depth_range_m: [5, 6]}\n"  # noqa: E501
MBPOLL = shutil.which("mbpoll")


def start(folder: Path, rigs: list[dict[str, Any]], **sections: Any) -> tuple[Monitor, int]:
    settings_file(folder, FLAPPING + ROIS)
    port = free_port()
    modbus = {"listen": f"127.0.0.1:{port}", **sections.pop("modbus", {})}
    path = monitor_config(
        folder,
        [{"settings": "s.yaml", **r} for r in rigs],
        http={"listen": None},
        modbus=modbus,
        **sections,
    )
    monitor = Monitor(load_config(path))
    monitor.start()
    return monitor, port


def client(port: int) -> ModbusTcpClient:
    c = ModbusTcpClient("127.0.0.1", port=port, timeout=10)
    assert c.connect()
    return c


def registers(port: int, address: int, count: int, table: str = "input") -> list[int]:
    c = client(port)
    try:
        read = c.read_input_registers if table == "input" else c.read_holding_registers
        got = read(address, count=count, device_id=1)
        assert not got.isError(), got
        return list(got.registers)
    finally:
        c.close()


def bits(port: int, address: int, count: int, table: str = "discrete") -> list[bool]:
    c = client(port)
    try:
        read = c.read_discrete_inputs if table == "discrete" else c.read_coils
        got = read(address, count=count, device_id=1)
        assert not got.isError(), got
        return list(got.bits[:count])
    finally:
        c.close()


def int16(raw: int) -> int:
    return raw - 65536 if raw >= 32768 else raw


def float32(hi_first: list[int], big: bool = True) -> float:
    hi, lo = hi_first if big else hi_first[::-1]
    return float(struct.unpack(">f", struct.pack(">HH", hi, lo))[0])


def as_float32(value: float) -> float:
    return float(struct.unpack(">f", struct.pack(">f", value))[0])


def mbpoll(port: int, kind: str, address: int, count: int, *more: str) -> list[str]:
    """What mbpoll reads, a value each (``kind``: its -t; addresses from 0)."""
    assert MBPOLL is not None
    args = [MBPOLL, "-m", "tcp", "-a", "1", "-t", kind, "-0", "-r", str(address),
            "-c", str(count), "-1", "-q", "-p", str(port), *more, "127.0.0.1"]  # fmt: skip
    done = subprocess.run(args, capture_output=True, text=True, timeout=60)
    lines = [line for line in done.stdout.splitlines() if line.startswith("[")]
    assert done.returncode == 0 and lines, done.stdout + done.stderr
    return [line.split(":", 1)[1].strip() for line in lines]


def test_values_equal_the_measurements_of_the_same_frame(tmp_path: Path) -> None:
    take = tmp_path / "take.zarr"
    record_session(open_source("sim", frames=12), take)
    settings_file(tmp_path, FLAPPING + ROIS)
    with open_source(f"recording:{take}") as src:  # the same recording measured apart
        pipe = Pipeline(Settings.load(tmp_path / "s.yaml"), src.calibration)
        frames = [pipe.process(p) for p in src]
    last = frames[-1]
    plate = next(r for r in last.rois if r.name == "plate")
    monitor, port = start(tmp_path, [{"name": "r", "source": f"recording:{take}", "pace": "fast"}])
    try:
        wait_for(lambda: monitor.runners["r"].status.state == "ended")
        status = next(r for r in monitor.status()["rigs"] if r["name"] == "r")
        # health is written each second by the clock: an ended replay is ok
        regs = wait_for(lambda: (g := registers(port, 0, 40)) and g[1] == 0 and g, every_s=0.2)
        held = registers(port, 0, 40, "holding")
        raised = bits(port, 0, 3)
        mb = mbpoll(port, "3", 0, 40) if MBPOLL else None
        mb_float = mbpoll(port, "3:float", 20, 3, "-B") if MBPOLL else None
    finally:
        monitor.stop()
    assert regs[0] == status["frames"] == len(frames)  # heartbeat: each fused frame
    assert regs[6:8] == [0, len(frames)]  # frames, uint32 high word first
    assert int16(regs[2]) == round(last.hotspots[0].max_c * 10)
    assert float32(regs[4:6]) == as_float32(last.hotspots[0].max_c)
    for k, stat in enumerate((plate.max_c, plate.mean_c, plate.min_c)):
        assert int16(regs[16 + k]) == round(stat * 10)
        assert float32(regs[20 + 2 * k : 22 + 2 * k]) == as_float32(stat)
    assert [int16(g) for g in regs[26:29]] == [-32768] * 3  # "nothing": no valid pixel
    assert all(math.isnan(float32(regs[30 + 2 * k : 32 + 2 * k])) for k in range(3))
    assert held == regs  # the holding registers read as the input registers
    states = pipe.alarms.states  # the rules' states after the same frames, measured apart
    assert raised == [False, states["hot"].raised, states["latched"].raised]
    if mb is None:
        pytest.skip("Debian's mbpoll (libmodbus) is not installed: only pymodbus read it")
    assert [int(v.split()[0]) for v in mb] == regs  # mbpoll: "58723 (-6813)"
    assert [float(v) for v in mb_float] == pytest.approx(  # type: ignore[union-attr]
        [as_float32(s) for s in (plate.max_c, plate.mean_c, plate.min_c)], rel=1e-6
    )


def test_little_word_order(tmp_path: Path) -> None:
    monitor, port = start(
        tmp_path, [{"name": "a", "source": "sim"}], modbus={"word_order": "little"}
    )
    try:
        wait_for(lambda: monitor.runners["a"].status.frames > 3)
        regs = wait_for(lambda: (g := registers(port, 0, 30)) and g[0] > 3 and g, every_s=0.2)
    finally:
        monitor.stop()
    assert regs[6:8] == [regs[0], 0]  # frames (< 65536): low word first
    hottest = float32(regs[4:6], big=False)
    assert round(hottest * 10) == int16(regs[2])  # the same frame's value, as int16
    assert not 20 < float32(regs[4:6], big=True) < 200  # read the other way: not a reading
    for k in range(3):  # plate's max, mean, min
        assert round(float32(regs[20 + 2 * k : 22 + 2 * k], big=False) * 10) == int16(regs[16 + k])


def test_writes_refused_a_coil_acknowledges_and_a_stopped_rigs_health(tmp_path: Path) -> None:
    monitor, port = start(
        tmp_path,
        [
            {"name": "a", "source": "sim"},
            {"name": "gone", "source": "sim:faults=unplug@0s+600s", "stall_s": 1},
        ],
        modbus={"allow_ack": True},
        failsafe={"startup_s": 6},
    )
    c = client(port)
    healths: list[int] = []

    def health_of_gone() -> int:
        healths.append(registers(port, 256 + 1, 1)[0])
        return healths[-1] == 2

    try:
        wait_for(health_of_gone, every_s=0.1)  # stale first, then its no_data fault
        wait_for(lambda: bits(port, 0, 3)[2])  # a: latched raised
        assert bits(port, 64, 1) == [True]  # gone: its sensor fault
        refused = c.write_register(0, 7, device_id=1)
        refused_many = c.write_registers(16, [1, 2], device_id=1)
        not_a_coil = c.write_coil(1, True, device_id=1)  # "hot" does not latch
        assert bits(port, 0, 3, "coil") == [False, False, False]
        acked = c.write_coil(2, True, device_id=1)  # "latched"
        wait_for(lambda: bits(port, 0, 3, "coil")[2])
        events = monitor.store.events(1000, "a", state="acknowledged")
        mb_refused = (
            subprocess.run(
                [
                    MBPOLL,
                    "-m",
                    "tcp",
                    "-a",
                    "1",
                    "-t",
                    "4",
                    "-0",
                    "-r",
                    "3",
                    "-1",
                    "-p",
                    str(port),
                    "127.0.0.1",
                    "5",
                ],
                capture_output=True,
                text=True,
                timeout=60,
            )
            if MBPOLL
            else None
        )
    finally:
        c.close()
        monitor.stop()
    assert refused.isError() and refused.exception_code == 1  # illegal function
    assert refused_many.isError() and refused_many.exception_code == 1
    assert not_a_coil.isError() and not_a_coil.exception_code == 2  # illegal address
    assert not acked.isError()
    assert [(e["rule"], e["by"]) for e in events] == [("latched", "modbus")]
    assert monitor.status()["outputs"]["modbus"]["acknowledged"] == 1
    assert 0 not in healths and healths[0] == 1 and healths[-1] == 2  # stale, then fault
    with socket.socket() as s:  # stopped, it let its port go
        s.bind(("127.0.0.1", port))
    if mb_refused is None:
        pytest.skip("Debian's mbpoll (libmodbus) is not installed: only pymodbus wrote")
    assert mb_refused.returncode != 0 and "Illegal function" in mb_refused.stderr


def test_without_allow_ack_there_are_no_coils(tmp_path: Path) -> None:
    monitor, port = start(tmp_path, [{"name": "a", "source": "sim"}])
    c = client(port)
    try:
        wait_for(lambda: bits(port, 0, 3)[2])  # latched raised
        write = c.write_coil(2, True, device_id=1)
        read = c.read_coils(0, count=3, device_id=1)
        other_unit = c.read_input_registers(0, count=1, device_id=9)
        beyond = c.read_input_registers(250, count=10, device_id=1)  # past the only rig
        acknowledged = monitor.store.events(1000, "a", state="acknowledged")
    finally:
        c.close()
        monitor.stop()
    assert write.isError() and write.exception_code == 2
    assert read.isError() and read.exception_code == 2
    assert other_unit.isError() and other_unit.exception_code == 0x0B
    assert beyond.isError() and beyond.exception_code == 2
    assert acknowledged == []


def read_map(path: Path) -> list[dict[str, str]]:
    done = CliRunner().invoke(app, ["monitor", str(path), "--modbus-map"])
    assert done.exit_code == 0, done.output
    return list(csv.DictReader(io.StringIO(done.output)))


def test_the_register_map_is_stable_when_a_rig_is_added(tmp_path: Path) -> None:
    settings_file(tmp_path, FLAPPING + ROIS)
    one = [{"name": "a", "source": "sim", "settings": "s.yaml"}]
    path = monitor_config(tmp_path, one, modbus={"allow_ack": True})
    rows = read_map(path)
    assert list(rows[0]) == ["address", "table", "type", "scale", "unit", "rig", "name"]
    keys = [(r["table"], int(r["address"])) for r in rows]
    assert len(keys) == len(set(keys))  # unique within each table
    by_name = {r["name"]: r for r in rows}
    assert by_name["heartbeat"]["address"] == "0" and by_name["health"]["address"] == "1"
    assert by_name["roi.plate.max_c"] == {"address": "20", "table": "input", "type": "float32",
                                          "scale": "1", "unit": "C", "rig": "a",
                                          "name": "roi.plate.max_c"}  # fmt: skip
    assert by_name["roi.nothing.min_c_x10"]["scale"] == "0.1"
    assert {r["name"] for r in rows if r["table"] == "coil"} == {"rule.latched.ack"}
    assert {r["table"] for r in rows} == {"input", "discrete", "coil"}
    two = [*one, {"name": "b", "source": "sim", "settings": "s.yaml"}]
    more = read_map(monitor_config(tmp_path, two, modbus={"allow_ack": True}))
    assert [r for r in more if r["rig"] == "a"] == rows
    b = [r for r in more if r["rig"] == "b"]
    assert min(int(r["address"]) for r in b if r["table"] == "input") == 256
    assert min(int(r["address"]) for r in b if r["table"] == "discrete") == 64


def test_modbus_config_problems(tmp_path: Path) -> None:
    many = "rois:\n" + "".join(f"  - {{name: r{i}, rect: [0, 0, 9, 9]}}\n" for i in range(25))
    settings_file(tmp_path, many)
    path = monitor_config(tmp_path, [{"name": "a", "source": "sim", "settings": "s.yaml"}],
                          modbus={"listen": "0.0.0.0:502"})  # fmt: skip
    with pytest.raises(InputError) as info:
        load_config(path)
    lines = [line.removeprefix(f"{path}: ") for line in str(info.value).splitlines()]
    assert lines == [
        "modbus.listen: 0.0.0.0:502 is reachable from other machines and Modbus has no "
        "authentication: set modbus.allow_remote: true (on a control network only), or listen "
        "on 127.0.0.1",
        "rigs.0 (a).settings: 25 ROIs: the Modbus register map has room for 24 per rig",
    ]
    path = monitor_config(tmp_path, [{"name": "a", "source": "sim"}],
                          modbus={"listen": "nowhere", "word_order": "middle"})  # fmt: skip
    with pytest.raises(InputError) as info:
        load_config(path)
    lines = [line.removeprefix(f"{path}: ") for line in str(info.value).splitlines()]
    assert len(lines) == 1 and lines[0].startswith("modbus.word_order: ")
    path = monitor_config(tmp_path, [{"name": "a", "source": "sim"}], modbus={"listen": "nowhere"})
    with pytest.raises(InputError) as info:
        load_config(path)
    assert (
        str(info.value) == f"{path}: modbus.listen: 'nowhere': expected HOST:PORT (127.0.0.1:5020)"
    )
    path = monitor_config(tmp_path, [{"name": "a", "source": "sim"}],
                          modbus={"listen": "0.0.0.0:0", "allow_remote": True})  # fmt: skip
    assert load_config(path).modbus is not None  # allowed, as asked
