"""Field calibration: gyro noise and bias, gyro scale/misalignment, dark frames, camera
intrinsics, gyro–camera alignment and time offset.

The command-line front ends (``gyrostar calibrate NAME``, with their ``--simulate`` paths)
are ground code in ``gyrostar.hil.calibrate``; here are the flight parts: estimation
modules that take plain arrays (``allan``, ``scale_fit``, ``dark_frames``, ``intrinsics``,
``align_fit``, ``gyro_integral``, ``star_fields``), live gyro recording (``gyro_log``), the
calibration TOML (``calfile``) and its use in the loop (``apply``, ``hot_pixels``), and the
report folder helpers (``report``).
"""
