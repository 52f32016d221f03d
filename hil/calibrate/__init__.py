"""Calibration front ends (``gyrostar calibrate NAME``): command-line modules with their
``--simulate`` paths on the simulator; the estimation they call is flight code in
:mod:`gyrostar.calibration`."""
