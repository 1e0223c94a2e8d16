r"""The computer-vision standard camera model (OpenCV / Matlab): forward model and inverses.

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

Fisheye family (``distortion_model="fisheye"``): OpenCV's ``cv::fisheye`` model, the
equidistant projection with Kannala & Brandt's odd polynomial ("A generic camera model and
calibration method for conventional, wide-angle, and fish-eye lenses", IEEE PAMI 2006) — what ROS
calls ``equidistant``, Kalibr ``equidistant`` and COLMAP ``OPENCV_FISHEYE``. With
:math:`r = \sqrt{x'^2 + y'^2}` and :math:`\theta = \arctan r`:

.. math::

    \theta_d = \theta\,(1 + k_1\theta^2 + k_2\theta^4 + k_3\theta^6 + k_4\theta^8), \qquad
    (x'', y'') = \frac{\theta_d}{r}\,(x', y')

(OpenCV's fisheye skew α is not supported: clpost's K has no skew.) The undistorted coordinates
are a pinhole's, so only rays within 90° of the axis have them.

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
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from functools import lru_cache

import numpy as np

from ..errors import InputError
from . import projections

COEFF_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4", "tau_x", "tau_y")
"""OpenCV's order of the distortion vector (4, 5, 8, 12 or 14 entries)."""

FISHEYE_COEFF_NAMES = ("k1", "k2", "k3", "k4")
"""``cv::fisheye``'s distortion vector (exactly 4 entries)."""

THINPRISM_COEFF_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "s1", "s3")
"""COLMAP ``THIN_PRISM_FISHEYE``'s distortion parameters (its sx1, sy1 are clpost's s1, s3)."""

FAMILY_PARAMS = {
    "opencv": COEFF_NAMES,
    "fisheye": FISHEYE_COEFF_NAMES,
    "thinprism": THINPRISM_COEFF_NAMES,
    "ftheta": ("k1", "k2", "k3", "k4"),
    "fov": ("omega",),
    "ucm": ("xi", "k1", "k2", "p1", "p2"),
    "ds": ("xi", "alpha"),
}
"""Each family's parameters besides K, in its vector's order (formulas: :mod:`.projections`)."""

DISTORTION_MODELS = tuple(FAMILY_PARAMS)
"""``OpenCVModel.distortion_model``: the standard (rational, tangential, thin-prism, tilt) model,
OpenCV's fisheye (equidistant, Kannala–Brandt), COLMAP's thin-prism fisheye, the f-theta
polynomial, the FOV model, the unified camera model (+ radtan) and the double sphere
(:mod:`clpost.calibration.projections`)."""

FAMILY_TITLES = {"opencv": "OpenCV", "fisheye": "OpenCV fisheye (Kannala–Brandt)",
                 "thinprism": "thin-prism fisheye (COLMAP)", "ftheta": "f-theta polynomial",
                 "fov": "FOV (Devernay–Faugeras)", "ucm": "unified (Mei, + radtan)", "ds": "double sphere"}


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
    xi: float = 0.0
    """UCM / double sphere ξ (dimensionless)."""
    alpha: float = 0.0
    """Double sphere α in [0, 1)."""
    omega: float = 0.0
    """FOV model ω (radians)."""
    inverse: str = "newton"
    """How the stage inverts the model: ``newton`` (exact) or ``heikkila`` (the paper's fit)."""
    distortion_model: str = "opencv"
    """One of :data:`DISTORTION_MODELS`; ``fisheye`` uses k1…k4 only (θ polynomial)."""
    source: str = field(default="", compare=False)
    """Where the model came from (file path), for messages."""

    def __post_init__(self) -> None:
        for n in ("width", "height"):
            v = getattr(self, n)
            if int(v) != v or v < 1:
                raise InputError(f"OpenCVModel.{n}={v!r} must be a whole number of pixels >= 1{self._where()}")
            object.__setattr__(self, n, int(v))
        for f in fields(self):
            if f.name in ("width", "height", "inverse", "source", "distortion_model"):
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
        if self.distortion_model not in DISTORTION_MODELS:
            raise InputError(f"OpenCVModel.distortion_model={self.distortion_model!r} must be one of "
                             f"{', '.join(DISTORTION_MODELS)}{self._where()}")
        extra = [n for n in COEFF_NAMES + ("xi", "alpha", "omega") if n not in self.coeff_names and getattr(self, n)]
        if extra:
            raise InputError(f"OpenCVModel: the {self.distortion_model} model has only "
                             f"{', '.join(self.coeff_names)}; {', '.join(extra)} must be 0{self._where()}")
        if self.distortion_model != "opencv":
            if self.inverse == "heikkila":
                raise InputError(f"OpenCVModel: the Heikkilä inverse is for the standard model, not "
                                 f"{self.distortion_model}; use inverse='newton'{self._where()}")
        if self.distortion_model == "ucm" and self.xi < 0:
            raise InputError(f"OpenCVModel: UCM xi={self.xi} must be >= 0{self._where()}")
        if self.distortion_model == "ds" and not (0 <= self.alpha < 1 and self.xi > -1):
            raise InputError(f"OpenCVModel: double sphere needs 0 <= alpha < 1 and xi > -1, got alpha={self.alpha}, "
                             f"xi={self.xi}{self._where()}")
        if self.distortion_model == "fov" and not (0 <= self.omega < math.pi):
            raise InputError(f"OpenCVModel: FOV omega={self.omega} must be in [0, pi) radians{self._where()}")

    def _where(self) -> str:
        return f" (from {self.source})" if self.source else ""

    # -- construction -----------------------------------------------------------------------
    @staticmethod
    def from_vector(width: int, height: int, k: np.ndarray, d, source: str = "",
                    distortion_model: str = "opencv", **scalars) -> "OpenCVModel":
        """From a 3×3 camera matrix and a distortion vector: OpenCV's 4/5/8/12/14 entries, or the
        family's coefficients (:data:`FAMILY_PARAMS` without the ``scalars`` xi, alpha, omega given
        by name; ``fisheye``: ``cv::fisheye``'s 4)."""
        k = np.asarray(k, dtype=np.float64)
        d = np.asarray(d, dtype=np.float64).reshape(-1)
        where = f" in {source}" if source else ""
        if k.shape != (3, 3):
            raise InputError(f"camera_matrix{where} must be 3×3, got shape {k.shape}")
        if abs(k[0, 1]) > 1e-9 * abs(k[0, 0]) or k[1, 0] or k[2, 0] or k[2, 1] or abs(k[2, 2] - 1) > 1e-12:
            raise InputError(f"camera_matrix{where} must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] "
                             f"(no skew); got {k.tolist()}")
        if distortion_model not in FAMILY_PARAMS:
            raise InputError(f"distortion model {distortion_model!r}{where} must be one of {', '.join(FAMILY_PARAMS)}")
        if distortion_model != "opencv":
            names = [n for n in FAMILY_PARAMS[distortion_model] if n not in ("xi", "alpha", "omega")]
            if d.size != len(names):
                raise InputError(f"distortion_coefficients{where} has {d.size} entries; the {distortion_model} "
                                 f"model has {len(names)} ({', '.join(names) or 'none'})")
            coeffs = dict(zip(names, d.tolist()))
        elif d.size not in (4, 5, 8, 12, 14):
            raise InputError(f"distortion_coefficients{where} has {d.size} entries; OpenCV uses 4, 5, 8, 12 "
                             f"or 14 ({', '.join(COEFF_NAMES)})")
        else:
            coeffs = dict(zip(COEFF_NAMES, d.tolist()))
        return OpenCVModel(width, height, k[0, 0], k[1, 1], k[0, 2], k[1, 2], source=source,
                           distortion_model=distortion_model, **coeffs, **scalars)

    @staticmethod
    def from_camera(camera, size: tuple[int, int], **coeffs) -> "OpenCVModel":
        """The camera's own pinhole intrinsics at ``size`` plus the given coefficients."""
        fx, fy, cx, cy = camera.intrinsics(*size)
        return OpenCVModel(size[0], size[1], fx, fy, cx, cy, **coeffs)

    def vector(self) -> np.ndarray:
        """The 14-entry OpenCV distortion vector (standard model only; see :meth:`coefficients`)."""
        if self.distortion_model != "opencv":
            raise InputError(f"OpenCVModel.vector(): a {self.distortion_model} model has no standard OpenCV vector; "
                             f"use coefficients(){self._where()}")
        return np.array([getattr(self, n) for n in COEFF_NAMES])

    @property
    def is_fisheye(self) -> bool:
        return self.distortion_model == "fisheye"

    @property
    def coeff_names(self) -> tuple[str, ...]:
        """The names of this family's coefficients, in its vector's order (:data:`FAMILY_PARAMS`)."""
        return FAMILY_PARAMS[self.distortion_model]

    def coefficients(self) -> np.ndarray:
        """The family's own distortion vector: 14 OpenCV entries, or fisheye's k1..k4."""
        return np.array([getattr(self, n) for n in self.coeff_names])

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
        """No distortion: the pinhole (every other family's projection is one even with k = 0)."""
        return self.distortion_model == "opencv" and not np.any(self.vector())

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

    def fisheye_scale(self, r: np.ndarray) -> np.ndarray:
        """θ_d(arctan r)/r of the fisheye model (1 at r = 0; ρ(θ) of :mod:`.projections`)."""
        r = np.asarray(r, np.float64)
        th = np.arctan(r)
        safe = np.where(r > 1e-12, r, 1.0)
        return np.where(r > 1e-12, projections._rho(self, th) / safe, 1 + th * th * self.k1)

    @property
    def has_plane_distortion(self) -> bool:
        """Whether D (:meth:`distort_plane`) is more than the identity."""
        fam = self.distortion_model
        return fam in ("opencv", "ucm", "thinprism") and any(getattr(self, n) for n in self.coeff_names
                                                             if n not in ("xi",))

    def distort_plane(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """D: plane coordinates of the family's projection P → distorted plane coordinates
        (float64): OpenCV's standard model (module docstring; for ``ucm`` its radtan k1, k2, p1,
        p2, as Kalibr's ``omni-radtan``), COLMAP's thin-prism polynomial for ``thinprism``
        (radial :math:`1 + k_1 r^2 + k_2 r^4 + k_3 r^6 + k_4 r^8`, the same tangential and
        s1 = sx1, s3 = sy1 terms), the identity for the other families."""
        fam = self.distortion_model
        if fam not in ("opencv", "ucm", "thinprism"):
            return x, y
        r2 = x * x + y * y
        rad = (1 + r2 * (self.k1 + r2 * (self.k2 + r2 * (self.k3 + r2 * self.k4)))) if fam == "thinprism" \
            else self.radial(r2)
        xd = x * rad + 2 * self.p1 * x * y + self.p2 * (r2 + 2 * x * x) + self.s1 * r2 + self.s2 * r2 * r2
        yd = y * rad + self.p1 * (r2 + 2 * y * y) + 2 * self.p2 * x * y + self.s3 * r2 + self.s4 * r2 * r2
        if self.tau_x or self.tau_y:
            t = self._tilt()
            w = t[2, 0] * xd + t[2, 1] * yd + t[2, 2]
            xd, yd = (t[0, 0] * xd + t[0, 1] * yd + t[0, 2]) / w, (t[1, 0] * xd + t[1, 1] * yd + t[1, 2]) / w
        return xd, yd

    def plane_radius(self, rho: np.ndarray) -> np.ndarray:
        """The radial part of D at plane radius ρ (ρ for the families without D)."""
        rho = np.asarray(rho, np.float64)
        if not self.has_plane_distortion:
            return rho
        return self.distort_plane(rho, np.zeros_like(rho))[0] if self.distortion_model == "thinprism" \
            else rho * self.radial(rho * rho)

    def distorted_radius(self, r: np.ndarray) -> np.ndarray:
        """ρ(r): the radial part of the model at undistorted (pinhole) normalised radius r."""
        r = np.asarray(r, np.float64)
        if self.distortion_model == "opencv":
            return r * self.radial(r * r)
        mx, _, ok = projections.project(self, r, np.zeros_like(r), np.ones_like(r))
        return np.where(ok, self.plane_radius(mx), np.nan)

    def distort_normalized(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Undistorted (pinhole) normalised (x', y') → distorted normalised coordinates (float64):
        D(P(x', y', 1)); NaN where the ray (x', y', 1) is outside P's domain."""
        if self.distortion_model == "opencv":
            return self.distort_plane(x, y)
        x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
        mx, my, ok = projections.project(self, x, y, np.ones_like(x))
        xd, yd = self.distort_plane(mx, my)
        return np.where(ok, xd, np.nan), np.where(ok, yd, np.nan)

    def project_rays(self, x: np.ndarray, y: np.ndarray, z: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Camera-frame rays (any length; z forward, y down) → pixels (u, v) and whether the ray
        has an image: inside P's domain and D's monotonic branch. The forward model of every
        family; (0, 0) where invalid."""
        mx, my, ok = projections.project(self, x, y, z)
        if self.has_plane_distortion:
            ok &= np.hypot(mx, my) < self.plane_fold_radius()
        xd, yd = self.distort_plane(mx, my)
        u, v = self.fx * xd + self.cx, self.fy * yd + self.cy
        ok &= np.isfinite(u) & np.isfinite(v)
        return np.where(ok, u, 0.0), np.where(ok, v, 0.0), ok

    def unproject(self, u: np.ndarray, v: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Pixels → unit camera-frame rays (x, y, z) and validity: the exact inverse of
        :meth:`project_rays` (:func:`unproject_plane` for D, then :func:`.projections.unproject`)."""
        if self.distortion_model == "opencv":
            x, y, ok = undistort_newton(self, u, v)
            n = np.sqrt(x * x + y * y + 1)
            return x / n, y / n, 1 / n, ok
        mx, my, ok = unproject_plane(self, u, v)
        x, y, z, ok2 = projections.unproject(self, mx, my)
        ok &= ok2
        return np.where(ok, x, 0.0), np.where(ok, y, 0.0), np.where(ok, z, 1.0), ok

    def project(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Undistorted normalised coordinates → distorted pixel coordinates (u, v)."""
        xd, yd = self.distort_normalized(np.asarray(x, np.float64), np.asarray(y, np.float64))
        return self.fx * xd + self.cx, self.fy * yd + self.cy

    def normalize(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distorted pixel coordinates → distorted normalised coordinates (before untilting)."""
        return (np.asarray(u, np.float64) - self.cx) / self.fx, (np.asarray(v, np.float64) - self.cy) / self.fy

    # -- fold-over ----------------------------------------------------------------------------
    def fold_radius(self, r_max: float = 20.0, n: int = 200001) -> float:
        r"""First undistorted radius r (normalised) where :math:`\rho(r)` (:meth:`distorted_radius`)
        stops increasing or the denominator of R reaches 0; ``inf`` if none up to ``r_max``."""
        return _first_fold(self.distorted_radius, self.distortion_model == "opencv" and self._den, r_max, n)

    def _den(self, r2: np.ndarray) -> np.ndarray:
        return 1 + r2 * (self.k4 + r2 * (self.k5 + r2 * self.k6))

    def plane_fold_radius(self) -> float:
        """:meth:`fold_radius` of D alone, in plane coordinates (inf for the families without D)."""
        if not self.has_plane_distortion:
            return math.inf
        if self.distortion_model == "opencv":
            return self.fold_radius()
        return _fold_cached(self)

    def fold_distorted_radius(self) -> float:
        """ρ(r_fold): the largest distorted radius the monotonic branch reaches (inf if none)."""
        rf = self.fold_radius()
        if math.isinf(rf):
            return math.inf
        return float(self.distorted_radius(np.array(rf)))


def _first_fold(rho_fn, den_fn, r_max: float, n: int) -> float:
    r = np.linspace(0.0, r_max, n)
    den = den_fn(r * r) if den_fn else np.ones_like(r)
    with np.errstate(all="ignore"):
        rho = rho_fn(np.where(den > 0, r, 0.0))
        bad = (den <= 0)[1:] | ~(np.diff(rho) > 0)
    if not bad.any():
        return math.inf
    return float(r[int(np.argmax(bad))])


@lru_cache(maxsize=64)
def _fold_cached(model: OpenCVModel) -> float:
    return _first_fold(model.plane_radius, None, 20.0, 200001)


# ---------------------------------------------------------------------------------------------
# Inverses
# ---------------------------------------------------------------------------------------------


def _newton_solve(model: OpenCVModel, fn, u, v, tol_px: float, max_iter: int):
    r"""Newton iteration :math:`x_{k+1} = x_k - J^{-1}(F(x_k) - p)` on ``fn`` (normalised
    coordinates → pixels) started from the normalised target p, J by central differences
    (h = 1e-7), steps limited to 0.5 normalised units so a strong model cannot jump across the
    fold. Returns (x, y, residual px)."""
    u = np.asarray(u, np.float64)
    v = np.asarray(v, np.float64)
    x, y = model.normalize(u, v)
    x, y = x.copy(), y.copy()
    h = 1e-7
    with np.errstate(all="ignore"):
        for _ in range(max_iter):
            pu, pv = fn(x, y)
            eu, ev = pu - u, pv - v
            done = np.hypot(eu, ev) < tol_px
            if done.all():
                break
            a, c = fn(x + h, y)
            b, d = fn(x - h, y)
            j11, j21 = (a - b) / (2 * h), (c - d) / (2 * h)
            a, c = fn(x, y + h)
            b, d = fn(x, y - h)
            j12, j22 = (a - b) / (2 * h), (c - d) / (2 * h)
            det = j11 * j22 - j12 * j21
            dx = (j22 * eu - j12 * ev) / det
            dy = (-j21 * eu + j11 * ev) / det
            step = np.hypot(dx, dy)
            scale = np.where(step > 0.5, 0.5 / np.maximum(step, 1e-300), 1.0)
            upd = ~done & np.isfinite(dx) & np.isfinite(dy)
            x = np.where(upd, x - scale * dx, x)
            y = np.where(upd, y - scale * dy, y)
        pu, pv = fn(x, y)
        err = np.hypot(pu - u, pv - v)
    return x, y, err


def undistort_newton(model: OpenCVModel, u: np.ndarray, v: np.ndarray, tol_px: float = 1e-6,
                     max_iter: int = 60) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""Exact inverse: distorted pixels (u, v) → undistorted (pinhole) normalised (x', y') and a
    validity mask.

    Standard model: Newton (:func:`_newton_solve`) on the full model in pixel units. Valid ⇔
    converged to ``tol_px`` within ``max_iter`` iterations, finite, and inside the monotonic
    branch (r < r_fold). Other families: :meth:`OpenCVModel.unproject`'s ray (x, y, z) as
    (x/z, y/z), valid where z > 0 (a ray at or beyond 90° has no pinhole image).
    """
    if model.distortion_model != "opencv":
        x, y, z, ok = model.unproject(u, v)
        ok = ok & (z > 1e-9)
        zs = np.where(ok, z, 1.0)
        return np.where(ok, x / zs, 0.0), np.where(ok, y / zs, 0.0), ok
    x, y, err = _newton_solve(model, model.project, u, v, tol_px, max_iter)
    valid = (err < tol_px) & np.isfinite(x) & np.isfinite(y) & (np.hypot(x, y) < model.fold_radius())
    return np.where(valid, x, 0.0), np.where(valid, y, 0.0), valid


def unproject_plane(model: OpenCVModel, u: np.ndarray, v: np.ndarray, tol_px: float = 1e-6,
                    max_iter: int = 60) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels → plane coordinates of the family's projection P: the inverse of K·D
    (:meth:`OpenCVModel.distort_plane`; Newton as :func:`undistort_newton` where D is not the
    identity, valid inside D's monotonic branch)."""
    if not model.has_plane_distortion:
        x, y = model.normalize(u, v)
        return x, y, np.ones(x.shape, bool)

    def fn(x, y):
        xd, yd = model.distort_plane(x, y)
        return model.fx * xd + model.cx, model.fy * yd + model.cy

    x, y, err = _newton_solve(model, fn, u, v, tol_px, max_iter)
    valid = (err < tol_px) & np.isfinite(x) & np.isfinite(y) & (np.hypot(x, y) < model.plane_fold_radius())
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
