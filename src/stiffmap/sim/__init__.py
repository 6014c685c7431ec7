"""The virtual test-bed: rendered target images and simulated sensor traces with known truth.

- :mod:`stiffmap.sim.render`: targets rendered through a distorted camera with exact
  anti-aliasing, photometry, the true corners;
- :mod:`stiffmap.sim.texture`: chessboard and ChArUco prints as cells of a grid;
- :mod:`stiffmap.sim.scene`: board poses, the default robot scene.

OpenCV is imported only here and in ``stiffmap.vision``. See ``docs/simulation.md``.
"""
