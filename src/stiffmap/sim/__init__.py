"""The virtual test-bed: rendered target images and simulated sensor traces with known truth.

- :mod:`stiffmap.sim.render`: targets rendered through a distorted camera with exact
  anti-aliasing, photometry, the true corners (the entry point), made of
  :mod:`stiffmap.sim.reflectance` (scene geometry: targets, the reflectance each pixel
  sees, true corners), :mod:`stiffmap.sim.coverage` (exact area coverage of a pixel on a
  board print) and :mod:`stiffmap.sim.photometry` (image formation: optics blur,
  vignetting, noise, 8 bits);
- :mod:`stiffmap.sim.texture`: chessboard and ChArUco prints as cells of a grid;
- :mod:`stiffmap.sim.scene`: board poses, the default robot scene;
- :mod:`stiffmap.sim.robot`: the virtual robot (stiffness field, repeatability);
- :mod:`stiffmap.sim.testbed`: a campaign's images and their truth (no I/O);
- :mod:`stiffmap.sim.writer`: the vision campaign directory and ``truth.json``;
- :mod:`stiffmap.sim.traces`: displacement-sensor recordings of stepped loads;
- :mod:`stiffmap.sim.sensor_campaign`: the 3PRR sensor campaign directory.

OpenCV is imported only here and in ``stiffmap.vision``. See ``docs/simulation.md``.
"""
