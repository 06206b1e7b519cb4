"""Elliptical geometry shared by light and mass profiles (SPEC §2.1).

* Angles φ in degrees, counter-clockwise from +x; the major axis lies along x′.
* Profile frame: x′ = (x − x_c) cos φ + (y − y_c) sin φ,
  y′ = −(x − x_c) sin φ + (y − y_c) cos φ.
* ``ell_comps = (e1, e2) = (f cos 2φ, f sin 2φ)``, f = (1 − q)/(1 + q) (lenstronomy order;
  the PyAutoLens anchor stores the reverse order).
"""

import numpy as np

MAX_ELLIPTICITY = 0.999


def ell_comps_from(axis_ratio: float, angle: float) -> tuple[float, float]:
    """``(e1, e2)`` of an ellipse with axis ratio q = minor/major and angle φ (degrees)."""
    if not 0.0 < axis_ratio <= 1.0:
        raise ValueError(f"axis_ratio must be in (0, 1], got {axis_ratio}")
    f = (1.0 - axis_ratio) / (1.0 + axis_ratio)
    two_phi = np.deg2rad(2.0 * angle)
    return float(f * np.cos(two_phi)), float(f * np.sin(two_phi))


def axis_ratio_and_angle_from(ell_comps: tuple[float, float]) -> tuple[float, float]:
    """``(q, φ)`` from ``(e1, e2)``; φ in [0, 180) degrees, f capped at 0.999."""
    e1, e2 = ell_comps
    f = min(float(np.hypot(e1, e2)), MAX_ELLIPTICITY)
    angle = 0.5 * float(np.rad2deg(np.arctan2(e2, e1)))
    if angle < 0.0:
        angle += 180.0
    return (1.0 - f) / (1.0 + f), angle


def to_profile_frame(
    x: np.ndarray, y: np.ndarray, centre: tuple[float, float], angle: float
) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates (x′, y′) in the frame centred on ``centre`` and rotated by ``angle``."""
    phi = np.deg2rad(angle)
    cos_phi, sin_phi = np.cos(phi), np.sin(phi)
    dx = np.asarray(x) - centre[0]
    dy = np.asarray(y) - centre[1]
    return dx * cos_phi + dy * sin_phi, -dx * sin_phi + dy * cos_phi


def from_profile_frame(
    vx: np.ndarray, vy: np.ndarray, angle: float
) -> tuple[np.ndarray, np.ndarray]:
    """Rotate a vector field given in the profile frame back to the (x, y) frame."""
    phi = np.deg2rad(angle)
    cos_phi, sin_phi = np.cos(phi), np.sin(phi)
    return vx * cos_phi - vy * sin_phi, vx * sin_phi + vy * cos_phi
