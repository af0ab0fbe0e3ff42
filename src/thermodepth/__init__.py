"""thermodepth: fuse a depth camera with a radiometric thermal camera.

Rooms, one per physical concept (see docs/architecture.md): camera, radiometry, calibration.
"""

__version__ = "0.1.0"
