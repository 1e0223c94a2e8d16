"""Default renderer: depth, velocity and colour against closed forms on small analytic scenes.

Oracles are independent of the renderer's own geometry code: rays through pixel centres
(x, y) = (i, j) (CONVENTIONS.md) are intersected with the analytic shape in closed form, moved
with the object's rigid motion and projected with ``x = f X/Z + c_x``.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from clpost.camera import Camera
from clpost.errors import InputError
from clpost.frame import Frame
from clpost.render import DemoScene, PyVistaRenderer, Renderer, render_demo_sequence
from clpost.render.demo_scene import Material, Plane, RigidMotion, SceneObject, Sphere, rotation

SIZE = (200, 150)
CAMERA = Camera(lens="thin:50", focus_distance_m=4.0)
STATIC_CAM = RigidMotion.camera((0.0, 0.0, 1.0), (0.0, 1.0, 0.0))
WHITE = Material(albedo=(0.8, 0.8, 0.8))


def facing_plane(distance_m: float, half_m: float = 5.0, **motion) -> SceneObject:
    """A square facing the static camera (normal −y) at planar depth ``distance_m``."""
    r = rotation((1.0, 0.0, 0.0), math.pi / 2)  # local +z → world −y
    return SceneObject("wall", Plane(half_m), WHITE,
                       RigidMotion(position_m=(0.0, distance_m, 1.0), base_rotation=tuple(map(tuple, r)), **motion),
                       casts_shadow=False)


def world_rays(scene: DemoScene, frame: int, size=SIZE):
    """Camera centre C and world ray directions R_c·((x − c_x)/f, (y − c_y)/f, 1) (unit Z in camera)."""
    w, h = size
    f, _, cx, cy = CAMERA.intrinsics(w, h)
    pose = scene.camera_pose(frame)
    x, y = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    cam_dirs = np.stack([(x - cx) / f, (y - cy) / f, np.ones_like(x)], -1)
    return pose[:3, 3], cam_dirs @ pose[:3, :3].T


def ray_sphere_t(c0, d, centre, radius):
    """Nearest t > 0 with |c0 + t d − centre| = radius (NaN when missed); t is planar depth for unit-Z rays."""
    oc = c0 - centre
    a = (d * d).sum(-1)
    b = 2 * (d * oc).sum(-1)
    c = oc @ oc - radius ** 2
    disc = b * b - 4 * a * c
    with np.errstate(invalid="ignore"):
        return np.where(disc > 0, (-b - np.sqrt(disc)) / (2 * a), np.nan)


def project(scene: DemoScene, frame: int, points: np.ndarray) -> np.ndarray:
    w, h = SIZE
    f, _, cx, cy = CAMERA.intrinsics(w, h)
    pose = scene.camera_pose(frame)
    xc = (points - pose[:3, 3]) @ pose[:3, :3]
    return np.stack([f * xc[..., 0] / xc[..., 2] + cx, f * xc[..., 1] / xc[..., 2] + cy], -1)


def erode(mask: np.ndarray, px: int) -> np.ndarray:
    """Pixels whose whole (2px+1)² neighbourhood is in ``mask`` (excludes a px-wide border)."""
    out = mask.copy()
    for dy in range(-px, px + 1):
        for dx in range(-px, px + 1):
            out &= np.roll(np.roll(mask, dy, 0), dx, 1)
    out[:px], out[-px:], out[:, :px], out[:, -px:] = False, False, False, False
    return out


def pixel_grid():
    w, h = SIZE
    return np.stack(np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64)), -1)


@pytest.fixture(scope="module")
def sphere_scene():
    ball = SceneObject("ball", Sphere(0.5), WHITE, RigidMotion(position_m=(0.3, 5.0, 1.2)))
    return DemoScene(objects=(ball,), camera_motion=STATIC_CAM, emitter_lighting=False)


@pytest.fixture(scope="module")
def demo_frames():
    return render_demo_sequence(CAMERA, size=SIZE, n_frames=2)


# -- depth ---------------------------------------------------------------------------------------


def test_plane_depth_equals_distance():
    scene = DemoScene(objects=(facing_plane(4.0),), camera_motion=STATIC_CAM)
    r = PyVistaRenderer(scene)
    frame = r.render(CAMERA, SIZE, 0)
    r.close()
    assert frame.depth.dtype == np.float32
    rel = np.abs(frame.depth / 4.0 - 1)
    assert rel.max() < 1e-3, f"max rel err {rel.max():.2e} at {np.unravel_index(rel.argmax(), rel.shape)}"


def test_sphere_depth_matches_ray_intersection(sphere_scene):
    r = PyVistaRenderer(sphere_scene)
    frame = r.render(CAMERA, SIZE, 0)
    r.close()
    c0, d = world_rays(sphere_scene, 0)
    t = ray_sphere_t(c0, d, np.array([0.3, 5.0, 1.2]), 0.5)
    hit = np.isfinite(t)
    inner = erode(hit, 2)
    assert inner.sum() > 500
    rel = np.abs(frame.depth[inner] / t[inner] - 1)
    assert rel.max() < 1e-3, f"max rel err {rel.max():.2e}"
    background = erode(~hit, 2)
    assert background.sum() > 500
    assert np.all(np.isinf(frame.depth[background])), "background must be +inf"
    assert np.all(frame.depth > 0)


# -- velocity ------------------------------------------------------------------------------------


def test_object_motion_velocity_matches_analytic():
    centre0 = np.array([0.2, 5.0, 1.1])
    motion = RigidMotion(position_m=tuple(centre0), velocity_m_per_frame=(0.05, 0.01, -0.02),
                         axis=(0.3, 0.2, 1.0), angle_rad=0.4, angular_velocity_rad_per_frame=0.05)
    ball = SceneObject("ball", Sphere(0.6), WHITE, motion)
    scene = DemoScene(objects=(ball,), camera_motion=STATIC_CAM)
    r = PyVistaRenderer(scene)
    frame_index = 2
    frame = r.render(CAMERA, SIZE, frame_index)
    r.close()

    c0, d = world_rays(scene, frame_index)
    t = ray_sphere_t(c0, d, motion.matrix(frame_index)[:3, 3], 0.6)
    hit = np.isfinite(t)
    p = c0 + t[..., None] * d
    delta = motion.matrix(frame_index + 1) @ np.linalg.inv(motion.matrix(frame_index))
    p1 = p @ delta[:3, :3].T + delta[:3, 3]
    expected = project(scene, frame_index + 1, p1) - pixel_grid()
    inner = erode(hit, 2)
    err = np.abs(frame.velocity[inner] - expected[inner]).max()
    assert err < 0.25, f"max velocity error {err:.4f} px"
    assert np.abs(expected[inner]).max() > 1.0  # the motion is really there
    bg = erode(~hit, 2)
    assert np.all(frame.velocity[bg] == 0), "static background under a static camera must not move"


def test_camera_motion_velocity_matches_analytic():
    cam_motion = RigidMotion(position_m=(0.0, 0.0, 1.0), base_rotation=tuple(map(tuple, STATIC_CAM.matrix(0)[:3, :3])),
                             velocity_m_per_frame=(0.15, 0.05, 0.03), axis=(0.2, 0.1, 1.0),
                             angular_velocity_rad_per_frame=math.radians(1.0))
    wall = facing_plane(6.0, half_m=0.8)
    scene = DemoScene(objects=(wall,), camera_motion=cam_motion)
    r = PyVistaRenderer(scene)
    frame = r.render(CAMERA, SIZE, 1)
    r.close()

    c0, d = world_rays(scene, 1)
    # wall plane y = 6 (static), square |x| <= 0.8, |z − 1| <= 0.8
    t = (6.0 - c0[1]) / d[..., 1]
    p = c0 + t[..., None] * d
    hit = (np.abs(p[..., 0]) <= 0.8) & (np.abs(p[..., 2] - 1.0) <= 0.8)
    expected = project(scene, 2, p) - pixel_grid()
    inner = erode(hit, 2)
    assert inner.sum() > 500
    err = np.abs(frame.velocity[inner] - expected[inner]).max()
    assert err < 0.25, f"max velocity error {err:.4f} px"
    # background (sky at infinity) moves with the camera's rotation only
    pose0, pose1 = scene.camera_pose(1), scene.camera_pose(2)
    dirs1 = d @ pose1[:3, :3]
    w, h = SIZE
    f, _, cx, cy = CAMERA.intrinsics(w, h)
    sky = np.stack([f * dirs1[..., 0] / dirs1[..., 2] + cx, f * dirs1[..., 1] / dirs1[..., 2] + cy], -1) - pixel_grid()
    bg = erode(~hit, 2)
    assert np.abs(frame.velocity[bg] - sky[bg]).max() < 0.01
    assert np.abs(sky[bg]).max() > 1.0


def test_static_scene_has_zero_velocity(sphere_scene):
    r = PyVistaRenderer(sphere_scene)
    frame = r.render(CAMERA, SIZE, 0)
    r.close()
    assert np.abs(frame.velocity).max() < 1e-6


# -- colour --------------------------------------------------------------------------------------


def test_shading_is_linear_lambert():
    """A white wall facing the camera: L = ρ (E_s max(0, n·s) + E_a (1 + n_z)/2) exactly (no gamma)."""
    scene = DemoScene(objects=(facing_plane(4.0),), camera_motion=STATIC_CAM, emitter_lighting=False)
    r = PyVistaRenderer(scene)
    frame = r.render(CAMERA, SIZE, 0)
    r.close()
    n = np.array([0.0, -1.0, 0.0])
    expected = 0.8 * (scene.sun_irradiance * max(0.0, n @ scene.sun_unit) + scene.ambient * 0.5)
    np.testing.assert_allclose(frame.color, expected, rtol=1e-5)


def test_demo_color_is_float_hdr_and_finite(demo_frames):
    frame = demo_frames[0]
    assert isinstance(frame, Frame)
    assert frame.color.dtype == np.float32 and frame.color.shape == (SIZE[1], SIZE[0], 3)
    assert np.isfinite(frame.color).all()
    assert frame.color.max() >= 100.0, "emitters must be >= 100x diffuse white"
    ids = frame.metadata["object_id"]
    names = frame.metadata["object_names"]
    diffuse = np.isin(ids, [k for k, n in enumerate(names) if not n.startswith(("lamp", "street", "city"))])
    assert 0.3 < np.percentile(frame.color[diffuse], 99) < 2.0, "diffuse white should read about 1"
    assert frame.alpha is None


def test_demo_frames_validate_and_cover_depth_range(demo_frames):
    for frame in demo_frames:
        assert not np.isnan(frame.depth).any() and np.all(frame.depth > 0)
        finite = frame.depth[np.isfinite(frame.depth)]
        assert finite.min() < 1.0 and finite.max() > 50.0
        assert np.isinf(frame.depth).any(), "the sky is +inf"
        assert np.isfinite(frame.velocity).all()
    ids = demo_frames[0].metadata["object_id"]
    mover = demo_frames[0].metadata["object_names"].index("mover")
    assert np.abs(demo_frames[0].velocity[ids == mover]).max() > 1.0
    still = (ids >= 0) & (ids != mover)
    assert np.abs(demo_frames[0].velocity[still]).max() < 1e-6


def test_render_is_deterministic(demo_frames):
    again = render_demo_sequence(CAMERA, size=SIZE, n_frames=1)[0]
    for name in ("color", "depth", "velocity"):
        np.testing.assert_array_equal(getattr(again, name), getattr(demo_frames[0], name))


def test_camera_motion_moves_background():
    frame = render_demo_sequence(CAMERA, size=SIZE, n_frames=1, camera_motion=True)[0]
    sky = np.isinf(frame.depth)
    assert np.abs(frame.velocity[sky]).max() > 0.1


def test_supersampling_keeps_centre_depth(sphere_scene):
    r1, r3 = PyVistaRenderer(sphere_scene), PyVistaRenderer(sphere_scene, supersample=3)
    a, b = r1.render(CAMERA, SIZE, 0), r3.render(CAMERA, SIZE, 0)
    r1.close(), r3.close()
    hit = erode(np.isfinite(a.depth), 2)
    np.testing.assert_allclose(b.depth[hit], a.depth[hit], rtol=1e-4)
    assert np.isinf(b.depth[erode(np.isinf(a.depth), 2)]).all()
    # the antialiased edge holds intermediate values the 1-sample image cannot
    assert b.color.dtype == np.float32 and abs(float(b.color.mean()) - float(a.color.mean())) < 0.02


# -- API and bad input -----------------------------------------------------------------------------


def test_protocol_and_bad_input(sphere_scene):
    r = PyVistaRenderer(sphere_scene)
    try:
        assert isinstance(r, Renderer)
        with pytest.raises(InputError, match="width, height"):
            r.render(CAMERA, (0, 10), 0)
    finally:
        r.close()
    with pytest.raises(InputError, match="odd"):
        PyVistaRenderer(sphere_scene, supersample=2)
    with pytest.raises(InputError, match="DemoScene"):
        PyVistaRenderer("scene")
    with pytest.raises(InputError, match="texture"):
        Material(texture="marble")
    with pytest.raises(InputError, match="n_frames"):
        render_demo_sequence(CAMERA, n_frames=0)
