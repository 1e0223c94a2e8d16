"""Verify the distortion stage as Lambers, Sommerhoff & Kolb did: render checkerboards, distort
them with known OpenCV parameters, calibrate with OpenCV, compare.

For each parameter set (barrel, pincushion, tangential): N views of a 14×10-square board
(13×9 inner corners) in 17 deterministic poses (:data:`VIEWS`: 40° tilts, the board as large as
fits, pushed into every image corner and edge) are rendered by the pyvista renderer at the
extended frustum of :func:`clpost.calibration.required_render` (no unfilled pixels), distorted by
the clpost pipeline (``--stages distortion``, final = cubic B-spline interpolation), and fed to
``cv2.findChessboardCorners`` + ``cornerSubPix`` + ``cv2.calibrateCamera`` (k3 fixed at 0, as
the paper). The board is anti-aliased by a Gaussian of :data:`BOARD_BLUR` px (an optical low-pass;
``Material.board_blur``) and the corners are refined by a blurred-saddle least-squares fit
(:mod:`clpost.calib_check.corner_refine`; ``--detector subpix`` keeps OpenCV's ``cornerSubPix``): on the
undistorted renders this pair is exact to ≈ 2e-4 px, so what remains is the stage's. The error
sources are separated: detected corners vs the analytic projection of the
true model (:func:`detection_error`), and the conditioning floor of the pose set at that
detection accuracy (:func:`conditioning_floor`: true corners + Gaussian noise). Also reports the
residuals of both inverses and the round trip distort → ``cv2.undistort`` vs a direct render.
``--what-if spline3`` also resamples the same renders through the stage's own map
(:func:`clpost.stages.distortion.distortion_map`) with another interpolator in numpy (``spline3``:
cubic B-spline with its prefilter, ``keys-0.5``, ``bilinear``, ``lanczos3``) to show what the
stage would reach with it. Results: docs/distortion_calibration.md. The report is printed by

    PYTHONPATH=. python tools/distortion_calibration.py --views 17 --size 800x600 --png /tmp/distortion_check

(needs OpenCV: ``pip install '.[test]'``); ``tests/test_distortion.py`` runs the hardest set.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .. import Camera, Frame, Pipeline
from ..calibration import OpenCVModel, required_render, undistort_newton
from ..render import DemoScene, PyVistaRenderer
from ..render.demo_scene import Material, Plane, RigidMotion, SceneObject

from .corner_refine import refine_grid

SQUARES = (14, 10)
SQUARE_M = 0.035
PATTERN = (SQUARES[0] - 1, SQUARES[1] - 1)


def parameter_sets(size: tuple[int, int]) -> dict[str, OpenCVModel]:
    w, h = size
    s = w / 800.0
    base = dict(width=w, height=h, fx=820.0 * s, fy=815.0 * s, cx=405.3 * s, cy=296.8 * s)
    return {
        "barrel": OpenCVModel(**base, k1=-0.25, k2=0.08),
        "pincushion": OpenCVModel(**base, k1=0.2, k2=0.05),
        "tangential": OpenCVModel(**base, k1=-0.1, k2=0.02, p1=0.004, p2=-0.003),
    }


# The 17 deterministic views: (tilt axis in the image plane, tilt °, roll °, board centre as a
# fraction of the image). Zhang (2000, sec. 5) finds ~45° tilts best and the distortion terms need
# corners out to the image edges: every view puts the board as close as it can be with its outline
# (plus half a square of margin) inside the image, so the 8 "fill" views cover the whole frame
# under tilts about 8 axis directions and the 8 others push a tilted board into each image corner
# and edge midpoint (r⁴, p1 and p2 are weighed by the image corners). Interleaved so that any
# prefix (the test uses 8) is balanced.
TILT_DEG = 40.0
_FILL = [((math.cos(math.pi * k / 4), math.sin(math.pi * k / 4)), TILT_DEG, 10.0 * (k % 3 - 1), (0.5, 0.5))
         for k in range(8)]
_PUSH = []
for _k, (_fu, _fv) in enumerate([(0.25, 0.25), (0.75, 0.25), (0.75, 0.75), (0.25, 0.75),
                                 (0.5, 0.25), (0.75, 0.5), (0.5, 0.75), (0.25, 0.5)]):
    _PUSH.append(((0.5 - _fv, _fu - 0.5), TILT_DEG * (1 if _k % 2 else -1), 20.0 if _k < 4 else -20.0, (_fu, _fv)))
VIEWS = [v for pair in zip([_FILL[k] for k in (0, 2, 4, 6, 1, 3, 5, 7)], _PUSH) for v in pair] + [((1.0, 0.0), 0.0, 0.0, (0.5, 0.5))]


def _rotation(axis, angle: float) -> np.ndarray:
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def board_pose(view: int, model: OpenCVModel, margin_px: float = 6.0) -> tuple[np.ndarray, np.ndarray]:
    """Board → camera (R, t) of view ``view`` (mod 17): the board faces the camera, rolled and
    tilted as :data:`VIEWS` says, its centre on the ray through the target pixel, at the smallest
    distance (bisection) at which its outline, distorted by ``model``, stays ``margin_px`` inside."""
    axis, tilt, roll, (fu, fv) = VIEWS[view % len(VIEWS)]
    r = _rotation((0, 0, 1), math.radians(roll))
    if tilt:
        r = _rotation((axis[0], axis[1], 0.0), math.radians(tilt)) @ r
    r = r @ np.diag([1.0, -1.0, -1.0])  # board normal (+z) towards the camera
    x, y, ok = undistort_newton(model, np.array([fu * (model.width - 1)]), np.array([fv * (model.height - 1)]))
    ray = np.array([x[0], y[0], 1.0])
    hx, hy = (0.5 * SQUARES[0] + 0.5) * SQUARE_M, (0.5 * SQUARES[1] + 0.5) * SQUARE_M
    t = np.linspace(-1, 1, 21)
    # the edges bow under distortion: sample them, not only the 4 corners
    outline = np.concatenate([np.c_[t * hx, np.full(21, s * hy)] for s in (-1, 1)]
                             + [np.c_[np.full(21, s * hx), t * hy] for s in (-1, 1)])
    outline = np.c_[outline, np.zeros(len(outline))] @ r.T

    def fits(z: float) -> bool:
        p = outline + z * ray
        if (p[:, 2] < 0.05).any():
            return False
        u, v = model.project(p[:, 0] / p[:, 2], p[:, 1] / p[:, 2])
        return bool(u.min() > margin_px and v.min() > margin_px and u.max() < model.width - 1 - margin_px
                    and v.max() < model.height - 1 - margin_px)

    lo, hi = 0.05, 50.0
    if not (ok[0] and fits(hi)):
        raise ValueError(f"view {view}: no board distance fits the image")
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if fits(mid) else (mid, hi)
    return r, hi * ray


BOARD_BLUR = 1.0
"""σ of the board's Gaussian anti-aliasing in pixel footprints (``Material.board_blur``). The box
filter (0) leaves edges ≈ 1 px wide, undersampled: fits and cornerSubPix then depend on where a
corner falls within its pixel (0.035–0.04 px RMS on the undistorted render); at 1.0 the saddle
fit is exact to ≈ 2e-4 px there (measured, docs/distortion_calibration.md)."""


def board_scene(view: int, n_views: int, model: OpenCVModel | None = None, blur: float = BOARD_BLUR) -> DemoScene:
    """The board in the world xy plane (z up, world = board frame) seen from view ``view`` (see
    :func:`board_pose`; ``n_views`` is accepted for the caller's loop and not needed). Without
    ``model`` (callers that only need the objects to build a renderer) the 800×600 barrel set
    places the board."""
    model = model or parameter_sets((800, 600))["barrel"]
    board = SceneObject("board", Plane(0.36), Material(albedo=(0.9, 0.9, 0.9), albedo2=(0.04, 0.04, 0.04),
                                                       texture="board", texture_scale_m=SQUARE_M,
                                                       board_squares=SQUARES, board_blur=blur), casts_shadow=False)
    r, t = board_pose(view, model)
    # camera → world: rotation Rᵀ (columns right, down, forward), centre −Rᵀ t
    cam = RigidMotion(position_m=tuple(-r.T @ t), base_rotation=tuple(tuple(row) for row in r.T))
    return DemoScene(objects=(board,), camera_motion=cam, sun_direction=(0.0, 0.0, 1.0), sun_irradiance=1.0,
                     ambient=0.3, emitter_lighting=False)


def board_points() -> np.ndarray:
    """The 13×9 inner corners in the board frame (metres, z = 0), row-major from (−6, −4) squares."""
    gx, gy = np.meshgrid((np.arange(PATTERN[0]) - (PATTERN[0] - 1) / 2) * SQUARE_M,
                         (np.arange(PATTERN[1]) - (PATTERN[1] - 1) / 2) * SQUARE_M)
    return np.c_[gx.ravel(), gy.ravel(), np.zeros(gx.size)]


def true_corners(model: OpenCVModel, view: int, camera: OpenCVModel | None = None) -> np.ndarray:
    """The inner corners of view ``view`` (posed for ``model``) projected by ``camera`` (default
    the true model) (N×2 px): ground truth."""
    r, t = board_pose(view, model)
    p = board_points() @ r.T + t
    u, v = (camera or model).project(p[:, 0] / p[:, 2], p[:, 1] / p[:, 2])
    return np.c_[u, v]


def render_views(model: OpenCVModel, n_views: int, supersample: int = 1, blur: float = BOARD_BLUR):
    """(undistorted renders at the extended frustum, distorted outputs) for ``n_views`` poses."""
    spec = required_render(model)
    cam = Camera(distortion=model)
    pipe = Pipeline(cam, quality="final", stages=["distortion"])
    renderer = PyVistaRenderer(board_scene(0, n_views, model, blur), supersample=supersample)
    raw, out = [], []
    try:
        for v in range(n_views):
            # the VTK actors depend only on the objects, identical in every view: swap the scene
            renderer.scene = board_scene(v, n_views, model, blur)
            f = renderer.render(cam, (spec.width, spec.height), 0, spec.intrinsics())
            raw.append(f)
            out.append(pipe.run(f))
    finally:
        renderer.close()
    return raw, out


def to_gray8(color: np.ndarray) -> np.ndarray:
    y = color @ np.array([0.2126, 0.7152, 0.0722])
    return np.clip(np.rint(y / max(float(y.max()), 1e-6) * 255), 0, 255).astype(np.uint8)


SUBPIX_WINDOW = (7, 7)
"""cornerSubPix half-window: 15×15 px, the most accurate of the half-windows tried on the
undistorted renders (squares are 25–60 px; the errors of 7, 5, 3 and of findChessboardCornersSB:
docs/distortion_calibration.md)."""
CALIB_FLAGS_DOC = "CALIB_FIX_K3 (the generating model has k3 = 0; k4–k6, s1–s4, τ are off by default)"


DETECTORS = ("fit", "subpix")


def detect_corners(frame, detector: str = "fit") -> np.ndarray | None:
    """Inner corners (N×2 px, OpenCV's order) of ``frame``: ``findChessboardCorners`` on 8 bits,
    then ``cornerSubPix`` on the float luminance (no quantisation in the sub-pixel fit), then
    (``detector="fit"``) the saddle-model fit of :mod:`.corner_refine` started from there (a
    corner whose fit fails keeps its cornerSubPix position)."""
    import cv2

    ok, corners = cv2.findChessboardCorners(to_gray8(frame.color), PATTERN, flags=cv2.CALIB_CB_ADAPTIVE_THRESH)
    if not ok:
        return None
    y = (frame.color @ np.array([0.2126, 0.7152, 0.0722])).astype(np.float32)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-5)
    sub = cv2.cornerSubPix(y / y.max(), corners, SUBPIX_WINDOW, (-1, -1), crit).reshape(-1, 2).astype(np.float64)
    if detector == "subpix":
        return sub
    if detector != "fit":
        raise ValueError(f"detector={detector!r} must be one of {DETECTORS}")
    return refine_grid(y / y.max(), sub, PATTERN)[0]


def calibrate_points(obj: list, img: list, size) -> tuple[dict, float]:
    """cv2.calibrateCamera (flags :data:`CALIB_FLAGS_DOC`, Levenberg–Marquardt to 1e-12):
    (estimates, RMS reprojection px)."""
    import cv2

    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    rms, k, d, _, _ = cv2.calibrateCamera([np.asarray(o, np.float32) for o in obj],
                                          [np.asarray(i, np.float32).reshape(-1, 1, 2) for i in img],
                                          size, None, None, flags=cv2.CALIB_FIX_K3, criteria=crit)
    d = d.ravel()
    est = dict(fx=k[0, 0], fy=k[1, 1], cx=k[0, 2], cy=k[1, 2], k1=d[0], k2=d[1], p1=d[2], p2=d[3])
    return {n: float(v) for n, v in est.items()}, float(rms)


def calibrate(frames, size, detector: str = "fit") -> tuple[dict, int, float]:
    """cv2.calibrateCamera on the detected corners: (estimates, views used, RMS reprojection px)."""
    objp = np.zeros((PATTERN[0] * PATTERN[1], 3), np.float32)
    objp[:, :2] = np.mgrid[0:PATTERN[0], 0:PATTERN[1]].T.reshape(-1, 2) * SQUARE_M
    img = [c for c in (detect_corners(fr, detector) for fr in frames) if c is not None]
    if len(img) < 3:
        raise RuntimeError(f"only {len(img)} board(s) detected")
    est, rms = calibrate_points([objp] * len(img), img, size)
    return est, len(img), rms


def detection_error(model: OpenCVModel, frames, camera: OpenCVModel | None = None,
                    detector: str = "fit") -> np.ndarray:
    """Detected minus true corner positions (M×2 px) over all views whose board was found; each
    detection is paired with the nearest true corner (squares are ≥ 20 px, errors ≪ 1 px).
    ``camera``: the frames' projection when they are not ``model``'s output (the undistorted
    renders: the pinhole of :func:`required_render`)."""
    out = []
    for v, fr in enumerate(frames):
        det = detect_corners(fr, detector)
        if det is None:
            continue
        tru = true_corners(model, v, camera)
        j = np.linalg.norm(det[:, None] - tru[None], axis=-1).argmin(axis=1)
        out.append(det - tru[j])
    return np.concatenate(out)


WHAT_IF = ("spline3", "keys-0.75", "keys-0.5", "bilinear", "lanczos3")


def keys(a: float):
    """Keys (1981) cubic convolution kernel with parameter ``a`` (−¾: OpenCV's INTER_CUBIC)."""
    def k(t):
        t = np.abs(t)
        return np.where(t <= 1, ((a + 2) * t - (a + 3)) * t * t + 1,
                        np.where(t < 2, a * (((t - 5) * t + 8) * t - 4), 0.0))
    return k


def resample_what_if(model: OpenCVModel, raw: list, kind: str) -> list:
    """The undistorted renders ``raw`` resampled through the stage's own map
    (:func:`clpost.stages.distortion.distortion_map`, float64) by another interpolator, in numpy:
    ``spline3`` cubic B-spline interpolation with its prefilter (Unser 1999; scipy
    ``map_coordinates(order=3)`` — the stage's final filter), ``keys-0.75`` Keys cubic convolution
    with a = −¾ (OpenCV's INTER_CUBIC; how it compares: docs/distortion_calibration.md),
    ``keys-0.5`` a = −½ (third order), ``bilinear``, ``lanczos3``
    (normalised). Edge repeated. What the stage would give with that final filter."""
    from scipy.ndimage import map_coordinates

    from clpost.stages.distortion import distortion_map, resample

    spec = required_render(model)
    m, ok = distortion_map(model, (spec.width, spec.height), spec.intrinsics())

    def convolve(plane, kern, taps, normalise):
        x0, y0 = np.floor(m[0]).astype(np.int64), np.floor(m[1]).astype(np.int64)
        h, w = plane.shape
        wx = [kern(m[0] - x0 - k) for k in taps]
        wy = [kern(m[1] - y0 - k) for k in taps]
        v = sum(wy[j] * sum(wx[i] * plane[np.clip(y0 + kj, 0, h - 1), np.clip(x0 + ki, 0, w - 1)]
                            for i, ki in enumerate(taps)) for j, kj in enumerate(taps))
        return v / (sum(wx) * sum(wy)) if normalise else v

    def lz(t):
        return np.where(np.abs(t) < 3, np.sinc(t) * np.sinc(t / 3), 0.0)

    out = []
    for fr in raw:
        planes = []
        for c in range(3):
            p = fr.color[..., c].astype(np.float64)
            if kind == "spline3":
                v = map_coordinates(p, [m[1], m[0]], order=3, mode="nearest")
            elif kind in ("keys-0.75", "keys-0.5"):
                v = convolve(p, keys(-float(kind.split("-")[1])), range(-1, 3), False)
            elif kind == "bilinear":
                v = resample(p, m, 1)
            elif kind == "lanczos3":
                v = convolve(p, lz, range(-2, 4), True)
            else:
                raise ValueError(f"what-if filter {kind!r} must be one of {WHAT_IF}")
            planes.append(np.where(ok, v, 0.0))
        out.append(Frame(np.maximum(np.stack(planes, -1), 0.0).astype(np.float32)))
    return out


def conditioning_floor(model: OpenCVModel, n_views: int, sigma_px: float, seeds: int = 8) -> dict:
    """RMS relative error per parameter when calibrating from the TRUE corners of the same views
    plus i.i.d. Gaussian noise of ``sigma_px`` per axis (``seeds`` draws): what this pose set
    and corner count allow at that detection accuracy, independent of rendering and detection."""
    rng = np.random.default_rng(0)
    obj = [board_points()] * n_views
    tru = [true_corners(model, v) for v in range(n_views)]
    errs = []
    for _ in range(seeds):
        est, _ = calibrate_points(obj, [t + rng.normal(0.0, sigma_px, t.shape) for t in tru], model_size(model))
        errs.append([r[2] for r in compare(model, est).values()])
    return dict(zip(("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"), np.sqrt(np.mean(np.square(errs), axis=0))))


PARAMS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2")


def model_size(model: OpenCVModel) -> tuple[int, int]:
    return model.width, model.height


def compare(model: OpenCVModel, est: dict) -> dict:
    """Per parameter: true, estimated, relative error (absolute for a true value of 0)."""
    rows = {}
    for n, e in est.items():
        t = getattr(model, n)
        rows[n] = (t, e, abs(e - t) / abs(t) if t else abs(e - t))
    return rows


def undistort_roundtrip(model: OpenCVModel, view: int = 3, n_views: int = 17) -> dict:
    """distort (clpost) → cv2.undistort → compare with a direct render at the model's K
    (fx = fy required by the renderer, so fy is set to fx here)."""
    import cv2

    m = replace(model, fy=model.fx)
    raw, out = render_views_single(m, view, n_views)
    und = cv2.undistort(out.color.astype(np.float32), m.matrix(), m.vector()[:8])
    valid = cv2.undistort(out.alpha.astype(np.float32), m.matrix(), m.vector()[:8]) > 0.999
    valid[:4], valid[-4:], valid[:, :4], valid[:, -4:] = False, False, False, False
    e = np.abs(und - raw.color)[valid]
    white = float(np.percentile(raw.color, 99))
    return {"mean_abs_rel_white": float(e.mean() / white), "median_abs_rel_white": float(np.median(e) / white),
            "p99_abs_rel_white": float(np.percentile(e, 99) / white), "pixels": int(valid.sum()),
            "undistorted": und, "reference": raw.color, "distorted": out.color}


def render_views_single(model: OpenCVModel, view: int, n_views: int):
    cam = Camera(distortion=model)
    renderer = PyVistaRenderer(board_scene(view, n_views, model))
    try:
        raw = renderer.render(cam, (model.width, model.height), 0, (model.fx, model.fy, model.cx, model.cy))
    finally:
        renderer.close()
    return raw, Pipeline(cam, quality="final", stages=["distortion"]).run(raw)
