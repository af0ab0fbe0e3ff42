"""``thermodepth monitor`` as a process, the way systemd runs it: killed with SIGKILL and
started again (the event store holds every event that was published), SIGHUP with a bad
config (the running one goes on) and a good one, SIGTERM, systemd's notify and watchdog
datagrams, and a disk that fills (measuring and alarming go on)."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the monitor's HTTP needs the monitor extra")
pytest.importorskip("uvicorn", reason="the monitor's HTTP needs the monitor extra")

import httpx
import yaml

from monitor_helpers import PATIENCE_S, Notifications, monitor_config, settings_file, wait_for
from thermodepth.errors import InputError
from thermodepth.monitor.store import EventStore
from thermodepth.sources import open_source


class Process:
    """``thermodepth monitor CONFIG`` in a process of its own (``wrap``: a command it runs
    under), its log in a file; ``url`` once it says where its HTTP server listens."""

    def __init__(
        self, config: Path, env: dict[str, str] | None = None, wrap: list[str] | None = None
    ) -> None:
        self.log = config.with_suffix(".log")
        self.log.write_text("")
        cmd = [sys.executable, "-m", "thermodepth.cli", "monitor", str(config)]
        with open(self.log, "ab") as log:
            self.proc = subprocess.Popen(
                [*(wrap or []), *cmd],
                stdout=log,
                stderr=log,
                env={**os.environ, **(env or {})},
            )
        found = wait_for(lambda: re.search(r"HTTP on (http://\S+)", self.text()) or self.dead())
        assert not isinstance(found, str), found
        self.url = found.group(1)
        self.http = httpx.Client(base_url=self.url, timeout=30)

    def text(self) -> str:
        return self.log.read_text(encoding="utf-8", errors="replace")

    def dead(self) -> str | None:
        if self.proc.poll() is None:
            return None
        return f"exited {self.proc.returncode}:\n{self.text()}"

    def status(self) -> dict[str, Any]:
        return dict(self.http.get("/api/status").json())

    def frames(self, rig: str) -> int:
        return int(next(r["frames"] for r in self.status()["rigs"] if r["name"] == rig))

    def signal(self, sig: int) -> None:
        self.proc.send_signal(sig)

    def wait(self, timeout_s: float = PATIENCE_S) -> int:
        code = self.proc.wait(timeout_s)
        self.http.close()
        return code

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.http.close()


def test_sigkill_loses_no_published_event_and_it_starts_again(tmp_path: Path) -> None:
    path = monitor_config(
        tmp_path, [{"name": "a", "source": "sim", "settings": settings_file(tmp_path).name}]
    )
    proc = Process(path)
    published: dict[int, dict[str, Any]] = {}

    def told() -> bool:
        for e in proc.http.get("/api/events", params={"limit": 1000}).json():
            published[e["id"]] = {k: v for k, v in e.items() if k != "evidence"}
        return len(published) >= 10

    try:
        wait_for(told, every_s=0.1)  # everything the API has told is published: it must
    finally:  # survive the kill
        proc.proc.send_signal(signal.SIGKILL)
        proc.wait()
    store = EventStore(tmp_path / "store" / "events.sqlite")
    kept = {e["id"]: e for e in store.events(100_000)}
    store.close()
    assert published.keys() <= kept.keys()
    assert all(kept[i] == e for i, e in published.items())  # the same rows
    # every clip replays what it holds; the one being written when it was killed may have
    # been cut before its first pair (no frame, or its first depth frame only), and says so
    clips = [e["clip"] for _, e in sorted(kept.items()) if e.get("clip")]  # the last, last
    replayed = {}
    for clip in dict.fromkeys(clips):
        try:
            with open_source(f"recording:{tmp_path / 'store' / 'clips' / clip / 'clip.zarr'}") as s:
                replayed[clip] = len(list(s))
        except InputError as e:
            assert clip == clips[-1] and re.search(r"holds no frames|gives \w+ only", str(e))
    assert all(n >= 1 for n in replayed.values()) and replayed
    again = Process(path)
    try:
        wait_for(lambda: again.http.get("/healthz").status_code == 200)
        newer = wait_for(
            lambda: [e for e in again.http.get("/api/events").json() if e["id"] > max(kept)]
        )
        assert newer  # the store opened and goes on
    finally:
        again.signal(signal.SIGTERM)
        assert again.wait() == 0


def test_sighup_reloads_a_good_config_and_refuses_a_bad_one_under_systemd(
    tmp_path: Path,
) -> None:
    settings = settings_file(tmp_path).name
    path = monitor_config(tmp_path, [{"name": "a", "source": "sim", "settings": settings}])
    good = path.read_text()
    notes = Notifications(tmp_path / "notify")
    env = {"NOTIFY_SOCKET": str(notes.path), "WATCHDOG_USEC": "400000"}
    proc = Process(path, env)
    try:
        wait_for(lambda: notes.has("READY=1"))
        wait_for(lambda: sum("WATCHDOG=1" in g for g in notes.read()) >= 3)  # every 0.2 s
        wait_for(lambda: proc.frames("a") > 5)
        path.write_text("rigs: []\nstorage: {path: store}\n")
        notes.got.clear()
        proc.signal(signal.SIGHUP)
        wait_for(lambda: "not reloaded, the running config goes on" in proc.text())
        assert f"{path}: rigs: List should have at least 1 item" in proc.text()
        before = proc.frames("a")
        wait_for(lambda: proc.frames("a") > before + 5)  # the old config goes on
        assert notes.has("RELOADING=1") and notes.has("READY=1")
        data = yaml.safe_load(good)
        data["rigs"].append({"name": "b", "source": "sim:thermal=lepton3.5", "settings": settings})
        path.write_text(yaml.safe_dump(data))
        proc.signal(signal.SIGHUP)
        wait_for(lambda: [r["name"] for r in proc.status()["rigs"]] == ["a", "b"])
        wait_for(lambda: proc.frames("b") > 3)
        a = next(r for r in proc.status()["rigs"] if r["name"] == "a")
        assert a["reconnects"] == 0 and a["frames"] > before  # unchanged: not restarted
        assert "b: started (reload)" in proc.text()
        notes.got.clear()
        proc.signal(signal.SIGTERM)
        assert proc.wait() == 0
    finally:
        proc.kill()
    assert notes.has("STOPPING=1")
    assert proc.text().rstrip().endswith("monitor: stopped")


def namespace_wrapper(store: Path) -> list[str] | str:
    """The command that runs a process with a small tmpfs mounted at ``store`` in a mount
    namespace of its own, or why it cannot be done here."""
    unshare = shutil.which("unshare")
    if unshare is None:
        return "the full-disk test needs util-linux's unshare"
    user = [] if os.geteuid() == 0 else ["--map-root-user"]
    wrap = [unshare, *user, "--mount", "sh", "-c",
            'mount -t tmpfs -o size=24m tmpfs "$0" && exec "$@"', str(store)]  # fmt: skip
    probe = subprocess.run([*wrap, "true"], capture_output=True, text=True, check=False)
    if probe.returncode != 0:
        why = probe.stderr.strip().splitlines()[-1] if probe.stderr.strip() else "no reason"
        return f"cannot mount a small tmpfs in a mount namespace here (unshare: {why})"
    return wrap


def test_a_full_disk_does_not_stop_measuring_or_alarming(tmp_path: Path) -> None:
    store = tmp_path / "store"
    store.mkdir()
    wrap = namespace_wrapper(store)
    if isinstance(wrap, str):
        pytest.skip(wrap)
    path = monitor_config(
        tmp_path,
        [{"name": "a", "source": "sim", "settings": settings_file(tmp_path).name}],
        storage={"continuous": True, "segment_s": 2, "min_free_gb": 0},
    )
    proc = Process(path, wrap=wrap)
    try:
        fault = wait_for(
            lambda: [
                e
                for e in proc.http.get("/api/events", params={"limit": 1000}).json()
                if e["rule"] == "storage_fault"
            ],
        )
        assert fault[-1]["event"] == "alarm" and fault[-1]["rig"] == "monitor"
        said = fault[-1]["condition"]
        assert "No space left on device" in said or "database or disk is full" in said
        frames = proc.frames("a")
        since = time.time()
        wait_for(lambda: proc.frames("a") > frames + 15)  # measuring goes on
        wait_for(  # alarming goes on
            lambda: len([
                e
                for e in proc.http.get("/api/events", params={"limit": 1000}).json()
                if e["rule"] == "hot" and e["time_s"] > since
            ]) >= 3
        )  # fmt: skip
        # the continuous recording says it lost what it could not write: when the writer thread
        # fails within the segment's time, its next frame stops it; later, its close does
        failed = r"(stopped \(|not started: |not closed cleanly \().*No space left"
        recording = rf"storage: continuous recording \S+: {failed}"
        wait_for(lambda: re.search(recording, proc.text()))
        status = proc.status()
        assert status["storage"]["fault"] is True
        assert proc.http.get("/healthz").status_code == 200
        proc.signal(signal.SIGTERM)
        assert proc.wait() == 0
    finally:
        proc.kill()
    assert "cannot rollback" not in proc.text()  # the disk's own error is what is told
    assert "unexpected error" not in proc.text()  # the rig never failed for it
