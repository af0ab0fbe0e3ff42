"""Remake docs/img/viewer.png: rerun's viewer on a short run of the simulated rig.

    .venv/bin/python docs/img/make_viewer_shot.py    # from the repository's root

Needs the `viewer` extra (rerun-sdk) and a Vulkan driver: without a GPU, Mesa's software one
(lavapipe, Debian package mesa-vulkan-drivers). No display or X server: `rerun --headless`
draws offscreen. The shot is asked for through rerun's ViewerClient once the recording has
loaded and the viewer's start-up notifications (toasts) have timed out.
"""

import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rerun.experimental import ViewerClient

SETTINGS = """\
hotspots: {threshold_c: 50}
rois: [{name: panel, rect: [400, 200, 880, 520]}]
viewer: {temp_range_c: [20, 75]}
"""
OUT = Path(__file__).resolve().parent / "viewer.png"
BIN = Path(sys.executable).parent
TOASTS_S = 15  # rerun's toasts are gone after some 5-10 s

with tempfile.TemporaryDirectory() as tmp:
    (Path(tmp) / "s.yaml").write_text(SETTINGS)
    rrd = str(Path(tmp) / "run.rrd")
    args = f"run --frames 5 --quiet --settings {tmp}/s.yaml --viewer-save {rrd}"
    subprocess.run([BIN / "thermodepth", *args.split()], check=True)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    args = f"--headless --window-size 1500x900 --bind 127.0.0.1 --port {port} {rrd}"
    # `rerun` is a shim that starts the viewer's binary: its own process group stops both
    viewer = subprocess.Popen([BIN / "rerun", *args.split()], start_new_session=True)
    try:
        for _ in range(120):
            time.sleep(0.5)
            try:
                state = ViewerClient.connect(f"rerun+http://127.0.0.1:{port}/proxy").get_state()
            except Exception:
                continue
            if state.active_recording and not state.loading:
                break
        else:
            sys.exit("the headless viewer did not load the recording")
        time.sleep(TOASTS_S)
        ViewerClient.connect(f"rerun+http://127.0.0.1:{port}/proxy").save_screenshot(str(OUT))
        print(f"wrote {OUT}")
    finally:
        os.killpg(viewer.pid, signal.SIGTERM)
        viewer.wait(10)
