"""Remake docs/img/dashboard-outputs.png: the health page of a monitor serving every plant
output at once, on a simulated rig: MQTT (its own Mosquitto broker), Modbus TCP, RTSP, OPC
UA, and a webhook target whose receiver is away for its first 20 s (the page shows the
retries, then the deliveries).

    .venv/bin/python docs/img/make_outputs_shot.py    # from the repository's root

Needs the `monitor`, `modbus`, `opcua`, `video`, `mqtt` and `dev` extras, Mosquitto, GStreamer's
RTSP server and Debian's chromium and chromium-driver (as the tests that drive them).
"""

import os
import sys
import tempfile
import threading
import time
from http.server import BaseHTTPRequestHandler, HTTPServer
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))

import browser  # noqa: E402
from monitor_helpers import monitor_config, settings_file, wait_for  # noqa: E402
from mqtt_broker import Broker, free_port  # noqa: E402
from thermodepth.monitor import Monitor, load_config  # noqa: E402

OUT = Path(__file__).resolve().parent
SETTINGS = """\
hotspots: {threshold_c: 50}
rois:
  - {name: plate, rect: [548, 266, 734, 452]}
alarms:
  - {name: chip-hot, above_c: 60, for_s: 2, latch: true}
"""
AWAY_S = 20.0


def receiver() -> HTTPServer:
    """A webhook receiver that answers 503 for its first AWAY_S, then 204."""
    started = time.monotonic()

    class Hook(BaseHTTPRequestHandler):
        def do_POST(self) -> None:
            self.rfile.read(int(self.headers["Content-Length"]))
            away = time.monotonic() - started < AWAY_S
            self.send_response(503 if away else 204)
            self.end_headers()

        def log_message(self, *args: object) -> None:
            pass

    server = HTTPServer(("127.0.0.1", 0), Hook)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def main() -> None:
    if browser.missing():
        sys.exit(browser.missing())
    broker = Broker()
    broker.start()
    hook = receiver()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp)
            settings_file(folder, SETTINGS, "line1.yaml")
            (folder / "token").write_text("s3cret\n")
            (folder / "rtsp.pass").write_text("pa55word\n")
            (folder / "hook.key").write_text("k3y\n")
            (folder / "users.yaml").write_text("jane: s3cret\n")
            rigs = [{"name": "line1", "source": "sim:pace=real", "settings": "line1.yaml",
                     "location": "Transformer bay 1"}]  # fmt: skip
            path = monitor_config(
                folder,
                rigs,
                http={"token_file": "token"},
                mqtt={"url": broker.url("plant")},
                modbus={"listen": f"127.0.0.1:{free_port()}", "allow_ack": True},
                opcua={"endpoint": f"opc.tcp://127.0.0.1:{free_port()}/thermodepth",
                       "users_file": "users.yaml"},
                rtsp={"listen": f"127.0.0.1:{free_port()}", "password_file": "rtsp.pass"},
                notify=[{"kind": "webhook", "name": "ops", "secret_file": "hook.key",
                         "url": f"http://127.0.0.1:{hook.server_port}/hook"}],
            )  # fmt: skip
            os.environ["THERMODEPTH_MQTT_PASSWORD"] = broker.password
            monitor = Monitor(load_config(path))
            monitor.start()
            driver = browser.chromium(1280, 1400)
            try:
                driver.get(f"{monitor.http.url}/login")
                browser.fill_login(driver, "s3cret")
                wait_for(lambda: monitor.status()["outputs"]["webhook:ops"]["delivered"], 120)
                driver.get(f"{monitor.http.url}/health")
                wait_for(lambda: driver.find_elements("css selector", "#outputs"), 30)
                time.sleep(3)
                # from the workers down: each output's worker and its state
                driver.execute_script(
                    "document.querySelector('#workers').previousElementSibling.scrollIntoView()"
                )
                time.sleep(1)
                driver.save_screenshot(str(OUT / "dashboard-outputs.png"))
                print(f"wrote {OUT / 'dashboard-outputs.png'}")
            finally:
                driver.quit()
                monitor.stop()
    finally:
        hook.shutdown()
        broker.cleanup()


if __name__ == "__main__":
    main()
