"""Vision measurement: board detection, camera calibration, target poses, compliant displacements.

OpenCV is imported only here and in ``stiffmap.sim``. See ``docs/vision.md``.

Main entry points:

- :func:`read_image` (file -> uint8 grey), :func:`check_image_size`
- :func:`detect_board`, :func:`detect_boards`, :func:`track_board` -> :class:`BoardDetection`
- :func:`calibrate_camera` -> :class:`CalibrationResult`; :func:`calibrate_rig` (several cameras
  together) -> :class:`RigCalibrationResult`
- :func:`estimate_pose` -> :class:`BoardPose` (corner-based, or refined by
  :func:`refine_pose_photometric`: a model of the blurred board fitted to its pixels)
- :class:`PoseTracker`, :func:`measure_sequence` -> list of :class:`ImageMeasurement` (one
  camera, or a :class:`~stiffmap.rig.Rig` of several: :func:`fuse_poses` -> :class:`FusedPose`,
  one pose in the rig frame from every camera that saw the board)
- :func:`compliant_displacement` -> :class:`Displacement`; :func:`displacement_per_image`
  -> :class:`ImageDisplacements` (each image of a series against the same reference)
- :func:`validate_stage`, :func:`validate_stage_series` -> :class:`StageValidation` (drawn by
  :func:`stiffmap.report.validation.stage_plot_svg`)

The pose maths shared with the test-bed (:class:`BoardPose`, :func:`projection_jacobian`,
the pose perturbation) live in :mod:`stiffmap.posemath`, the image check in
:func:`stiffmap.vision.images.check_image`.
"""

from ..posemath import BoardPose, PoseEstimate, projection_jacobian
from .calibrate import DIST_MODELS, CalibrationResult, ViewResult, calibrate_camera
from .corners import refine_corners
from .detect import BoardDetection, DetectionError, board_label, detect_board, detect_boards, track_board
from .displacement import (
    Displacement,
    ImageDisplacements,
    compliant_displacement,
    displacement_per_image,
    mean_pose,
)
from .files import calibrate_files, calibrate_rig_files, measure_files, read_stage_manifest, read_transform
from .fuse import FusedPose, fuse_poses
from .images import ImageError, check_image_size, read_image
from .photometric import PhotometricError, PhotometricFit, refine_pose_photometric
from .pose import estimate_pose, pose_shift_sigma
from .rig_calibration import RigCalibrationResult, calibrate_rig
from .sequence import CameraView, ImageMeasurement, PoseTracker, measure_sequence, mobile2base_from_poses
from .validate import StageStep, StageValidation, validate_stage, validate_stage_series

__all__ = [
    "BoardDetection",
    "BoardPose",
    "PoseEstimate",
    "CalibrationResult",
    "CameraView",
    "DIST_MODELS",
    "DetectionError",
    "Displacement",
    "FusedPose",
    "ImageDisplacements",
    "ImageError",
    "ImageMeasurement",
    "PhotometricError",
    "PhotometricFit",
    "PoseTracker",
    "RigCalibrationResult",
    "StageStep",
    "StageValidation",
    "ViewResult",
    "board_label",
    "calibrate_camera",
    "calibrate_files",
    "calibrate_rig",
    "calibrate_rig_files",
    "check_image_size",
    "compliant_displacement",
    "detect_board",
    "detect_boards",
    "displacement_per_image",
    "estimate_pose",
    "fuse_poses",
    "mean_pose",
    "measure_files",
    "measure_sequence",
    "mobile2base_from_poses",
    "pose_shift_sigma",
    "projection_jacobian",
    "read_image",
    "read_stage_manifest",
    "read_transform",
    "refine_corners",
    "refine_pose_photometric",
    "track_board",
    "validate_stage",
    "validate_stage_series",
]
