"""The camera model families (clpost/calibration/projections.py, model.py): each forward model
against an independent implementation (cv2.fisheye, the published closed forms written out here
in another form), the exact inverses by round trip, the domains, and the distortion stage's map
for every family."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from clpost.calibration import OpenCVModel, load_calibration, required_render
from clpost.calibration import projections
from clpost.errors import InputError

FAMILIES = {
    "opencv": OpenCVModel(640, 480, 420.0, 419.0, 321.3, 238.2, k1=-0.2, k2=0.05, p1=1e-3, p2=-5e-4),
    "fisheye": OpenCVModel(640, 480, 260.0, 259.0, 321.3, 238.2, k1=0.06, k2=-0.02, k3=0.004, k4=-0.0007,
                           distortion_model="fisheye"),
    "thinprism": OpenCVModel(640, 480, 260.0, 259.0, 321.3, 238.2, k1=0.01, k2=0.02, p1=0.001, p2=0.002,
                             k3=3e-4, k4=4e-4, s1=1e-4, s3=2e-4, distortion_model="thinprism"),
    "ftheta": OpenCVModel(640, 480, 230.0, 230.0, 321.3, 238.2, k1=-0.05, k2=0.012, k3=-0.002, k4=1e-4,
                          distortion_model="ftheta"),
    "fov": OpenCVModel(640, 480, 300.0, 299.0, 321.3, 238.2, omega=0.93, distortion_model="fov"),
    "ucm": OpenCVModel(640, 480, 520.0, 519.0, 321.3, 238.2, xi=0.9, k1=-0.2, k2=0.04, p1=1e-3, p2=-1e-3,
                       distortion_model="ucm"),
    "ucm_xi_gt_1": OpenCVModel(640, 480, 620.0, 619.0, 321.3, 238.2, xi=1.6, distortion_model="ucm"),
    "ds": OpenCVModel(640, 480, 190.0, 189.5, 321.3, 238.2, xi=-0.2, alpha=0.59, distortion_model="ds"),
    "ds_low_alpha": OpenCVModel(640, 480, 250.0, 251.0, 321.3, 238.2, xi=0.3, alpha=0.4, distortion_model="ds"),
}


def _rays(model, n=4000, seed=0, max_deg=120.0):
    rng = np.random.default_rng(seed)
    tmax = min(projections.theta_max(model), math.radians(max_deg))
    th = rng.uniform(0, 0.995 * tmax, n)
    ph = rng.uniform(0, 2 * np.pi, n)
    return np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)


@pytest.mark.parametrize("name", FAMILIES)
def test_unproject_inverts_project_rays_exactly(name):
    m = FAMILIES[name]
    # the standard model's Newton inverse starts at the distorted point: far out (here beyond 55°,
    # r > 1.4) it can stop short of a valid preimage and says so (invalid, never a wrong ray)
    x, y, z = _rays(m, max_deg=55.0 if name == "opencv" else 120.0)
    u, v, ok = m.project_rays(x, y, z)
    assert ok.mean() > 0.5
    X, Y, Z, ok2 = m.unproject(u[ok], v[ok])
    assert ok2.all()
    ang = np.linalg.norm(np.cross(np.c_[X, Y, Z], np.c_[x, y, z][ok]), axis=1)  # sin of the angle
    assert ang.max() < 1e-8  # Newton's 1e-6 px tolerance over f ≈ 300 px; closed forms reach 1e-15
    # and pixels → rays → pixels over the whole image
    vv, uu = np.mgrid[0:m.height:7, 0:m.width:7].astype(np.float64)
    X, Y, Z, ok = m.unproject(uu, vv)
    pu, pv, ok2 = m.project_rays(X, Y, Z)
    good = ok & ok2
    assert good.mean() > 0.9
    assert np.abs(np.hypot(pu - uu, pv - vv)[good]).max() < 1e-6


def test_fisheye_matches_cv2_fisheye_project_points():
    m = FAMILIES["fisheye"]
    x, y, z = _rays(m, max_deg=89.0)
    u, v, ok = m.project_rays(x, y, z)
    pts = np.c_[x, y, z][:, None, :].astype(np.float64)
    ref, _ = cv2.fisheye.projectPoints(pts, np.zeros(3), np.zeros(3), m.matrix(), m.coefficients())
    assert ok.all()
    np.testing.assert_allclose(np.c_[u, v], ref[:, 0], atol=1e-7)
    # and cv2's inverse agrees with the exact one where it converges (its fixed-point iteration
    # stops short near 90°: below 70° here)
    near = z > math.cos(math.radians(70))
    u, v = u[near], v[near]
    und = cv2.fisheye.undistortPoints(np.c_[u, v][:, None, :], m.matrix(), m.coefficients(),
                                      criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14))[:, 0]
    X, Y, Z, ok = m.unproject(u, v)
    np.testing.assert_allclose(und, np.c_[X / Z, Y / Z], rtol=1e-6, atol=1e-6)


def test_ucm_and_double_sphere_against_the_papers_other_forms():
    """Usenko et al. 2018: UCM in the α form, π = f·x/(α d + (1 − α) z), is Mei's ξ form with
    ξ = α/(1 − α) and f_ξ = f_α/(1 − α) (eq. 5–6); the double sphere with ξ = 0 is that UCM (eq. 41),
    with ξ = α = 0 the pinhole; the UCM with ξ = 1 is the stereographic projection f_ξ tan(θ/2)
    (= 2 f_α tan(θ/2), α = ½)."""
    a, f = 0.6, 300.0
    ucm = OpenCVModel(640, 480, f / (1 - a), f / (1 - a), 320.0, 240.0, xi=a / (1 - a), distortion_model="ucm")
    ds0 = OpenCVModel(640, 480, f, f, 320.0, 240.0, xi=0.0, alpha=a, distortion_model="ds")
    x, y, z = _rays(ucm, max_deg=110.0)
    d = np.sqrt(x * x + y * y + z * z)
    ua = f * x / (a * d + (1 - a) * z) + 320.0
    u1, v1, ok1 = ucm.project_rays(x, y, z)
    u2, v2, ok2 = ds0.project_rays(x, y, z)
    assert ok1.all() and ok2.all()
    np.testing.assert_allclose(u1, ua, atol=1e-9)
    np.testing.assert_allclose(np.c_[u1, v1], np.c_[u2, v2], atol=1e-9)
    ster = OpenCVModel(640, 480, 200.0, 200.0, 320.0, 240.0, xi=1.0, distortion_model="ucm")
    th = np.linspace(0, 2.5, 50)
    u, _, ok = ster.project_rays(np.sin(th), np.zeros_like(th), np.cos(th))
    np.testing.assert_allclose(u - 320.0, 200.0 * np.tan(th / 2), atol=1e-9)
    pin = OpenCVModel(640, 480, 200.0, 200.0, 320.0, 240.0, distortion_model="ds")
    u, v, ok = pin.project_rays(np.array([0.3]), np.array([-0.2]), np.array([1.0]))
    np.testing.assert_allclose([u[0], v[0]], [320 + 60.0, 240 - 40.0], atol=1e-12)


def test_double_sphere_domain_is_the_papers():
    """Usenko et al. eq. 43–45: rays with z ≤ −w₂ d have no image; the unprojection of r² > 1/(2α − 1) is invalid."""
    m = FAMILIES["ds"]
    a, xi = m.alpha, m.xi
    w1 = (1 - a) / a if a > 0.5 else a / (1 - a)
    w2 = (w1 + xi) / math.sqrt(2 * w1 * xi + xi * xi + 1)
    assert projections.theta_max(m) == pytest.approx(math.acos(-w2), abs=1e-12)
    t = math.acos(-w2)
    _, _, ok = m.project_rays(np.array([math.sin(t - 1e-6), math.sin(t + 1e-6)]), np.zeros(2),
                              np.array([math.cos(t - 1e-6), math.cos(t + 1e-6)]))
    assert ok.tolist() == [True, False]
    r = math.sqrt(1 / (2 * a - 1))
    _, _, _, ok = m.unproject(m.cx + m.fx * np.array([0.999 * r, 1.001 * r]), np.full(2, m.cy))
    assert ok.tolist() == [True, False]


def test_ftheta_is_nvidias_angle_to_pixel_polynomial_and_fov_is_devernay_faugeras():
    m = FAMILIES["ftheta"]
    a = m.fx * np.array([1.0, m.k1, m.k2, m.k3, m.k4])  # a1..a5 of r_px = sum a_i θ^i
    th = np.linspace(0, 2.0, 40)
    u, _, ok = m.project_rays(np.sin(th), np.zeros_like(th), np.cos(th))
    assert ok.all()
    np.testing.assert_allclose(u - m.cx, sum(a[i] * th ** (i + 1) for i in range(5)), atol=1e-9)
    f = FAMILIES["fov"]
    x = np.linspace(0, 3, 30)
    u, _, ok = f.project_rays(x, np.zeros_like(x), np.ones_like(x))
    w = f.omega  # COLMAP's FOVCameraModel: r_d = atan(2 r tan(ω/2)) / ω on the pinhole radius r
    np.testing.assert_allclose(u - f.cx, f.fx * np.arctan(2 * x * math.tan(w / 2)) / w, atol=1e-9)


def test_colmap_thin_prism_fisheye_written_out():
    """COLMAP's ThinPrismFisheyeCameraModel::ImgFromCam: equidistant, then radial k1..k4 in r², p, sx1, sy1."""
    m = FAMILIES["thinprism"]
    x, y, z = _rays(m, max_deg=85.0)
    u, v, ok = m.project_rays(x, y, z)
    r = np.hypot(x / z, y / z)
    th = np.arctan(r)
    uu, vv = th * (x / z) / r, th * (y / z) / r
    r2 = uu * uu + vv * vv
    rad = m.k1 * r2 + m.k2 * r2 ** 2 + m.k3 * r2 ** 3 + m.k4 * r2 ** 4
    du = uu * rad + 2 * m.p1 * uu * vv + m.p2 * (r2 + 2 * uu * uu) + m.s1 * r2
    dv = vv * rad + 2 * m.p2 * uu * vv + m.p1 * (r2 + 2 * vv * vv) + m.s3 * r2
    np.testing.assert_allclose(np.c_[u, v], np.c_[m.fx * (uu + du) + m.cx, m.fy * (vv + dv) + m.cy], atol=1e-9)


@pytest.mark.parametrize("kwargs,msg", [
    (dict(xi=-0.1, distortion_model="ucm"), "xi=-0.1 must be >= 0"),
    (dict(xi=0.1, alpha=1.0, distortion_model="ds"), "0 <= alpha < 1"),
    (dict(omega=4.0, distortion_model="fov"), "omega=4.0"),
    (dict(k5=0.1, distortion_model="ftheta"), "k5 must be 0"),
    (dict(xi=0.5), "opencv model has only"),
])
def test_bad_parameters_are_one_line(kwargs, msg):
    with pytest.raises(InputError, match=msg) as e:
        OpenCVModel(64, 48, 50.0, 50.0, 32.0, 24.0, **kwargs)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("name", [n for n in FAMILIES if n != "opencv"])
def test_the_distortion_map_of_every_family_samples_each_pixels_ray(name):
    """The stage's map (clpost/stages/distortion.py distortion_map) at the required render — the
    pinhole of required_render, or the cubemap where the camera sees beyond 75° off axis: each
    output pixel with data samples the render where its own unprojected ray lands."""
    from clpost.calibration import PINHOLE_LIMIT_DEG, max_ray_angle_deg, required_cubemap
    from clpost.stages.distortion import distortion_map

    small = FAMILIES[name].scaled_to(160, 120)
    vv, uu = np.mgrid[0:120, 0:160].astype(np.float64)
    X, Y, Z, okr = small.unproject(uu, vv)
    if max_ray_angle_deg(small) > PINHOLE_LIMIT_DEG:
        spec = required_cubemap(small)
        mp, ok = distortion_map(small, (spec.width, spec.height), spec)
        sx, sy = spec.positions(X, Y, Z)
        sel = ok & okr
        assert sel.mean() > 0.9
    else:
        spec = required_render(small)
        mp, ok = distortion_map(small, (spec.width, spec.height), spec.intrinsics())
        sel = ok & okr & (Z > 0)
        assert sel.mean() > 0.9
        sx, sy = spec.f * X / np.where(sel, Z, 1) + spec.cx, spec.f * Y / np.where(sel, Z, 1) + spec.cy
    np.testing.assert_allclose(mp[0][sel], sx[sel], atol=1e-6)
    np.testing.assert_allclose(mp[1][sel], sy[sel], atol=1e-6)


def test_kalibr_double_sphere_file_reads_and_projects():
    from pathlib import Path

    m = load_calibration(Path(__file__).parent / "data" / "calibration" / "camchain_ds.yaml#cam0")
    assert m.distortion_model == "ds"
    u, v, ok = m.project_rays(np.array([0.0]), np.array([0.0]), np.array([1.0]))
    assert ok[0] and (u[0], v[0]) == (m.cx, m.cy)


# -- cubemap renders for fields of view beyond a pinhole's ------------------------------------------

WIDE = OpenCVModel(480, 480, 120.0, 120.0, 239.5, 239.5, xi=-0.15, alpha=0.6, distortion_model="ds")  # ≈ 230°


def _direction_pattern(x, y, z):
    """A smooth function of the direction (no preferred face): what a cubemap should carry."""
    n = np.sqrt(x * x + y * y + z * z)
    x, y, z = x / n, y / n, z / n
    return 0.5 + 0.2 * np.sin(3 * x) * np.cos(2 * y) + 0.2 * z


def _synthetic_atlas(spec):
    from clpost.calibration.cubemap import face_rotation

    f, _, c, _ = spec.intrinsics()
    vv, uu = np.mgrid[0:spec.size, 0:spec.size].astype(np.float64)
    faces = []
    for i in range(6):
        d = np.stack([(uu - c) / f, (vv - c) / f, np.ones_like(uu)], -1) @ face_rotation(i).T
        faces.append(_direction_pattern(d[..., 0], d[..., 1], d[..., 2]))
    return np.repeat(np.concatenate(faces, axis=1)[..., None], 3, -1).astype(np.float32)


def test_cubemap_positions_land_on_the_rays_face_and_back():
    from clpost.calibration.cubemap import CubemapSpec, face_rotation

    spec = CubemapSpec(64)
    rng = np.random.default_rng(3)
    p = rng.normal(size=(5000, 3))
    sx, sy = spec.positions(p[:, 0], p[:, 1], p[:, 2])
    i = np.floor(sx / spec.size).astype(int)
    f, _, c, _ = spec.intrinsics()
    a, b = (sx - i * spec.size - c) / f, (sy - c) / f
    assert np.abs(a).max() <= 1 + 1e-12 and np.abs(b).max() <= 1 + 1e-12  # inside the face's 90°
    back = np.einsum("nij,nj->ni", np.stack([face_rotation(k) for k in i]), np.c_[a, b, np.ones_like(a)])
    cosang = np.sum(back * p, 1) / np.linalg.norm(back, axis=1) / np.linalg.norm(p, axis=1)
    assert cosang.min() > 1 - 1e-12


def test_beyond_150_degrees_render_size_asks_for_a_cubemap_and_the_stage_samples_it():
    from clpost import Camera, Frame, Pipeline
    from clpost.calibration import max_ray_angle_deg, required_cubemap
    from clpost.render_size import report

    assert max_ray_angle_deg(WIDE) > 100
    with pytest.raises(InputError, match="render a cubemap of six 240 px faces"):
        required_render(WIDE)
    assert "render a cubemap: six 240 px faces" in report(WIDE, "calibration")
    spec = required_cubemap(WIDE)
    frame = Frame(_synthetic_atlas(spec), metadata={"cubemap": (spec.face, spec.pad)})
    out = Pipeline(Camera(distortion=WIDE), quality="final", stages=["distortion"]).run(frame)
    vv, uu = np.mgrid[0:480, 0:480].astype(np.float64)
    x, y, z, ok = WIDE.unproject(uu, vv)
    assert ok.mean() > 0.7 and (np.degrees(np.arccos(z[ok])) > 100).any()
    np.testing.assert_array_equal(out.alpha > 0, ok)
    err = np.abs(out.color[..., 0] - _direction_pattern(x, y, z))[ok]
    assert err.max() < 2e-3, err.max()  # cubic B-spline of a smooth pattern, float32, across face seams


def test_render_cubemap_faces_are_the_rotated_pinhole_renders():
    from clpost import Camera
    from clpost.calibration.cubemap import CubemapSpec
    from clpost.render import DemoScene, PyVistaRenderer

    spec = CubemapSpec(48)
    r = PyVistaRenderer(DemoScene.default())
    try:
        atlas = r.render_cubemap(Camera(), spec, 0)
        front = r.render(Camera(), (spec.size, spec.size), 0, spec.intrinsics())
    finally:
        r.close()
    assert atlas.color.shape == (spec.size, 6 * spec.size, 3) and atlas.metadata["cubemap"] == (48, spec.pad)
    np.testing.assert_array_equal(atlas.color[:, 4 * spec.size:5 * spec.size], front.color)  # +z is the camera's view
    assert all(atlas.color[:, k * spec.size:(k + 1) * spec.size].std() > 0 for k in range(6))


def _cli(argv, capsys):
    from clpost.cli import main

    rc = main(argv)
    return rc, capsys.readouterr()


def test_cli_show_render_size_and_bad_files(tmp_path, capsys):
    from clpost.calibration import calibration_text

    wide = tmp_path / "wide.yaml"
    wide.write_text(calibration_text(WIDE, "kalibr"))
    rc, io = _cli(["calibration", "show", str(wide)], capsys)
    assert rc == 0 and "model=ds" in io.out and "cubemap of six 240 px faces" in io.out, io.err
    rc, io = _cli(["render-size", "--calibration", str(wide)], capsys)
    assert rc == 0 and "render a cubemap: six 240 px faces" in io.out, io.err
    narrow = tmp_path / "narrow.yaml"
    narrow.write_text(calibration_text(FAMILIES["ds"].scaled_to(160, 120), "opencv-yaml"))
    rc, io = _cli(["calibration", "show", str(narrow)], capsys)
    assert rc == 0 and "model=ds" in io.out, io.err
    bad = tmp_path / "bad.yaml"
    bad.write_text("cam0:\n  camera_model: ds\n  intrinsics: [0.1, 0.6, 300, 300, 320]\n  distortion_model: none\n"
                   "  distortion_coeffs: []\n  resolution: [640, 480]\n")
    rc, io = _cli(["calibration", "show", str(bad)], capsys)
    assert rc == 2 and str(bad) in io.err and "intrinsics must be [xi, alpha, fx, fy, cx, cy]" in io.err
    assert len(io.err.strip().splitlines()) == 1


@pytest.mark.parametrize("name", [n for n in FAMILIES if n != "opencv"])
def test_stmap_distort_and_undistort_invert_each_other(name):
    """clpost.stmap's two directions (distorted pixel → undistorted image at the calibration's K, and back)
    for every family, where the pixel's ray is within 80° of the axis (the undistorted image is a pinhole's)."""
    from clpost.stmap import map_points

    m = FAMILIES[name]
    vv, uu = np.mgrid[0:m.height:9, 0:m.width:9].astype(np.float64)
    x, y, ok = map_points(m, "distort", uu, vv)
    _, _, z, _ = m.unproject(uu, vv)
    ok &= z > math.cos(math.radians(80))
    u2, v2, ok2 = map_points(m, "undistort", x[ok], y[ok])
    assert ok.mean() > 0.5 and ok2.all()
    assert np.hypot(u2 - uu[ok], v2 - vv[ok]).max() < 1e-6
