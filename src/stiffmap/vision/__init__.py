"""Vision measurement: board detection, camera calibration, target poses, compliant displacements.

OpenCV is imported only here and in ``stiffmap.sim``.
"""
