"""The ST map measurements of docs/distortion_calibration.md ("Formats and ST maps"): each held-out model of
tests/test_stmap.py against OpenCV, the exact composition of the two maps, the round trip through images
(bilinear and cubic B-spline sampling) and the time of a 1080p map.

    .venv/bin/python tools/stmap_check.py   (from the repository root; needs the test extra: opencv)
"""
import sys, time
import cv2, numpy as np
from scipy.ndimage import binary_erosion, map_coordinates
sys.path.insert(0, "tests")
from test_stmap import MODELS, CRIT, _project_cv
from clpost.stmap import make_stmap, map_points, xy_from_st

for name, m in MODELS.items():
    yy, xx = np.mgrid[0:m.height, 0:m.width].astype(np.float64)
    pts = np.stack([xx.ravel(), yy.ravel()], -1)[:, None, :]
    d = make_stmap(m); u = make_stmap(m, "undistort")
    x, y = xy_from_st(d.st[..., 0], d.st[..., 1], m.width, m.height)
    if m.is_fisheye:
        ref = cv2.fisheye.undistortPoints(pts, m.matrix(), m.coefficients(), P=m.matrix(), criteria=CRIT)[:, 0]
    else:
        ref = cv2.undistortPoints(pts, m.matrix(), m.vector(), P=m.matrix(), criteria=CRIT)[:, 0]
    back = _project_cv(m, (ref[:, 0] - m.cx) / m.fx, (ref[:, 1] - m.cy) / m.fy)
    conv = np.hypot(*(back - pts[:, 0]).T) < 1e-6
    e_d = np.hypot(x.ravel() - ref[:, 0], y.ravel() - ref[:, 1])[conv].max()
    uu, vv = xy_from_st(u.st[..., 0], u.st[..., 1], m.width, m.height)
    pr = _project_cv(m, ((xx - m.cx) / m.fx).ravel(), ((yy - m.cy) / m.fy).ravel())
    e_u = np.hypot(uu.ravel() - pr[:, 0], vv.ravel() - pr[:, 1]).max()
    qx, qy, _ = map_points(m, "undistort", xx, yy)
    px, py, _ = map_points(m, "distort", qx, qy)
    e_c = np.hypot(px - xx, py - yy).max()
    print(f"| {name} | {m.width}x{m.height} | {e_d:.1e} ({100*conv.mean():.1f} % of pixels where OpenCV converged) | {e_u:.1e} | {e_c:.1e} |")

def rt(name, size, order):
    m = MODELS[name].scaled_to(*size); w, h = size
    d, u = make_stmap(m), make_stmap(m, "undistort")
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    def node(img, st):
        x, y = xy_from_st(st.st[..., 0], st.st[..., 1], w, h)
        return np.stack([map_coordinates(c, [y, x], order=order, mode="nearest") for c in img]), x, y
    dist, dx, dy = node(np.stack([xx, yy]), d); back, ux, uy = node(dist, u)
    e = 0 if order == 1 else 6
    ins = (u.alpha > 0) & (ux >= e) & (ux <= w - 1 - e) & (uy >= e) & (uy <= h - 1 - e)
    dok = (d.alpha > 0) & (dx >= e) & (dx <= w - 1 - e) & (dy >= e) & (dy <= h - 1 - e)
    dok = binary_erosion(dok, iterations=e) if e else dok
    ins &= map_coordinates(dok.astype(float), [uy, ux], order=1, mode="nearest") > 1 - 1e-9
    err = np.hypot(back[0] - xx, back[1] - yy)[ins]
    return err.max(), np.sqrt((err ** 2).mean()), ins.mean()
for name in ("strong-barrel", "strong-pincushion", "radtan-k1-k6", "fisheye"):
    a = rt(name, (960, 600), 1); b = rt(name, (960, 600), 3)
    print(f"| {name} | 960x600 | {a[0]:.1e} / {a[1]:.1e} ({100*a[2]:.0f} %) | {b[0]:.1e} / {b[1]:.1e} ({100*b[2]:.0f} %) |")
from clpost.calibration import OpenCVModel
m = OpenCVModel(1920, 1080, 1500., 1500., 959.5, 539.5, k1=-0.15, k2=0.02)
for dr in ("distort", "undistort"):
    t = time.perf_counter(); make_stmap(m, dr); print(dr, "1920x1080 s", round(time.perf_counter() - t, 2))
