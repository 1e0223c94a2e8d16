"""dof ground truth: sheared-frustum renders agree on the focus plane and move other depths by
f a (1/u - 1/S); aperture samples fill the aperture polygon."""
import math

import numpy as np
import pytest

from clpost import Camera
from clpost.render import DemoScene, PyVistaRenderer
from clpost.render.thin_lens import accumulate, aperture_samples
from clpost.stages.dof import aperture_radius


def centroid(frame, name):
    ids = frame.metadata["object_id"]
    k = frame.metadata["object_names"].index(name)
    ys, xs = np.nonzero(ids == k)
    return np.array([xs.mean(), ys.mean()])


def centre_depth(scene, name):
    """Planar depth of an object's centre (a sphere's silhouette centroid follows its centre)."""
    k = [o.name for o in scene.objects].index(name)
    cam = scene.camera_pose(0)
    return float((scene.object_pose(k, 0)[:3, 3] - cam[:3, 3]) @ cam[:3, 2])


@pytest.mark.parametrize("focus_m", [3.0, math.inf])
def test_sheared_frustum_keeps_the_focus_plane_and_shifts_the_rest(focus_m):
    cam = Camera(focus_distance_m=focus_m)
    scene = DemoScene.default()
    r = PyVistaRenderer(scene)
    try:
        size = (240, 160)
        base = r.render(cam, size, 0)
        a = (0.05, -0.03)
        moved = r.render(cam, size, 0, aperture_offset_m=a)
        assert moved.velocity is None
        fx = cam.intrinsics(*size)[0]
        # the dome (25 m, radius 2 m): a clean silhouette; its base is cut by the ground, whose
        # cut moves with the viewpoint by a fraction of a pixel
        s = centre_depth(scene, "dome_25m")
        inv_u = 0.0 if math.isinf(focus_m) else 1.0 / focus_m
        expected = fx * np.array(a) * (inv_u - 1.0 / s)
        np.testing.assert_allclose(centroid(moved, "dome_25m") - centroid(base, "dome_25m"), expected, atol=0.2)
    finally:
        r.close()


@pytest.mark.parametrize("blades, rot", [(0, 0.0), (6, 0.0), (5, 20.0)])
def test_aperture_samples_fill_the_aperture(blades, rot):
    cam = Camera(f_number=2.0, blades=blades, blade_rotation_deg=rot)
    pts = aperture_samples(cam, 200)
    radius = 50 / 4 * 1e-3
    rho = np.hypot(pts[:, 0], pts[:, 1]) / radius
    assert len(pts) == 200
    assert (rho <= aperture_radius(np.arctan2(pts[:, 1], pts[:, 0]), blades, rot, 0.0) + 1e-12).all()
    assert np.abs(pts[:16].mean(0)).max() < 0.2 * radius  # every prefix is spread


def test_accumulation_is_the_average_of_the_views():
    cam = Camera(f_number=1.4, focus_distance_m=3.0)
    frame, partial = accumulate(cam, (64, 40), 4, checkpoints=(2, 4))
    np.testing.assert_allclose(partial[4], frame.color, rtol=1e-6)
    assert np.isfinite(frame.color).all() and not np.allclose(partial[2], partial[4])
