"""clpost.render.kolb_trace: the distribution ray tracer that is the reference of
docs/image_based_lens.md — its exposure normalisation on a uniform scene, corner falloff,
and determinism per seed."""
import math

import numpy as np

from clpost.render.demo_scene import DemoScene, Material, Plane, RigidMotion, SceneObject, rotation
from clpost.render.kolb_trace import kolb_image, planes_scene, radiance

LENS, N, FOCUS_M, FILM_MM = "thorlabs-lb1471", 4.0, 3.0, (12.0, 8.0)


def uniform_wall() -> DemoScene:
    """One uniform plane filling the view (both checker albedos equal) at 25 m."""
    face = tuple(tuple(r) for r in rotation((1.0, 0.0, 0.0), math.pi / 2))
    wall = SceneObject("wall", Plane(60.0), Material(albedo=(0.5, 0.4, 0.3), albedo2=(0.5, 0.4, 0.3),
                                                     texture="checker", texture_scale_m=1.0),
                       RigidMotion(position_m=(0.0, 25.0, 1.0), base_rotation=face), casts_shadow=False)
    return DemoScene(objects=(wall,), camera_motion=RigidMotion.camera((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
                     sun_irradiance=0.0, ambient=2.0, emitter_lighting=False)


def test_uniform_scene_gives_its_radiance_on_axis_and_less_in_the_corners():
    """Radiance × relative illumination, normalised by the axial point: the centre pixel of a
    uniform scene is its radiance (to Monte Carlo noise, ≈ 1 % at 4096 rays), the corners no more."""
    scene = uniform_wall()
    L = radiance(scene, np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 1.0, 0.0]]))[0]
    assert np.all(L > 0)
    img = kolb_image(LENS, N, FOCUS_M, FILM_MM, (3, 3), scene, rays=4096, seed=0)
    np.testing.assert_allclose(img[1, 1], L, rtol=0.05)
    corners = img[[0, 0, -1, -1], [0, -1, 0, -1]]
    assert np.all(corners <= img[1, 1] * 1.05)
    np.testing.assert_allclose(img / L, (img / L)[..., :1].repeat(3, -1), rtol=1e-9)  # grey falloff


def test_deterministic_per_seed():
    args = (LENS, N, FOCUS_M, FILM_MM, (6, 4), planes_scene())
    a = kolb_image(*args, rays=32, seed=0)
    assert a.shape == (4, 6, 3) and np.isfinite(a).all() and a.min() >= 0
    np.testing.assert_array_equal(a, kolb_image(*args, rays=32, seed=0))
    assert not np.array_equal(a, kolb_image(*args, rays=32, seed=1))
