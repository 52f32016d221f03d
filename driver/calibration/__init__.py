"""Field calibration: gyro noise and bias, gyro scale/misalignment, dark frames, camera
intrinsics, gyro–camera alignment and time offset.

One CLI module per command (``gyro_static``, ``gyro_scale``, ``dark``, ``camera``,
``alignment``; each exposes ``HELP``, ``configure(parser)``, ``run(args)``) over small
estimation modules that take plain arrays (``allan``, ``scale_fit``, ``dark_frames``,
``intrinsics``, ``align_fit``). Results go to the calibration TOML (``calfile``) that the
driver loads, and to a report folder with plots (``report``).
"""
