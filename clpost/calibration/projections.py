r"""The central projections of the camera model families: camera ray → plane coordinates and back.

Every family of :class:`~clpost.calibration.model.OpenCVModel` is *pixel = K · D(P(ray))*: a
central projection P of the ray (X, Y, Z) (camera frame, z forward, y down) to plane coordinates
m, a distortion D of the plane (identity for most families; :mod:`.model` holds D and K), and
the intrinsics :math:`u = f_x m'_x + c_x`, :math:`v = f_y m'_y + c_y`. This module holds each P
and its exact inverse, once, with its source; θ is the angle of the ray to the optical axis and
:math:`d = \sqrt{X^2 + Y^2 + Z^2}`.

=========== ================================================================================
family      P
=========== ================================================================================
opencv      pinhole :math:`m = (X, Y)/Z` (D: OpenCV's rational, tangential, thin-prism, tilt)
fisheye     Kannala–Brandt / ``cv::fisheye`` (Kannala & Brandt, IEEE PAMI 28(8), 2006, eq. 6):
            :math:`|m| = \theta(1 + k_1\theta^2 + k_2\theta^4 + k_3\theta^6 + k_4\theta^8)`
thinprism   equidistant :math:`|m| = \theta` (COLMAP ``THIN_PRISM_FISHEYE``, D: polynomial radial
            in r² to r⁸, tangential, thin prism; ``src/colmap/sensor/models.h``)
ftheta      f-theta polynomial, NVIDIA DriveWorks / Isaac Sim's ``ftheta`` camera in its
            angle → pixel-distance form :math:`r_\text{px} = a_1\theta + a_2\theta^2 + … + a_5\theta^5`
            (a₀ = 0) with :math:`f = a_1`, :math:`k_i = a_{i+1}/a_1`:
            :math:`|m| = \theta + k_1\theta^2 + k_2\theta^3 + k_3\theta^4 + k_4\theta^5`
fov         Devernay & Faugeras, "Straight lines have to be straight", MVA 13(1), 2001, eq. 13
            (COLMAP ``FOV``): :math:`|m| = \arctan(2\tan\theta\,\tan\tfrac\omega2)/\omega`
ucm         unified camera model, Geyer & Daniilidis (ECCV 2000), Mei & Rives (ICRA 2007, eq. 3;
            Kalibr ``omni``, D: radtan k1, k2, p1, p2): :math:`m = (X, Y)/(Z + \xi d)`
ds          double sphere, Usenko, Demmel & Cremers, "The Double Sphere Camera Model", 3DV 2018,
            eq. 40–41: :math:`d_2 = \sqrt{X^2 + Y^2 + (\xi d + Z)^2}`,
            :math:`m = (X, Y)/(\alpha d_2 + (1 - \alpha)(\xi d + Z))`
=========== ================================================================================

The UCM is written in Mei's ξ form (Kalibr's ``omni`` intrinsics ``[xi, fu, fv, pu, pv]``);
Usenko et al.'s α form is the same camera with :math:`\alpha = \xi/(1 + \xi)`,
:math:`f_\alpha = f_\xi (1 - \alpha)`.

Inverses (:func:`unproject`): closed form for pinhole, UCM (Mei & Rives eq. 5), double sphere
(Usenko et al. eq. 47–50) and FOV (:math:`\theta = \arctan(\tan(\omega|m|)/(2\tan\frac\omega2))`);
for the θ-polynomials (fisheye, ftheta) bisection of the monotonic |m|(θ) on [0, θ_max] to float64
precision (64 halvings: exact, no starting guess to go wrong). Validity: a ray projects only inside
the family's domain (θ < :func:`theta_max`: beyond it |m|(θ) folds back, or the UCM/DS
denominators change sign — Usenko et al. eq. 43 and 45), and a plane point unprojects only if
its radius is reached on that branch.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

RADIAL_FAMILIES = ("fisheye", "thinprism", "ftheta", "fov")
"""Families whose P is |m| = ρ(θ) along the ray's azimuth."""


def _rho(model, th: np.ndarray) -> np.ndarray:
    """ρ(θ) = |m| of the radial families (module table)."""
    fam = model.distortion_model
    if fam == "fisheye":
        t2 = th * th
        return th * (1 + t2 * (model.k1 + t2 * (model.k2 + t2 * (model.k3 + t2 * model.k4))))
    if fam == "thinprism":
        return th
    if fam == "ftheta":
        return th * (1 + th * (model.k1 + th * (model.k2 + th * (model.k3 + th * model.k4))))
    if fam == "fov":
        w = model.omega
        if w == 0:
            return np.tan(th)
        return np.arctan(2 * np.tan(th) * math.tan(w / 2)) / w
    raise ValueError(fam)


@lru_cache(maxsize=64)
def theta_max(model) -> float:
    r"""The largest angle to the axis the family projects (radians, ≤ π): the first fold of
    ρ(θ) (:math:`d\rho/d\theta \le 0`, sampled every 1e-5 rad) for the radial families (π/2 for
    FOV and the pinhole); for UCM :math:`\arccos(-\min(\xi, 1/\xi))` (Mei's projection needs
    :math:`Z > -w d`, Usenko et al. eq. 43 with α = ξ/(1+ξ)); for double sphere
    :math:`\arccos(-w_2)`, :math:`w_2 = (w_1 + \xi)/\sqrt{2 w_1 \xi + \xi^2 + 1}`,
    :math:`w_1 = \alpha/(1-\alpha)` for α ≤ ½ else :math:`(1-\alpha)/\alpha` (eq. 45)."""
    fam = model.distortion_model
    if fam in ("opencv", "fov"):
        return math.pi / 2
    if fam == "ucm":
        xi = model.xi
        w = xi if xi <= 1 else 1 / xi
        return math.acos(-w)
    if fam == "ds":
        a, xi = model.alpha, model.xi
        w1 = a / (1 - a) if a <= 0.5 else (1 - a) / a
        w2 = (w1 + xi) / math.sqrt(2 * w1 * xi + xi * xi + 1)
        return math.acos(max(-1.0, min(1.0, -w2)))
    th = np.linspace(0.0, math.pi, 314160)
    bad = np.diff(_rho(model, th)) <= 0
    return float(th[int(np.argmax(bad))]) if bad.any() else math.pi


def project(model, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rays (x, y, z) (any length) → plane coordinates (mx, my) of P and whether the ray is in
    P's domain (θ < :func:`theta_max`). float64."""
    x, y, z = (np.asarray(a, np.float64) for a in (x, y, z))
    fam = model.distortion_model
    d = np.sqrt(x * x + y * y + z * z)
    with np.errstate(all="ignore"):
        cos_t = np.where(d > 0, z / np.where(d > 0, d, 1.0), 1.0)
        ok = (cos_t > math.cos(theta_max(model))) & (d > 0)
        if fam == "opencv":
            den = z
        elif fam == "ucm":
            den = z + model.xi * d
        elif fam == "ds":
            zz = model.xi * d + z
            d2 = np.sqrt(x * x + y * y + zz * zz)
            den = model.alpha * d2 + (1 - model.alpha) * zz
        else:  # radial families: |m| = ρ(θ) along the azimuth
            rxy = np.hypot(x, y)
            th = np.arctan2(rxy, z)
            rho = _rho(model, th)
            s = np.where(rxy > 0, rho / np.where(rxy > 0, rxy, 1.0), 0.0)
            mx, my = x * s, y * s
            return np.where(ok, mx, 0.0), np.where(ok, my, 0.0), ok & np.isfinite(mx) & np.isfinite(my)
        ok &= den > 0
        mx, my = x / np.where(ok, den, 1.0), y / np.where(ok, den, 1.0)
    return np.where(ok, mx, 0.0), np.where(ok, my, 0.0), ok


def unproject(model, mx: np.ndarray, my: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Plane coordinates of P → unit rays (x, y, z) and validity (module docstring). float64."""
    mx, my = np.asarray(mx, np.float64), np.asarray(my, np.float64)
    fam = model.distortion_model
    r2 = mx * mx + my * my
    with np.errstate(all="ignore"):
        if fam == "opencv":
            x, y, z, ok = mx, my, np.ones_like(mx), np.ones(mx.shape, bool)
        elif fam == "ucm":  # Mei & Rives 2007, eq. 5
            xi = model.xi
            disc = 1 + (1 - xi * xi) * r2
            ok = disc >= 0
            k = (xi + np.sqrt(np.where(ok, disc, 0.0))) / (1 + r2)
            x, y, z = k * mx, k * my, k - xi
        elif fam == "ds":  # Usenko et al. 2018, eq. 47–50
            a, xi = model.alpha, model.xi
            ok = np.ones(mx.shape, bool) if a <= 0.5 else r2 <= 1 / (2 * a - 1)
            mz = (1 - a * a * r2) / (a * np.sqrt(np.where(ok, 1 - (2 * a - 1) * r2, 0.0)) + 1 - a)
            k = (mz * xi + np.sqrt(mz * mz + (1 - xi * xi) * r2)) / (mz * mz + r2)
            x, y, z = k * mx, k * my, k * mz - xi
            ok &= np.isfinite(k)
        else:
            rho = np.sqrt(r2)
            tmax = theta_max(model)
            if fam == "fov":
                w = model.omega
                th = np.arctan(rho) if w == 0 else np.arctan(np.tan(w * rho) / (2 * math.tan(w / 2)))
                ok = (w * rho < math.pi / 2) if w else np.ones(rho.shape, bool)
            elif fam == "thinprism":
                th, ok = rho, rho < tmax
            else:  # bisection of the monotonic ρ(θ) on [0, θ_max]
                ok = rho <= _rho(model, np.float64(tmax))
                lo, hi = np.zeros_like(rho), np.full_like(rho, tmax)
                for _ in range(64):
                    mid = 0.5 * (lo + hi)
                    below = _rho(model, mid) < rho
                    lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
                th = 0.5 * (lo + hi)
            s = np.where(rho > 0, np.sin(th) / np.where(rho > 0, rho, 1.0), 1.0)
            x, y, z = mx * s, my * s, np.cos(th)
        n = np.sqrt(x * x + y * y + z * z)
        x, y, z = x / n, y / n, z / n
        ok = ok & np.isfinite(x) & np.isfinite(y) & np.isfinite(z)
        if fam in ("ucm", "ds"):  # the + root must lie in P's domain
            ok &= z > math.cos(theta_max(model)) - 1e-12
    return np.where(ok, x, 0.0), np.where(ok, y, 0.0), np.where(ok, z, 1.0), ok
