"""Direct (photometric) refinement of a chessboard's pose: a model of the blurred board fitted to its pixels.

Corner-based poses use small windows around the corners; the depth of a
planar board then comes from its apparent scale, measured by a few hundred
corners of ~0.02 px noise. This package fits a model of the whole blurred
chessboard to every pixel near the board's edges (``docs/vision.md``,
"Photometric pose refinement"): 3.4-5.9 times more precise along the line of
sight on the virtual test-bed's realistic renders.

One module per step, in the order of the fit:

- :mod:`~stiffmap.vision.photometric.pixels`: the pixel set -- which pixels of the
  board the fit uses (near one grid line, away from the corners, unsaturated, not
  excluded) and what stays fixed during it (:class:`PhotometricSetup`,
  :func:`prepare_pixels`);
- :mod:`~stiffmap.vision.photometric.model`: the edge model -- the blurred, shaded
  board's value at each selected pixel and its analytic Jacobian
  (:func:`model_and_jacobian`);
- :mod:`~stiffmap.vision.photometric.solver`: damped Gauss-Newton with a noise model
  and Huber weights;
- :mod:`~stiffmap.vision.photometric.acceptance`: when a converged fit is accepted
  (plausible blur, few outliers, a positive and even contrast) and its covariance;
- :mod:`~stiffmap.vision.photometric.refine`: :func:`refine_pose_photometric`, the two
  passes from the corner-based pose to a :class:`~stiffmap.posemath.BoardPose`;
- :mod:`~stiffmap.vision.photometric.diagnostics`: :func:`edge_agreement`, where the image's
  edges sit relative to a pose (the corner pose): why a fit lands away from it.

The pixels' rays come from the camera's ray cache (:func:`stiffmap.camera.pixel_rays`),
the pose perturbation and the board-plane homography from :mod:`stiffmap.posemath`.

ChArUco boards (markers in the white squares) are not modelled.
"""

from .diagnostics import EdgeAgreement, edge_agreement
from .model import model_and_jacobian
from .pixels import PhotometricError, PhotometricSetup, prepare_pixels
from .refine import PhotometricFit, PhotometricTrack, refine_pose_photometric

__all__ = [
    "EdgeAgreement",
    "edge_agreement",
    "PhotometricFit",
    "PhotometricError",
    "PhotometricSetup",
    "PhotometricTrack",
    "prepare_pixels",
    "model_and_jacobian",
    "refine_pose_photometric",
]
