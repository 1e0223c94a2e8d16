r"""Sub-pixel checkerboard corners by a least-squares fit of a blurred-saddle model.

Each inner corner of a checkerboard is the crossing of two board lines. Box-filtering a checker
in board coordinates keeps it separable (:math:`\tfrac12 + \tfrac12 F(x) F(y)` with F the
filtered square wave), and an affine map (a homography over a few pixels) keeps that form with
x, y replaced by signed distances to the two image lines. So, in a window around the corner,

.. math::

    I(\mathbf p) = a + b\,\operatorname{erf}(u_1 l_1)\,\operatorname{erf}(u_2 l_2), \qquad
    l_i = \mathbf n_i\cdot(\mathbf p - \mathbf c) + \kappa_i\,(\mathbf t_i\cdot(\mathbf p - \mathbf c))^2

with :math:`\mathbf n_i = (\cos\theta_i, \sin\theta_i)`, :math:`\mathbf t_i = (-\sin\theta_i,
\cos\theta_i)`: the lines through the corner :math:`\mathbf c`, bent by a curvature
:math:`\kappa_i` (lens distortion bends board lines; a bend that is symmetric about the corner
does not move it), blurred by a step of width :math:`1/u_i` px. Ten parameters
:math:`(c_x, c_y, \theta_1, \theta_2, \ln u_1, \ln u_2, \kappa_1, \kappa_2, a, b)` are fitted to
the pixel values at the pixel centres (OpenCV convention: pixel (i, j) is centred at (i, j)) by
Levenberg–Marquardt with the analytic Jacobian.

Why not ``cv2.cornerSubPix``: it solves for the point to which every image gradient in the
window is orthogonal, which is exact for two straight ideal edges but biased by blur near the
crossing when the lines are not perpendicular (perspective), by the discrete gradient, and by
bent lines: 0.012–0.027 px RMS on exact synthetic corners (tests/test_corner_refine.py), 0.014
px on the Gaussian-filtered board renders of tools/distortion_calibration.py, where this fit is
at 0.0004 px.

Where it is exact, and where not (measured): exact (to the solver's tolerance) when the blur is
a Gaussian separable along the board's axes, as ``Material.board_blur`` renders it, also seen
through an affine map; near-exact with bent lines (2.7e-4 px RMS at 0.06 px of bow over the
window). Approximate when the blur is isotropic in the image and the corner is skewed (the
product form is then wrong: 0.004 px RMS, 0.02 px at the most acute corners), and when edges
are undersampled (the renderer's ≈ 1-px box filter: 0.042 px RMS, worse than cornerSubPix,
because an erf fitted to a few samples of a ramp depends on the ramp's sub-pixel phase).

References: Lucchese & Mitra, "Using saddle points for subpixel feature detection in camera
calibration targets", APCCAS 2002 (saddle fits); Placht et al., "ROCHADE: Robust Checkerboard
Advanced Detection for Camera Calibration", ECCV 2014 (model fits beat gradient methods).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares

_TWO_OVER_SQRT_PI = 2.0 / math.sqrt(math.pi)


def saddle(params: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The model :math:`I(\\mathbf p)` of the module docstring at points (x, y) (px)."""
    return _model(params, x, y)[0]


def _model(params, x, y):
    cx, cy, t1, t2, lu1, lu2, k1, k2, a, b = params
    dx, dy = x - cx, y - cy
    out = []
    for th, lu, k in ((t1, lu1, k1), (t2, lu2, k2)):
        c, s = math.cos(th), math.sin(th)
        nd = c * dx + s * dy  # n·d
        td = -s * dx + c * dy  # t·d
        l = nd + k * td * td
        # LM may try absurd steps on a window without a corner; keep exp finite (such fits fail)
        u = math.exp(min(max(lu, -30.0), 30.0))
        e = _erf(u * l)
        g = _TWO_OVER_SQRT_PI * np.exp(-(u * l) ** 2)  # erf'(u l)
        out.append((c, s, nd, td, l, u, e, g, k))
    (c1, s1, nd1, td1, l1, u1, e1, g1, k1_), (c2, s2, nd2, td2, l2, u2, e2, g2, k2_) = out
    return a + b * e1 * e2, out


def _erf(z):
    from scipy.special import erf

    return erf(z)


def _jacobian(params, x, y):
    a, b = params[8], params[9]
    _, out = _model(params, x, y)
    jac = np.empty((x.size, 10))
    for i, (c, s, nd, td, l, u, e, g, k) in enumerate(out):
        other = out[1 - i][6]
        de_dl = b * other * g * u  # ∂I/∂l_i
        # ∂l/∂c = −n − 2κ (t·d) t ;  ∂l/∂θ = t·d − 2κ (t·d)(n·d) ;  ∂l/∂κ = (t·d)²
        jac[:, 0] = (jac[:, 0] if i else 0.0) + de_dl * (-c + 2.0 * k * td * s)
        jac[:, 1] = (jac[:, 1] if i else 0.0) + de_dl * (-s - 2.0 * k * td * c)
        jac[:, 2 + i] = de_dl * (td - 2.0 * k * td * nd)
        jac[:, 4 + i] = b * other * g * l * u  # ∂/∂ ln u
        jac[:, 6 + i] = de_dl * td * td
    jac[:, 8] = 1.0
    jac[:, 9] = out[0][6] * out[1][6]
    return jac


def refine_corner(image: np.ndarray, corner, dir1, dir2, half: int = 7, curved: bool = True,
                  sigma: float | None = None) -> tuple[np.ndarray, dict]:
    """Fit the saddle model to ``image`` (H×W float, any scale) in the (2·half+1)² window of
    pixel centres around the rounded ``corner`` (x, y px).

    ``dir1``, ``dir2``: approximate image directions of the two board lines through the corner
    (e.g. towards the next corners of its row and column; only their angles are used, to ±30°).
    ``curved`` fits the line curvatures κ (else straight lines). ``sigma`` (px): Gaussian weight
    of the residuals about the initial corner (None: uniform).
    Returns the corner (x, y) and a dict: ``params``, ``rms`` (residual RMS relative to |b|),
    ``ok`` (the fit converged, stayed within 1.5 px of the start, kept distinct lines (> 11.5°
    apart), found a saddle of at least half the window's contrast and fits it to 20 % of |b|).
    """
    image = np.asarray(image, dtype=np.float64)
    h, w = image.shape
    c0 = np.asarray(corner, dtype=np.float64)
    ix, iy = int(round(c0[0])), int(round(c0[1]))
    x0, x1 = max(ix - half, 0), min(ix + half + 1, w)
    y0, y1 = max(iy - half, 0), min(iy + half + 1, h)
    yy, xx = np.mgrid[y0:y1, x0:x1].astype(np.float64)
    x, y, v = xx.ravel(), yy.ravel(), image[y0:y1, x0:x1].ravel()
    # the lines' normals are perpendicular to their directions
    th1 = math.atan2(dir1[1], dir1[0]) + 0.5 * math.pi
    th2 = math.atan2(dir2[1], dir2[0]) + 0.5 * math.pi
    # a, b by linear least squares at the initial geometry (sharp-ish steps, u = 1/px)
    p = np.array([c0[0], c0[1], th1, th2, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    e12 = _model(p, x, y)[1]
    basis = np.c_[np.ones_like(x), e12[0][6] * e12[1][6]]
    p[8:10] = np.linalg.lstsq(basis, v, rcond=None)[0]
    wgt = np.ones_like(x) if sigma is None else np.exp(-0.5 * ((x - c0[0]) ** 2 + (y - c0[1]) ** 2) / sigma**2)
    sw = np.sqrt(wgt)
    free = np.ones(10, bool)
    if not curved:
        free[6:8] = False

    def fun(q):
        pp = p.copy()
        pp[free] = q
        return sw * (_model(pp, x, y)[0] - v)

    def jac(q):
        pp = p.copy()
        pp[free] = q
        return (sw[:, None] * _jacobian(pp, x, y))[:, free]

    res = least_squares(fun, p[free], jac=jac, method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=200)
    q = p.copy()
    q[free] = res.x
    corner_out = q[:2].copy()
    sep = abs(math.sin(q[2] - q[3]))
    rms = float(np.sqrt(np.mean((res.fun / sw) ** 2)) / max(abs(q[9]), 1e-12))
    # a saddle spans 2|b| (erf ∈ [−1, 1]); a flat or edge-only window leaves b, c undetermined
    contrast = float(v.max() - v.min())
    ok = bool(res.status > 0 and np.hypot(*(corner_out - c0)) < 1.5 and sep > 0.2 and contrast > 0
              and abs(q[9]) > 0.25 * contrast and rms < 0.2 and np.isfinite(q).all())
    return corner_out, {"params": q, "rms": rms, "ok": ok, "nfev": res.nfev}


def grid_directions(corners: np.ndarray, pattern: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Per corner of a (cols, rows) grid in OpenCV's row-major order: the direction along its row
    and along its column (central differences of the neighbours, one-sided at the ends)."""
    g = np.asarray(corners, dtype=np.float64).reshape(pattern[1], pattern[0], 2)
    return (np.gradient(g, axis=1).reshape(-1, 2), np.gradient(g, axis=0).reshape(-1, 2))


def refine_grid(image: np.ndarray, corners: np.ndarray, pattern: tuple[int, int], half: int = 7,
                curved: bool = True, sigma: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`refine_corner` for every corner of a detected grid (N×2, OpenCV's order).
    Returns the refined corners (N×2) and a flag per corner (False: the fit failed and the input
    corner is kept)."""
    rows, cols = grid_directions(corners, pattern)
    out = np.array(corners, dtype=np.float64).reshape(-1, 2)
    ok = np.zeros(len(out), bool)
    for k in range(len(out)):
        c, info = refine_corner(image, out[k], rows[k], cols[k], half, curved, sigma)
        if info["ok"]:
            out[k], ok[k] = c, True
    return out, ok
