"""Estimation core (paper 000 and beyond), numba-compiled, no Python objects per sample.

Modules (import the one you need; this package imports nothing heavy):

* ``motion``       — spot motion on the image plane and trajectory prediction from gyro rates
* ``windows``      — extraction windows as row spans (trajectory union of k×k squares; fixed)
* ``centroid``     — background, CoG, weighted CoG, smeared-PSF least-squares fit (EKF default)
* ``spot_ekf``     — the 5-state spot EKF of paper 000 ([x, y, bx, by, bz])
* ``joint_filter`` — all tracked spots sharing one gyro bias (state 2n + 3)
* ``mekf``         — attitude multiplicative EKF (quaternion + gyro bias)
* ``quest``        — QUEST snapshot attitude with covariance
* ``crlb``         — Cramér–Rao bound of a centroid (Mortensen et al. 2010)

Paper 000's sim1..sim4 on the simulator (``gyrostar eval centroid``) are ground code:
``gyrostar.hil.evaluation``.

Frames: ``gyrostar.attitude`` (body = camera, +z boresight, x columns, y rows; q scalar
last, ICRS → body). Image-plane coordinates in pixels from the principal point.
"""
