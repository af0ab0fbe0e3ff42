"""thermodepth: fuse a depth camera with a radiometric thermal camera.

Rooms, one per physical concept (see docs/architecture.md): camera, radiometry, calibration,
registration, compensation, sim, sources, io, pipeline.
"""

import os

# Our numba kernels share the cores with camera drivers and the recorder's thread. OpenMP's
# default spin-waiting between parallel regions starves them (and us, when another process
# holds a core: measured 3-8x slower medians under load; even a short spin, GOMP_SPINCOUNT
# 10,000, was up to 2.2x slower and erratic). Passive waiting costs ~60 us per parallel region
# to wake the threads (measured, against 2 us spinning). A value the user sets wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__version__ = "0.1.0"
