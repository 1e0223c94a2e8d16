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
Levenberg–Marquardt with the analytic Jacobian, all corners of an image at once (numpy batches of
10×10 normal equations rather than one ``scipy.optimize.least_squares`` per corner; cost in
docs/distortion_calibration.md).

Why not ``cv2.cornerSubPix``: it solves for the point to which every image gradient in the
window is orthogonal, which is exact for two straight ideal edges but biased by blur near the
crossing when the lines are not perpendicular (perspective), by the discrete gradient, and by
bent lines: 0.012–0.027 px RMS on exact synthetic corners (tests/test_corner_refine.py), 0.014
px on the Gaussian-filtered board renders of :mod:`clpost.calib_check.checkerboard`, where this fit is
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
from scipy.special import erf

_TWO_OVER_SQRT_PI = 2.0 / math.sqrt(math.pi)
NPARAM = 10
"""(c_x, c_y, θ₁, θ₂, ln u₁, ln u₂, κ₁, κ₂, a, b)"""


def saddle(params: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The model :math:`I(\\mathbf p)` of the module docstring with ``params`` (10,) at points
    (x, y) (px, any equal shapes)."""
    x = np.asarray(x, dtype=np.float64)
    return _model(np.asarray(params, dtype=np.float64)[None], x.reshape(1, -1),
                  np.asarray(y, dtype=np.float64).reshape(1, -1))[0].reshape(x.shape)


def _model(params, x, y):
    """Batched model: ``params`` (N, 10), x, y (N, M) → (values (N, M), per-line terms)."""
    cx, cy, t1, t2, lu1, lu2, k1, k2, a, b = (params[:, i:i + 1] for i in range(NPARAM))
    dx, dy = x - cx, y - cy
    out = []
    for th, lu, k in ((t1, lu1, k1), (t2, lu2, k2)):
        c, s = np.cos(th), np.sin(th)
        nd = c * dx + s * dy  # n·d
        td = -s * dx + c * dy  # t·d
        l = nd + k * td * td
        # LM may try absurd steps on a window without a corner; keep exp finite (such fits fail)
        u = np.exp(np.clip(lu, -30.0, 30.0))
        z = u * l
        out.append((c, s, nd, td, l, u, erf(z), _TWO_OVER_SQRT_PI * np.exp(-z * z), k))  # erf, erf'
    return a + b * out[0][6] * out[1][6], out


def _jacobian(params, x, y):
    """∂ model / ∂ params, (N, M, 10) for ``params`` (N, 10) (also (10,) with x, y (M,): (M, 10))."""
    single = np.ndim(params) == 1
    if single:
        params, x, y = np.asarray(params)[None], np.asarray(x)[None], np.asarray(y)[None]
    b = params[:, 9:10]
    _, out = _model(params, x, y)
    jac = np.zeros(x.shape + (NPARAM,))
    for i, (c, s, nd, td, l, u, e, g, k) in enumerate(out):
        other = out[1 - i][6]
        de_dl = b * other * g * u  # ∂I/∂l_i
        # ∂l/∂c = −n − 2κ (t·d) t ;  ∂l/∂θ = t·d − 2κ (t·d)(n·d) ;  ∂l/∂κ = (t·d)²
        jac[..., 0] += de_dl * (-c + 2.0 * k * td * s)
        jac[..., 1] += de_dl * (-s - 2.0 * k * td * c)
        jac[..., 2 + i] = de_dl * (td - 2.0 * k * td * nd)
        jac[..., 4 + i] = b * other * g * l * u  # ∂/∂ ln u
        jac[..., 6 + i] = de_dl * td * td
    jac[..., 8] = 1.0
    jac[..., 9] = out[0][6] * out[1][6]
    return jac[0] if single else jac


def _levenberg_marquardt(p, x, y, v, w, free, iters: int = 200):
    """Minimise Σ w (model − v)² per row of ``p`` (N, 10) (Levenberg–Marquardt with Marquardt's
    diagonal scaling, a damping per corner); ``free`` (10,) masks the fitted parameters.
    Returns (params, cost, converged)."""
    def cost_of(q, i):
        r = _model(q, x[i], y[i])[0] - v[i]
        return np.sum(w[i] * r * r, axis=1), r

    cost, r = cost_of(p, slice(None))
    lam = np.full(len(p), 1e-3)
    done = np.zeros(len(p), bool)
    eye = np.eye(NPARAM)
    for _ in range(iters):
        act = np.flatnonzero(~done)
        if act.size == 0:
            break
        jac = _jacobian(p[act], x[act], y[act]) * free
        jw = jac * w[act][..., None]
        a = np.einsum("nmi,nmj->nij", jw, jac)
        g = np.einsum("nmi,nm->ni", jw, r[act])
        diag = np.maximum(np.einsum("nii->ni", a), 1e-12)
        # fixed parameters: zero column → a unit row keeps their step at 0
        lhs = a + (lam[act, None] * diag)[..., None] * eye + (~free)[:, None] * eye
        step = -np.linalg.solve(lhs, g[..., None])[..., 0]
        q = p[act] + step
        c_new, r_new = cost_of(q, act)
        ok = np.isfinite(c_new) & (c_new <= cost[act])
        i_ok = act[ok]
        # every parameter, not only the position: a corner on a pixel centre can sit still while θ moves
        small = np.abs(step[ok]).max(axis=1) < 1e-10
        flat = (cost[i_ok] - c_new[ok]) <= 1e-15 * np.maximum(cost[i_ok], 1e-300)
        p[i_ok], cost[i_ok], r[i_ok] = q[ok], c_new[ok], r_new[ok]
        lam[i_ok] = np.maximum(lam[i_ok] / 3.0, 1e-12)
        done[i_ok[small | flat]] = True
        i_bad = act[~ok]
        lam[i_bad] *= 4.0
        done[i_bad[lam[i_bad] > 1e12]] = True  # no descent left at any step length: a minimum
    return p, cost, done


def refine_corners(image: np.ndarray, corners, dir1, dir2, half: int = 7, curved: bool = True,
                   sigma: float | None = None) -> tuple[np.ndarray, dict]:
    """Fit the saddle model to ``image`` (H×W float, any scale) in the (2·half+1)² window of
    pixel centres around each rounded corner of ``corners`` (N×2, x, y px); pixels outside the
    image are left out of the fit.

    ``dir1``, ``dir2`` (N×2): approximate image directions of the two board lines through each
    corner (e.g. towards the next corners of its row and column; only their angles are used, to
    ±30°). ``curved`` fits the line curvatures κ (else straight lines). ``sigma`` (px): Gaussian
    weight of the residuals about the initial corner (None: uniform).
    Returns the corners (N×2) and a dict: ``params`` (N×10), ``rms`` (residual RMS relative to
    |b|), ``ok`` (the fit converged, stayed within 1.5 px of the start, kept distinct lines
    (> 11.5° apart), found a saddle of at least half the window's contrast and fits it to 20 %
    of |b|).
    """
    image = np.asarray(image, dtype=np.float64)
    h, w = image.shape
    c0 = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    n = len(c0)
    off = np.arange(-half, half + 1, dtype=np.float64)
    oy, ox = (t.ravel() for t in np.meshgrid(off, off, indexing="ij"))
    ix, iy = np.rint(c0[:, 0]), np.rint(c0[:, 1])
    x, y = ix[:, None] + ox[None], iy[:, None] + oy[None]
    inside = (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)
    v = image[np.clip(y, 0, h - 1).astype(np.int64), np.clip(x, 0, w - 1).astype(np.int64)]
    wgt = inside.astype(np.float64)
    if sigma is not None:
        wgt *= np.exp(-0.5 * ((x - c0[:, :1]) ** 2 + (y - c0[:, 1:]) ** 2) / sigma**2)
    d1, d2 = np.asarray(dir1, dtype=np.float64).reshape(-1, 2), np.asarray(dir2, dtype=np.float64).reshape(-1, 2)
    p = np.zeros((n, NPARAM))
    p[:, :2] = c0
    # the lines' normals are perpendicular to their directions
    p[:, 2] = np.arctan2(d1[:, 1], d1[:, 0]) + 0.5 * np.pi
    p[:, 3] = np.arctan2(d2[:, 1], d2[:, 0]) + 0.5 * np.pi
    # a, b by weighted linear least squares at the initial geometry (steps of 1 px, u = 1)
    p[:, 9] = 1.0
    _, out = _model(p, x, y)
    e = out[0][6] * out[1][6]
    s0, s1, s2 = wgt.sum(1), (wgt * e).sum(1), (wgt * e * e).sum(1)
    t0, t1 = (wgt * v).sum(1), (wgt * e * v).sum(1)
    det = np.where(np.abs(s0 * s2 - s1 * s1) > 1e-300, s0 * s2 - s1 * s1, 1.0)
    p[:, 8], p[:, 9] = (s2 * t0 - s1 * t1) / det, (s0 * t1 - s1 * t0) / det
    free = np.ones(NPARAM, bool)
    if not curved:
        free[6:8] = False
    p, cost, converged = _levenberg_marquardt(p, x, y, v, wgt, free)
    out_c = p[:, :2].copy()
    rms = np.sqrt(cost / np.maximum(wgt.sum(1), 1e-300)) / np.maximum(np.abs(p[:, 9]), 1e-12)
    sep = np.abs(np.sin(p[:, 2] - p[:, 3]))
    # a saddle spans 2|b| (erf ∈ [−1, 1]); a flat or edge-only window leaves b, c undetermined
    vin = np.where(inside, v, np.nan)
    contrast = np.nanmax(vin, axis=1) - np.nanmin(vin, axis=1)
    ok = (converged & np.isfinite(p).all(axis=1) & (np.hypot(*(out_c - c0).T) < 1.5) & (sep > 0.2)
          & (contrast > 0) & (np.abs(p[:, 9]) > 0.25 * contrast) & (rms < 0.2))
    return out_c, {"params": p, "rms": rms, "ok": ok}


def refine_corner(image: np.ndarray, corner, dir1, dir2, half: int = 7, curved: bool = True,
                  sigma: float | None = None) -> tuple[np.ndarray, dict]:
    """:func:`refine_corners` for one corner: (x, y) and the dict with scalars."""
    c, info = refine_corners(image, np.reshape(corner, (1, 2)), np.reshape(dir1, (1, 2)),
                             np.reshape(dir2, (1, 2)), half, curved, sigma)
    return c[0], {k: (bool(v[0]) if k == "ok" else v[0]) for k, v in info.items()}


def grid_directions(corners: np.ndarray, pattern: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Per corner of a (cols, rows) grid in OpenCV's row-major order: the direction along its row
    and along its column (central differences of the neighbours, one-sided at the ends)."""
    g = np.asarray(corners, dtype=np.float64).reshape(pattern[1], pattern[0], 2)
    return (np.gradient(g, axis=1).reshape(-1, 2), np.gradient(g, axis=0).reshape(-1, 2))


def refine_grid(image: np.ndarray, corners: np.ndarray, pattern: tuple[int, int], half: int = 7,
                curved: bool = True, sigma: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`refine_corners` for every corner of a detected grid (N×2, OpenCV's order).
    Returns the refined corners (N×2) and a flag per corner (False: the fit failed and the input
    corner is kept)."""
    rows, cols = grid_directions(corners, pattern)
    start = np.array(corners, dtype=np.float64).reshape(-1, 2)
    fit, info = refine_corners(image, start, rows, cols, half, curved, sigma)
    return np.where(info["ok"][:, None], fit, start), info["ok"]
