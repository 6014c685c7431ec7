"""Guided capture: a campaign's images taken from a live camera, one step at a time.

- :mod:`stiffmap.capture.sources`: camera sources behind one protocol (OpenCV devices, streams
  and video files, folders of images, GenICam cameras through harvesters);
- :mod:`stiffmap.capture.cameras`: the ``--camera`` option, and the simulated camera of a
  campaign (:mod:`stiffmap.sim.live_camera`);
- :mod:`stiffmap.capture.settle`: per frame, both boards, their exposure and sharpness, and
  whether the platform has settled (within stiffmap's own pose noise);
- :mod:`stiffmap.capture.plan`: the campaign's plan as the operator's steps;
- :mod:`stiffmap.capture.session`: the walk, the files, the capture log, resuming;
- :mod:`stiffmap.capture.view`: the live terminal view.

Layer: above ``campaign`` (it reads the campaign's spec and plan) and below ``report`` and
``cli``; OpenCV is used here for the camera sources (docs/architecture.md).
"""
