"""Quaternion and frame conventions shared by every stage (numba, ``cache=True``).

Conventions (also in docs/ARCHITECTURE.md, "Frames and units"):

* Quaternion ``q = [x, y, z, w]`` (vector part first, scalar last; Shuster/Markley).
  ``q`` maps inertial (ICRS) vectors to body: ``v_body = A(q) @ v_icrs`` with
  ``A(q) = (w² - |e|²) I + 2 e eᵀ - 2 w [e×]``.
* Composition ``q ⊗ p`` with ``A(q ⊗ p) = A(q) A(p)``.
* Body frame = camera frame: +z the boresight (out of the lens, to the sky), +x along
  increasing sensor column, +y along increasing sensor row (x right, y down, z forward).
* ``ω`` is the body angular rate relative to inertial, in body axes, rad/s. Kinematics
  ``q̇ = ½ Ω(ω) q``; a star direction in the body frame moves as ``ṡ = -ω × s``.
* Exact step for constant ``ω`` over ``dt``: ``q(t+dt) = δq(ω dt) ⊗ q(t)`` with
  ``δq(φ) = [sin(|φ|/2) φ/|φ|, cos(|φ|/2)]``.
* Small attitude error of an estimate: ``δθ = 2 vec(q_est ⊗ q_true⁻¹)`` (rad, body axes);
  components x, y are cross-boresight, z is roll about the boresight.
* Boresight at (ra, dec) with roll 0 has image ``-y`` (up) towards celestial north.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def quat_mult(q, p):
    """q ⊗ p, so that A(q ⊗ p) = A(q) A(p)."""
    out = np.empty(4)
    out[0] = p[3] * q[0] + q[3] * p[0] - (q[1] * p[2] - q[2] * p[1])
    out[1] = p[3] * q[1] + q[3] * p[1] - (q[2] * p[0] - q[0] * p[2])
    out[2] = p[3] * q[2] + q[3] * p[2] - (q[0] * p[1] - q[1] * p[0])
    out[3] = q[3] * p[3] - (q[0] * p[0] + q[1] * p[1] + q[2] * p[2])
    return out


@njit(cache=True)
def quat_conj(q):
    """Inverse of a unit quaternion."""
    return np.array([-q[0], -q[1], -q[2], q[3]])


@njit(cache=True)
def quat_normalize(q):
    """Unit quaternion with non-negative scalar part."""
    n = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    s = 1.0 / n if q[3] >= 0.0 else -1.0 / n
    return np.array([q[0] * s, q[1] * s, q[2] * s, q[3] * s])


@njit(cache=True)
def quat_to_dcm(q):
    """Attitude matrix A(q): inertial -> body."""
    x, y, z, w = q[0], q[1], q[2], q[3]
    a = np.empty((3, 3))
    a[0, 0] = w * w + x * x - y * y - z * z
    a[0, 1] = 2.0 * (x * y + w * z)
    a[0, 2] = 2.0 * (x * z - w * y)
    a[1, 0] = 2.0 * (x * y - w * z)
    a[1, 1] = w * w - x * x + y * y - z * z
    a[1, 2] = 2.0 * (y * z + w * x)
    a[2, 0] = 2.0 * (x * z + w * y)
    a[2, 1] = 2.0 * (y * z - w * x)
    a[2, 2] = w * w - x * x - y * y + z * z
    return a


@njit(cache=True)
def dcm_to_quat(a):
    """Quaternion of an attitude matrix (Shepperd's method, robust for all angles)."""
    tr = a[0, 0] + a[1, 1] + a[2, 2]
    q = np.empty(4)
    if tr >= a[0, 0] and tr >= a[1, 1] and tr >= a[2, 2]:
        w = 0.5 * np.sqrt(1.0 + tr)
        q[3] = w
        q[0] = (a[1, 2] - a[2, 1]) / (4.0 * w)
        q[1] = (a[2, 0] - a[0, 2]) / (4.0 * w)
        q[2] = (a[0, 1] - a[1, 0]) / (4.0 * w)
    elif a[0, 0] >= a[1, 1] and a[0, 0] >= a[2, 2]:
        x = 0.5 * np.sqrt(1.0 + 2.0 * a[0, 0] - tr)
        q[0] = x
        q[1] = (a[0, 1] + a[1, 0]) / (4.0 * x)
        q[2] = (a[0, 2] + a[2, 0]) / (4.0 * x)
        q[3] = (a[1, 2] - a[2, 1]) / (4.0 * x)
    elif a[1, 1] >= a[2, 2]:
        y = 0.5 * np.sqrt(1.0 + 2.0 * a[1, 1] - tr)
        q[1] = y
        q[0] = (a[0, 1] + a[1, 0]) / (4.0 * y)
        q[2] = (a[1, 2] + a[2, 1]) / (4.0 * y)
        q[3] = (a[2, 0] - a[0, 2]) / (4.0 * y)
    else:
        z = 0.5 * np.sqrt(1.0 + 2.0 * a[2, 2] - tr)
        q[2] = z
        q[0] = (a[0, 2] + a[2, 0]) / (4.0 * z)
        q[1] = (a[1, 2] + a[2, 1]) / (4.0 * z)
        q[3] = (a[0, 1] - a[1, 0]) / (4.0 * z)
    return quat_normalize(q)


@njit(cache=True)
def rotvec_to_quat(phi):
    """δq(φ) = [sin(|φ|/2) φ/|φ|, cos(|φ|/2)] for a rotation vector φ (rad)."""
    angle = np.sqrt(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2])
    half = 0.5 * angle
    # sin(half)/angle, with its series near zero
    k = 0.5 - angle * angle / 48.0 if angle < 1e-6 else np.sin(half) / angle
    return np.array([phi[0] * k, phi[1] * k, phi[2] * k, np.cos(half)])


@njit(cache=True)
def quat_propagate(q, omega, dt):
    """Exact step of q under constant body rate ``omega`` (rad/s) for ``dt`` seconds."""
    return quat_normalize(quat_mult(rotvec_to_quat(omega * dt), q))


@njit(cache=True)
def quat_rotate(q, v):
    """A(q) v: an inertial vector expressed in body axes."""
    return quat_to_dcm(q) @ v


@njit(cache=True)
def quat_error_angles(q_est, q_true):
    """Small-angle error δθ = 2 vec(q_est ⊗ q_true⁻¹) in body axes (rad)."""
    dq = quat_mult(q_est, quat_conj(q_true))
    s = 2.0 if dq[3] >= 0.0 else -2.0
    return np.array([s * dq[0], s * dq[1], s * dq[2]])


@njit(cache=True)
def radec_to_vec(ra, dec):
    """ICRS unit vector from right ascension and declination (rad)."""
    cd = np.cos(dec)
    return np.array([cd * np.cos(ra), cd * np.sin(ra), np.sin(dec)])


@njit(cache=True)
def quat_from_boresight(ra, dec, roll):
    """Attitude whose +z (boresight) points at (ra, dec), image up (-y) to north at roll 0.

    ``roll`` (rad) turns the body x/y axes about the boresight (positive from +x to +y).
    """
    z = radec_to_vec(ra, dec)
    north = np.array([-np.sin(dec) * np.cos(ra), -np.sin(dec) * np.sin(ra), np.cos(dec)])
    y0 = -north
    x0 = np.cross(y0, z)
    c, s = np.cos(roll), np.sin(roll)
    x = c * x0 + s * y0
    y = -s * x0 + c * y0
    a = np.empty((3, 3))
    a[0, :] = x
    a[1, :] = y
    a[2, :] = z
    return dcm_to_quat(a)


def random_attitudes(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` attitudes uniform on SO(3) (boresight uniform on the sphere, roll uniform)."""
    u = rng.standard_normal((n, 4))
    u /= np.linalg.norm(u, axis=1)[:, None]
    u[u[:, 3] < 0] *= -1.0
    return u
