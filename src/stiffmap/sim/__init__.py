"""The virtual test-bed: rendered target images and simulated sensor traces with known truth.

OpenCV is imported only here and in ``stiffmap.vision``.
"""
