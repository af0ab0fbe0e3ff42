"""Target-based calibration of the depth + thermal pair: thermal (and depth) intrinsics and
``thermal_from_depth`` from image pairs of a calibration board, with a quality report.

The method is OpenCV's two-step stereo calibration (Zhang's method per camera, then the
rigid transform with the intrinsics held fixed), which is stabler than a joint fit when one
camera has 19,200 pixels and the other 921,600. One module per stage:

1. :mod:`.discover`: :func:`discover_pairs` matches the images of a folder by name.
2. :mod:`.images`: :func:`load_image` reads 8- or 16-bit PNG/TIFF/JPEG or ``.npy``;
   :func:`stretch_to_unit` and :func:`upscale_factor` prepare small low-contrast images.
3. :mod:`.detect`: :func:`detect_board` tries both polarities (a heated board's paint is
   bright where the print is dark), refines corners on fronto-parallel patches
   (:func:`refine_corners_homography`), :func:`grid_continues` tells a larger board, and
   :func:`canonical_order` / :func:`match_order` make the corner order of a pair agree.
4. :mod:`.fit`: :func:`calibrate_camera` (``cv2.calibrateCamera``) per camera, or
   :func:`fixed_camera_fit` when the intrinsics are given; :func:`stereo_calibrate`
   (``cv2.stereoCalibrate`` with ``CALIB_FIX_INTRINSIC``); :func:`flag_outliers`.
5. :mod:`.run`: :func:`run_calibration` ties them together into a
   :class:`CalibrationResult`; :mod:`.single`: :func:`run_camera_calibration`, one camera's
   intrinsics from single views (:class:`CameraResult`); :mod:`.report` writes
   ``calib_report.json`` and ``.png`` for either.

Units: lengths in metres (square size, translation), pixels for image coordinates (OpenCV
conventions: pixel centres at integers), angles in degrees in the report.
"""

from .detect import (
    REFINE_METHODS,
    Detection,
    canonical_order,
    detect_board,
    grid_continues,
    match_order,
    refine_corners_homography,
)
from .discover import ImagePair, PairListing, discover_pairs
from .fit import (
    DISTORTION_MODELS,
    CameraFit,
    StereoFit,
    calibrate_camera,
    coverage_grid,
    fixed_camera_fit,
    flag_outliers,
    outlier_limits_px,
    stereo_calibrate,
)
from .images import IMAGE_SUFFIXES, load_image, stretch_to_unit, upscale_factor
from .report import plot_camera_report, plot_report, write_report_json
from .run import (
    MIN_PAIRS,
    CalibrationResult,
    SkippedPair,
    detect_view,
    load_intrinsics,
    run_calibration,
)
from .single import (
    CameraResult,
    SkippedImage,
    as_camera,
    discover_images,
    run_camera_calibration,
)

__all__ = [
    "DISTORTION_MODELS",
    "IMAGE_SUFFIXES",
    "MIN_PAIRS",
    "REFINE_METHODS",
    "CalibrationResult",
    "CameraFit",
    "CameraResult",
    "Detection",
    "ImagePair",
    "PairListing",
    "SkippedImage",
    "SkippedPair",
    "StereoFit",
    "as_camera",
    "calibrate_camera",
    "canonical_order",
    "coverage_grid",
    "detect_board",
    "detect_view",
    "discover_images",
    "discover_pairs",
    "fixed_camera_fit",
    "flag_outliers",
    "grid_continues",
    "load_image",
    "load_intrinsics",
    "match_order",
    "outlier_limits_px",
    "plot_camera_report",
    "plot_report",
    "refine_corners_homography",
    "run_calibration",
    "run_camera_calibration",
    "stereo_calibrate",
    "stretch_to_unit",
    "upscale_factor",
    "write_report_json",
]
