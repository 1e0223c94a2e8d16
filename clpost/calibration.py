r"""The computer-vision standard camera model (OpenCV / Matlab) and calibration files.

Forward model (OpenCV ``projectPoints``; Lambers, Sommerhoff & Kolb, "Realistic Lens
Distortion Rendering", WSCG 2018, eq. 1–4). A camera-space point (X, Y, Z) → undistorted
normalised coordinates :math:`x' = X/Z,\ y' = Y/Z`, :math:`r^2 = x'^2 + y'^2`:

.. math::

    x'' &= x'\,\frac{1 + k_1 r^2 + k_2 r^4 + k_3 r^6}{1 + k_4 r^2 + k_5 r^4 + k_6 r^6}
           + 2 p_1 x'y' + p_2 (r^2 + 2x'^2) + s_1 r^2 + s_2 r^4 \\
    y'' &= y'\,\frac{1 + k_1 r^2 + k_2 r^4 + k_3 r^6}{1 + k_4 r^2 + k_5 r^4 + k_6 r^6}
           + p_1 (r^2 + 2y'^2) + 2 p_2 x'y' + s_3 r^2 + s_4 r^4 \\
    (x''', y''') &= \text{tilt}(\tau_x, \tau_y)\,(x'', y'') \qquad
    u = f_x x''' + c_x,\quad v = f_y y''' + c_y

The tilt is OpenCV's ``computeTiltProjectionMatrix`` (Scheimpflug sensor). Pixel coordinates
follow ``shared/CONVENTIONS.md`` (pixel centres at integers, OpenCV).

Inverse (distorted → undistorted, what post-processing needs, because each output pixel asks
where its light came from in the pinhole render):

* :func:`undistort_newton` — exact: Newton's method on the full model, analytic-free Jacobian by
  central differences in float64, started from the distorted point; a point counts as converged
  when the forward model reproduces it to ``tol_px`` (default 1e-6 px). Points that do not
  converge, or converge beyond the fold radius, are reported invalid (never silently used).
* :class:`HeikkilaInverse` — the approximation Lambers et al. use (Heikkilä & Silvén, "A
  four-step camera calibration procedure with implicit image correction", CVPR 1997, eq. 17):
  an 8-parameter rational model fitted by linear least squares to forward-projected samples;
  only meant for k1, k2, p1, p2.

Fold-over: the radial part :math:`\rho(r) = r\,R(r)` must grow with r; beyond its first
maximum (or a pole of the rational denominator) two undistorted radii map to one distorted radius
and no inverse exists. :meth:`OpenCVModel.fold_radius` finds the first r where
:math:`d\rho/dr \le 0` (or the denominator reaches 0); output pixels whose distorted radius lies
beyond :math:`\rho(r_\text{fold})` have no preimage and are **clamped**: marked invalid, i.e.
alpha 0 in the distortion stage. Tangential / thin-prism terms are not part of this check.

Calibration files (:func:`load_calibration`): OpenCV FileStorage YAML or JSON
(``camera_matrix``, ``distortion_coefficients``, ``image_width``/``image_height``), ROS
``camera_info`` YAML (``camera_matrix``, ``distortion_model: plumb_bob|rational_polynomial``,
``distortion_coefficients``, ``image_width``/``image_height``) and COLMAP ``cameras.txt``
(``SIMPLE_RADIAL``, ``RADIAL``, ``OPENCV``, ``FULL_OPENCV``).
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field, fields, replace
from functools import lru_cache
from pathlib import Path

import numpy as np

from .errors import InputError

COEFF_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4", "tau_x", "tau_y")
"""OpenCV's order of the distortion vector (4, 5, 8, 12 or 14 entries)."""


@dataclass(frozen=True)
class OpenCVModel:
    """A calibrated camera: intrinsics in pixels for an image of ``width`` × ``height`` pixels and
    OpenCV's distortion coefficients (dimensionless; τ in radians)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    k5: float = 0.0
    k6: float = 0.0
    s1: float = 0.0
    s2: float = 0.0
    s3: float = 0.0
    s4: float = 0.0
    tau_x: float = 0.0
    tau_y: float = 0.0
    inverse: str = "newton"
    """How the stage inverts the model: ``newton`` (exact) or ``heikkila`` (the paper's fit)."""
    source: str = field(default="", compare=False)
    """Where the model came from (file path), for messages."""

    def __post_init__(self) -> None:
        for n in ("width", "height"):
            v = getattr(self, n)
            if int(v) != v or v < 1:
                raise InputError(f"OpenCVModel.{n}={v!r} must be a whole number of pixels >= 1{self._where()}")
            object.__setattr__(self, n, int(v))
        for f in fields(self):
            if f.name in ("width", "height", "inverse", "source"):
                continue
            v = getattr(self, f.name)
            try:
                v = float(v)
            except (TypeError, ValueError):
                raise InputError(f"OpenCVModel.{f.name}={v!r} is not a number{self._where()}") from None
            if not math.isfinite(v):
                raise InputError(f"OpenCVModel.{f.name}={v!r} must be finite{self._where()}")
            object.__setattr__(self, f.name, v)
        if not (self.fx > 0 and self.fy > 0):
            raise InputError(f"OpenCVModel: focal lengths fx={self.fx}, fy={self.fy} px must be > 0{self._where()}")
        if abs(self.tau_x) >= math.pi / 2 or abs(self.tau_y) >= math.pi / 2:
            raise InputError(f"OpenCVModel: tilt tau_x={self.tau_x}, tau_y={self.tau_y} must be within ±90° (radians){self._where()}")
        if self.inverse not in ("newton", "heikkila"):
            raise InputError(f"OpenCVModel.inverse={self.inverse!r} must be 'newton' or 'heikkila'")

    def _where(self) -> str:
        return f" (from {self.source})" if self.source else ""

    # -- construction -----------------------------------------------------------------------
    @staticmethod
    def from_vector(width: int, height: int, k: np.ndarray, d, source: str = "") -> "OpenCVModel":
        """From a 3×3 camera matrix and an OpenCV distortion vector of 4/5/8/12/14 entries."""
        k = np.asarray(k, dtype=np.float64)
        d = np.asarray(d, dtype=np.float64).reshape(-1)
        where = f" in {source}" if source else ""
        if k.shape != (3, 3):
            raise InputError(f"camera_matrix{where} must be 3×3, got shape {k.shape}")
        if abs(k[0, 1]) > 1e-9 * abs(k[0, 0]) or k[1, 0] or k[2, 0] or k[2, 1] or abs(k[2, 2] - 1) > 1e-12:
            raise InputError(f"camera_matrix{where} must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] "
                             f"(no skew); got {k.tolist()}")
        if d.size not in (4, 5, 8, 12, 14):
            raise InputError(f"distortion_coefficients{where} has {d.size} entries; OpenCV uses 4, 5, 8, 12 "
                             f"or 14 ({', '.join(COEFF_NAMES)})")
        coeffs = dict(zip(COEFF_NAMES, d.tolist()))
        return OpenCVModel(width, height, k[0, 0], k[1, 1], k[0, 2], k[1, 2], source=source, **coeffs)

    @staticmethod
    def from_camera(camera, size: tuple[int, int], **coeffs) -> "OpenCVModel":
        """The camera's own pinhole intrinsics at ``size`` plus the given coefficients."""
        fx, fy, cx, cy = camera.intrinsics(*size)
        return OpenCVModel(size[0], size[1], fx, fy, cx, cy, **coeffs)

    def vector(self) -> np.ndarray:
        """The 14-entry OpenCV distortion vector."""
        return np.array([getattr(self, n) for n in COEFF_NAMES])

    def matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def scaled_to(self, width: int, height: int) -> "OpenCVModel":
        r"""The same camera at another resolution of the same aspect: pixel-centre convention,
        so :math:`c' = (c + \tfrac12) s - \tfrac12`, :math:`f' = f s`."""
        sx, sy = width / self.width, height / self.height
        if abs(sx - sy) > 1e-3 * sx:
            raise InputError(
                f"frame size {width}x{height} has another aspect ratio than the calibration "
                f"{self.width}x{self.height}{self._where()}; render at the calibration's size (or a multiple)")
        return replace(self, width=width, height=height, fx=self.fx * sx, fy=self.fy * sy,
                       cx=(self.cx + 0.5) * sx - 0.5, cy=(self.cy + 0.5) * sy - 0.5)

    @property
    def is_identity(self) -> bool:
        return not np.any(self.vector())

    # -- the forward model --------------------------------------------------------------------
    def _tilt(self) -> np.ndarray:
        cx_, sx_ = math.cos(self.tau_x), math.sin(self.tau_x)
        cy_, sy_ = math.cos(self.tau_y), math.sin(self.tau_y)
        rot_x = np.array([[1, 0, 0], [0, cx_, sx_], [0, -sx_, cx_]])
        rot_y = np.array([[cy_, 0, -sy_], [0, 1, 0], [sy_, 0, cy_]])
        rxy = rot_y @ rot_x
        proj = np.array([[rxy[2, 2], 0, -rxy[0, 2]], [0, rxy[2, 2], -rxy[1, 2]], [0, 0, 1]])
        return proj @ rxy

    def radial(self, r2: np.ndarray) -> np.ndarray:
        """R(r²) = (1 + k1 r² + k2 r⁴ + k3 r⁶)/(1 + k4 r² + k5 r⁴ + k6 r⁶)."""
        num = 1 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        den = 1 + r2 * (self.k4 + r2 * (self.k5 + r2 * self.k6))
        return num / den

    def distort_normalized(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Undistorted normalised (x', y') → distorted normalised (x''', y''') (float64)."""
        r2 = x * x + y * y
        rad = self.radial(r2)
        xd = x * rad + 2 * self.p1 * x * y + self.p2 * (r2 + 2 * x * x) + self.s1 * r2 + self.s2 * r2 * r2
        yd = y * rad + self.p1 * (r2 + 2 * y * y) + 2 * self.p2 * x * y + self.s3 * r2 + self.s4 * r2 * r2
        if self.tau_x or self.tau_y:
            t = self._tilt()
            w = t[2, 0] * xd + t[2, 1] * yd + t[2, 2]
            xd, yd = (t[0, 0] * xd + t[0, 1] * yd + t[0, 2]) / w, (t[1, 0] * xd + t[1, 1] * yd + t[1, 2]) / w
        return xd, yd

    def project(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Undistorted normalised coordinates → distorted pixel coordinates (u, v)."""
        xd, yd = self.distort_normalized(np.asarray(x, np.float64), np.asarray(y, np.float64))
        return self.fx * xd + self.cx, self.fy * yd + self.cy

    def normalize(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distorted pixel coordinates → distorted normalised coordinates (before untilting)."""
        return (np.asarray(u, np.float64) - self.cx) / self.fx, (np.asarray(v, np.float64) - self.cy) / self.fy

    # -- fold-over ----------------------------------------------------------------------------
    def fold_radius(self, r_max: float = 20.0, n: int = 200001) -> float:
        r"""First undistorted radius r (normalised) where :math:`\rho(r) = r R(r^2)` stops
        increasing or the denominator of R reaches 0; ``inf`` if none up to ``r_max``."""
        r = np.linspace(0.0, r_max, n)
        r2 = r * r
        den = 1 + r2 * (self.k4 + r2 * (self.k5 + r2 * self.k6))
        rho = r * self.radial(np.where(den > 0, r2, 0.0))
        bad = (den <= 0)[1:] | (np.diff(rho) <= 0)
        if not bad.any():
            return math.inf
        return float(r[int(np.argmax(bad))])

    def fold_distorted_radius(self) -> float:
        """ρ(r_fold): the largest distorted radius the monotonic branch reaches (inf if none)."""
        rf = self.fold_radius()
        if math.isinf(rf):
            return math.inf
        return float(rf * self.radial(np.array(rf * rf)))


# ---------------------------------------------------------------------------------------------
# Inverses
# ---------------------------------------------------------------------------------------------


def undistort_newton(model: OpenCVModel, u: np.ndarray, v: np.ndarray, tol_px: float = 1e-6,
                     max_iter: int = 60) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""Exact inverse: distorted pixels (u, v) → undistorted normalised (x', y') and a validity mask.

    Newton iteration :math:`x_{k+1} = x_k - J^{-1}(D(x_k) - x_d)` on the full model D in pixel
    units, J by central differences (h = 1e-7), steps limited to 0.5 normalised units so a
    strong model cannot jump across the fold. Valid ⇔ converged to ``tol_px`` within
    ``max_iter`` iterations, finite, and inside the monotonic branch (r < r_fold).
    """
    u = np.asarray(u, np.float64)
    v = np.asarray(v, np.float64)
    x, y = model.normalize(u, v)
    x, y = x.copy(), y.copy()
    h = 1e-7
    rf = model.fold_radius()
    done = np.zeros(u.shape, bool)
    err = np.full(u.shape, np.inf)
    with np.errstate(all="ignore"):
        for _ in range(max_iter):
            pu, pv = model.project(x, y)
            eu, ev = pu - u, pv - v
            err = np.hypot(eu, ev)
            done = err < tol_px
            if done.all():
                break
            a, c = model.project(x + h, y)
            b, d = model.project(x - h, y)
            j11, j21 = (a - b) / (2 * h), (c - d) / (2 * h)
            a, c = model.project(x, y + h)
            b, d = model.project(x, y - h)
            j12, j22 = (a - b) / (2 * h), (c - d) / (2 * h)
            det = j11 * j22 - j12 * j21
            dx = (j22 * eu - j12 * ev) / det
            dy = (-j21 * eu + j11 * ev) / det
            step = np.hypot(dx, dy)
            scale = np.where(step > 0.5, 0.5 / np.maximum(step, 1e-300), 1.0)
            upd = ~done & np.isfinite(dx) & np.isfinite(dy)
            x = np.where(upd, x - scale * dx, x)
            y = np.where(upd, y - scale * dy, y)
        pu, pv = model.project(x, y)
        err = np.hypot(pu - u, pv - v)
    valid = (err < tol_px) & np.isfinite(x) & np.isfinite(y) & (np.hypot(x, y) < rf)
    return np.where(valid, x, 0.0), np.where(valid, y, 0.0), valid


@dataclass(frozen=True)
class HeikkilaInverse:
    r"""Heikkilä & Silvén's implicit inverse model (CVPR 1997, eq. 17), as used by Lambers et al.:

    .. math::

        x = \frac{\tilde x + \tilde x (a_1\tilde r^2 + a_2\tilde r^4) + 2a_3\tilde x\tilde y + a_4(\tilde r^2 + 2\tilde x^2)}{G},\quad
        y = \frac{\tilde y + \tilde y (a_1\tilde r^2 + a_2\tilde r^4) + a_3(\tilde r^2 + 2\tilde y^2) + 2a_4\tilde x\tilde y}{G}

    with :math:`G = (a_5\tilde r^2 + a_6\tilde x + a_7\tilde y)\tilde r^2 + 1` and
    :math:`(\tilde x, \tilde y)` distorted normalised coordinates. a₁…a₇ are fitted by linear least
    squares (multiplying through by G) to a 60×60 grid of undistorted points spanning the image,
    pushed through the forward model. Models with k3…k6, s, τ are outside its form: the residual
    (reported by :func:`inverse_residual_px`) says how far off it is.
    """

    a: tuple[float, ...]

    @staticmethod
    def fit(model: OpenCVModel, n: int = 60) -> "HeikkilaInverse":
        uu, vv = np.meshgrid(np.linspace(-0.5, model.width - 0.5, n), np.linspace(-0.5, model.height - 0.5, n))
        xu, yu, ok = undistort_newton(model, uu.ravel(), vv.ravel())
        xu, yu = xu[ok], yu[ok]
        xd, yd = model.distort_normalized(xu, yu)
        r2 = xd * xd + yd * yd
        rows_x = np.stack([xd * r2, xd * r2 * r2, 2 * xd * yd, r2 + 2 * xd * xd,
                           -xu * r2 * r2, -xu * xd * r2, -xu * yd * r2], -1)
        rows_y = np.stack([yd * r2, yd * r2 * r2, r2 + 2 * yd * yd, 2 * xd * yd,
                           -yu * r2 * r2, -yu * xd * r2, -yu * yd * r2], -1)
        a_mat = np.concatenate([rows_x, rows_y])
        rhs = np.concatenate([xu - xd, yu - yd])
        a, *_ = np.linalg.lstsq(a_mat, rhs, rcond=None)
        return HeikkilaInverse(tuple(float(t) for t in a))

    def __call__(self, xd: np.ndarray, yd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a1, a2, a3, a4, a5, a6, a7 = self.a
        r2 = xd * xd + yd * yd
        g = (a5 * r2 + a6 * xd + a7 * yd) * r2 + 1
        x = (xd + xd * (a1 * r2 + a2 * r2 * r2) + 2 * a3 * xd * yd + a4 * (r2 + 2 * xd * xd)) / g
        y = (yd + yd * (a1 * r2 + a2 * r2 * r2) + a3 * (r2 + 2 * yd * yd) + 2 * a4 * xd * yd) / g
        return x, y


def undistort(model: OpenCVModel, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distorted pixels → undistorted normalised coordinates + validity, by ``model.inverse``."""
    if model.inverse == "newton":
        return undistort_newton(model, u, v)
    x, y = HeikkilaInverse.fit(model)(*model.normalize(u, v))
    valid = np.isfinite(x) & np.isfinite(y) & (np.hypot(x, y) < model.fold_radius())
    return np.where(valid, x, 0.0), np.where(valid, y, 0.0), valid


def inverse_residual_px(model: OpenCVModel, method: str = "newton") -> dict:
    """max / RMS of |forward(inverse(p)) − p| in pixels over every pixel centre of the image,
    with where the maximum is, for ``newton`` or ``heikkila``."""
    vv, uu = np.mgrid[0:model.height, 0:model.width].astype(np.float64)
    x, y, ok = undistort(replace(model, inverse=method), uu, vv)
    pu, pv = model.project(x, y)
    e = np.where(ok, np.hypot(pu - uu, pv - vv), 0.0)
    j = np.unravel_index(int(np.argmax(e)), e.shape)
    return {"method": method, "max_px": float(e.max()), "rms_px": float(np.sqrt(np.mean(e[ok] ** 2))),
            "argmax_xy": (int(j[1]), int(j[0])), "invalid_pixels": int((~ok).sum())}


# ---------------------------------------------------------------------------------------------
# What the undistorted render must cover
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RenderSpec:
    r"""A pinhole render (square pixels) that covers every output pixel of a distorted image.

    Frustum at unit distance in OpenCV's pixel-centre convention (Lambers et al., sec. 3.2;
    ``shared/CONVENTIONS.md``):

    .. math::

        l = -\frac{c_x + 0.5}{f},\ r = \frac{W}{f} + l,\ b = -\frac{c_y + 0.5}{f},\ t = \frac{H}{f} + b

    (b, t are in OpenCV's y-down image axis; an OpenGL projection uses −t, −b.)
    """

    width: int
    height: int
    f: float
    cx: float
    cy: float

    def intrinsics(self) -> tuple[float, float, float, float]:
        return self.f, self.f, self.cx, self.cy

    def frustum(self) -> tuple[float, float, float, float]:
        left = -(self.cx + 0.5) / self.f
        bottom = -(self.cy + 0.5) / self.f
        return left, self.width / self.f + left, bottom, self.height / self.f + bottom


@lru_cache(maxsize=32)
def _radial_fit(lens: str, focus_distance_m: float, f_number: float, r_max_mm: float):
    """k1, k2, k3 least-squares fitted to the traced distortion curve over image heights up to
    ``r_max_mm``, and the fit's worst residual in percent."""
    from .optics.curves import lens_curves

    c = lens_curves(lens, focus_distance_m, f_number)
    keep = c.image_height_mm <= r_max_mm + 1e-9
    t = np.tan(np.radians(c.field_angle_deg[keep]))
    d = c.distortion_pct[keep] / 100.0
    a = np.stack([t ** 2, t ** 4, t ** 6], -1)
    k = np.linalg.lstsq(a, d, rcond=None)[0]
    return tuple(float(v) for v in k), float(100.0 * np.max(np.abs(a @ k - d), initial=0.0))


def lens_distortion_model(camera, size: tuple[int, int]) -> "OpenCVModel | None":
    r"""The traced lens's distortion as an OpenCV radial model at ``size`` (None for a thin lens,
    with ``camera.lens_distortion`` off, or when the lens is distortion-free to 0.001 %).

    The traced curve gives :math:`D(\theta) = r_{real}/r_{par} - 1` against the chief ray's
    object-space angle θ (:mod:`clpost.optics.curves`); the pinhole render puts that ray at the
    normalised radius :math:`\tan\theta`, so :math:`x_d = x_u (1 + D)` is OpenCV's radial model
    with :math:`D \approx k_1 t^2 + k_2 t^4 + k_3 t^6`, t = tan θ, fitted by least squares over the
    sensor's half diagonal (the worst residual is kept in the model's ``source``). The scale is
    the camera's own (f = v / pixel pitch): the curve sets the shape, the focus sets the size.
    """
    if camera.optics is None or not camera.lens_distortion:
        return None
    w, h = size
    pitch = camera.pixel_pitch_mm(w)
    r_max = 0.5 * math.hypot(w * pitch, h * pitch)
    (k1, k2, k3), resid = _radial_fit(camera.lens, camera.focus_distance_m, camera.f_number, r_max)
    if max(abs(k1), abs(k2), abs(k3)) < 1e-5:
        return None
    return OpenCVModel.from_camera(camera, (w, h), k1=k1, k2=k2, k3=k3,
                                   source=f"{camera.lens} traced distortion curve, fit residual {resid:.3g} %")


def required_render(model: OpenCVModel, margin_px: float = 2.0) -> RenderSpec:
    r"""The undistorted render that leaves no output pixel unfilled.

    Every point of the output image's border ([−0.5, W−0.5] × [−0.5, H−0.5], 4·(W+H) samples) is
    undistorted; the render keeps the model's larger focal length f = max(f_x, f_y) (the same
    pixel density at the centre) and gets the frustum of the bounding box of those points
    (union with the model's own frustum), widened by ``margin_px`` for the resampling filter's
    support. Barrel distortion → a larger render, pincushion → the model's own frustum.
    Points beyond the fold (no preimage) are left out: they stay alpha 0 anyway.
    """
    w, h = model.width, model.height
    t = np.linspace(-0.5, w - 0.5, 4 * w + 1)
    s = np.linspace(-0.5, h - 0.5, 4 * h + 1)
    u = np.concatenate([t, t, np.full_like(s, -0.5), np.full_like(s, w - 0.5)])
    v = np.concatenate([np.full_like(t, -0.5), np.full_like(t, h - 0.5), s, s])
    x, y, ok = undistort_newton(model, u, v)
    f = max(model.fx, model.fy)
    # the model's own (pinhole) frustum
    x0, x1 = -(model.cx + 0.5) / model.fx, (w - 0.5 - model.cx) / model.fx
    y0, y1 = -(model.cy + 0.5) / model.fy, (h - 0.5 - model.cy) / model.fy
    if ok.any():
        x0, x1 = min(x0, x[ok].min()), max(x1, x[ok].max())
        y0, y1 = min(y0, y[ok].min()), max(y1, y[ok].max())
    m = margin_px / f
    x0, x1, y0, y1 = x0 - m, x1 + m, y0 - m, y1 + m
    rw, rh = int(math.ceil(f * (x1 - x0))), int(math.ceil(f * (y1 - y0)))
    # l = −(c + 0.5)/f = x0  ⇒  c = −x0 f − 0.5
    return RenderSpec(rw, rh, float(f), float(-x0 * f - 0.5), float(-y0 * f - 0.5))


def render_intrinsics(model: OpenCVModel, size: tuple[int, int]) -> tuple[float, float, float, float] | None:
    """(f_x, f_y, c_x, c_y) of an undistorted render of ``size`` made for this calibration: its own
    K at the calibration's size, :func:`required_render`'s frustum at that size; None otherwise."""
    if tuple(size) == (model.width, model.height):
        return float(model.fx), float(model.fy), float(model.cx), float(model.cy)
    spec = required_render(model)
    if tuple(size) == (spec.width, spec.height):
        return spec.intrinsics()
    return None


# ---------------------------------------------------------------------------------------------
# Calibration files
# ---------------------------------------------------------------------------------------------


def _read_opencv_yaml(text: str) -> dict:
    """The subset of OpenCV FileStorage YAML calibration files use: scalars and ``!!opencv-matrix``
    mappings (rows, cols, dt, data: [...]); also plain ROS YAML."""
    import yaml

    class _Loader(yaml.SafeLoader):
        pass

    def _matrix(loader, node):
        return loader.construct_mapping(node, deep=True)

    _Loader.add_constructor("tag:yaml.org,2002:opencv-matrix", _matrix)
    _Loader.add_multi_constructor("!", lambda loader, suffix, node: loader.construct_mapping(node, deep=True))
    # OpenCV writes a '%YAML:1.0' directive PyYAML rejects (it wants '%YAML 1.1')
    text = re.sub(r"^%YAML[: ]1\.0\s*$", "", text, flags=re.M).lstrip("\n")
    if text.startswith("---"):
        text = text.split("\n", 1)[1] if "\n" in text else ""
    return yaml.load(text, Loader=_Loader) or {}


def _matrix_value(node, name: str, path: str) -> np.ndarray:
    if isinstance(node, dict) and "data" in node:
        data = np.asarray(node["data"], dtype=np.float64)
        rows, cols = int(node.get("rows", 1)), int(node.get("cols", data.size))
        if rows * cols != data.size:
            raise InputError(f"{path}: {name} says {rows}×{cols} but has {data.size} values")
        return data.reshape(rows, cols)
    if isinstance(node, (list, tuple)):
        return np.asarray(node, dtype=np.float64)
    raise InputError(f"{path}: {name} must be a matrix (rows/cols/data) or a list of numbers")


def _size_from(d: dict, path: str) -> tuple[int, int]:
    w = d.get("image_width", d.get("width"))
    h = d.get("image_height", d.get("height"))
    if w is None or h is None:
        raise InputError(f"{path}: no image size; add image_width and image_height (pixels) — "
                         "the intrinsics are only meaningful for the resolution they were calibrated at")
    return int(w), int(h)


def _from_mapping(d: dict, path: str) -> OpenCVModel:
    if not isinstance(d, dict) or "camera_matrix" not in d:
        raise InputError(f"{path}: no camera_matrix; expected an OpenCV FileStorage or ROS camera_info "
                         "file with camera_matrix and distortion_coefficients")
    k = _matrix_value(d["camera_matrix"], "camera_matrix", path).reshape(-1)
    if k.size != 9:
        raise InputError(f"{path}: camera_matrix must have 9 values, has {k.size}")
    dist_node = d.get("distortion_coefficients", d.get("dist_coeffs", d.get("D")))
    if dist_node is None:
        raise InputError(f"{path}: no distortion_coefficients; add them (OpenCV order {', '.join(COEFF_NAMES[:5])}, …)")
    dist = _matrix_value(dist_node, "distortion_coefficients", path).reshape(-1)
    model_name = d.get("distortion_model")
    if model_name is not None and model_name not in ("plumb_bob", "rational_polynomial"):
        raise InputError(f"{path}: distortion_model {model_name!r} is not the OpenCV standard model; "
                         "clpost reads plumb_bob and rational_polynomial (fisheye/equidistant are other models)")
    w, h = _size_from(d, path)
    return OpenCVModel.from_vector(w, h, k.reshape(3, 3), dist, source=path)


COLMAP_MODELS = {
    # name: parameter names (COLMAP src/colmap/sensor/models.h)
    "SIMPLE_RADIAL": ("f", "cx", "cy", "k1"),
    "RADIAL": ("f", "cx", "cy", "k1", "k2"),
    "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
    "FULL_OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
}


def _read_colmap(text: str, path: str, camera_id: int | None) -> OpenCVModel:
    r"""COLMAP ``cameras.txt``: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS…``. COLMAP's pixel
    convention puts the image's top-left *corner* at (0, 0) (pixel centres at i + 0.5), so
    :math:`c_{\text{OpenCV}} = c_{\text{COLMAP}} - 0.5`."""
    rows = [ln.split() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not rows:
        raise InputError(f"{path}: no camera lines (CAMERA_ID MODEL WIDTH HEIGHT PARAMS…)")
    if camera_id is None and len(rows) > 1:
        raise InputError(f"{path}: {len(rows)} cameras; say which with {path}#<CAMERA_ID>")
    row = rows[0] if camera_id is None else next((r for r in rows if r[0] == str(camera_id)), None)
    if row is None:
        raise InputError(f"{path}: no camera with id {camera_id}")
    name = row[1]
    if name not in COLMAP_MODELS:
        raise InputError(f"{path}: COLMAP model {name} is not supported; use one of {', '.join(COLMAP_MODELS)}")
    names = COLMAP_MODELS[name]
    vals = [float(t) for t in row[4:]]
    if len(vals) != len(names):
        raise InputError(f"{path}: {name} needs {len(names)} parameters ({' '.join(names)}), got {len(vals)}")
    p = dict(zip(names, vals))
    if "f" in p:
        p["fx"] = p["fy"] = p.pop("f")
    p["cx"] -= 0.5
    p["cy"] -= 0.5
    return OpenCVModel(int(row[2]), int(row[3]), source=path, **p)


def load_calibration(path: str | Path) -> OpenCVModel:
    """Read a calibration file (format from its content: OpenCV YAML/JSON, ROS YAML, COLMAP txt);
    ``cameras.txt#2`` picks COLMAP camera 2."""
    spec = str(path)
    camera_id = None
    if "#" in spec and spec.rsplit("#", 1)[1].isdigit():
        spec, cid = spec.rsplit("#", 1)
        camera_id = int(cid)
    p = Path(spec)
    try:
        text = p.read_text()
    except FileNotFoundError:
        raise InputError(f"--calibration {spec}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"--calibration {spec}: cannot read it as text ({exc})") from None
    stripped = text.lstrip()
    if stripped.startswith("{"):
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(f"{spec}: invalid JSON ({exc})") from None
        d = d.get("opencv_storage", d) if isinstance(d, dict) else d
        return _from_mapping(d, spec)
    if re.match(r"^(#.*\n|\s*\n)*\s*\d+\s+[A-Z_]+\s+\d+\s+\d+", text) or p.name == "cameras.txt":
        return _read_colmap(text, spec, camera_id)
    try:
        d = _read_opencv_yaml(text)
    except Exception as exc:  # yaml.YAMLError and friends: report as a file problem
        raise InputError(f"{spec}: not a readable OpenCV/ROS YAML, JSON or COLMAP cameras.txt ({exc})") from None
    return _from_mapping(d, spec)
