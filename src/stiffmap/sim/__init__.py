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
- :mod:`stiffmap.sim.calibration_views`: views of a calibration board at the poses a
  careful user takes, rendered like the campaign's images (calibrated from by
  :mod:`stiffmap.campaign.simulated`, through ``stiffmap.vision``);
- :mod:`stiffmap.sim.plan`: a vision campaign's settings from a user's choices, its plan
  and the disk space its images need (what ``stiffmap simulate`` decides);
- :mod:`stiffmap.sim.render_pool`: those images rendered to files in a pool of processes;
- :mod:`stiffmap.sim.traces`: displacement-sensor recordings of stepped loads.

The test-bed produces data; the campaign directories it becomes (``campaign.toml``,
``truth.json``) are written by :mod:`stiffmap.campaign.simulated` and
:mod:`stiffmap.campaign.simulated_sensor`. OpenCV is imported only here and in
``stiffmap.vision``. See ``docs/simulation.md``.
"""
