"""Helpers of the test suite (and of the benchmarks), one idea a module.

Imported as ``helpers.<module>``: pytest puts ``tests/`` on ``sys.path`` (``conftest.py``
makes sure of it whatever the import mode); a benchmark inserts ``tests/`` itself.

- :mod:`helpers.cli_process` runs the real ``stiffmap`` command in a subprocess.
- :mod:`helpers.finite_difference` is the one central-difference Jacobian.
- :mod:`helpers.random_matrices` draws rotations and SPD matrices.
- :mod:`helpers.shared_data` finds the real data beside the repository.
- :mod:`helpers.board_scenes` poses boards before a camera: poses, exact corners, cameras.
- :mod:`helpers.board_images` makes images of boards (a quick test renderer, the test-bed's
  renderer, a brute-force reference).
- :mod:`helpers.opencv_corners` finds a board's corners with OpenCV alone (a reference detector).
- :mod:`helpers.corner_round_trip` measures a simulated campaign from its exported corners.
- :mod:`helpers.mechanism_checks` draws reachable poses of a model and checks its Jacobian.
- :mod:`helpers.sensor_traces` simulates short sensor recordings.
- :mod:`helpers.report_cases` builds degenerate report data.
- :mod:`helpers.urdf_reference` reads a URDF independently of stiffmap: forward kinematics,
  Jacobian by central differences, K and K6; writes configurations as ``--configs`` reads them.
- :mod:`helpers.own_hexapod` is a 6-UPS hexapod of our own (legs TOML) and its closed-form K6.
- :mod:`helpers.fitted_campaign` runs a simulated campaign and returns the model it fitted.
"""
