"""Geometry pre-processing distortion (Lambers et al. sec. 3.2): vertex stage vs the calibration
forward model, clip margin, crack-free subdivision bounds, end-to-end ids/depth vs the exact ray
cast, bad inputs."""
from __future__ import annotations

import math

import numpy as np
import pytest

from clpost.calibration import OpenCVModel
from clpost.errors import InputError
from clpost.render import DemoScene
from clpost.render.geometry_distortion import (GeometryDistortionRenderer, SubdivisionStats, clip_region,
                                               distort_points, project_distorted, render_reference, subdivide)

FULL = dict(k1=-0.21, k2=0.05, p1=0.002, p2=-0.0015, k3=0.01, k4=0.02, k5=0.003, k6=0.001,
            s1=0.001, s2=-0.0005, s3=0.0007, s4=0.0002, tau_x=0.01, tau_y=-0.008)


def model(w=61, h=43, **coeffs):
    return OpenCVModel(w, h, 50.0, 47.0, 30.3, 20.8, **coeffs)


def test_vertex_stage_lands_on_calibration_forward_with_all_14_coefficients(rng):
    m = model(**FULL)
    pts = np.stack([rng.uniform(-0.5, 0.5, 500), rng.uniform(-0.4, 0.4, 500), rng.uniform(0.1, 50, 500)], -1)
    pts[:, :2] *= pts[:, 2:3]
    back = distort_points(m, pts)
    # a pinhole at f_x, (c_x, c_y) renders the back-transformed vertex
    u = m.fx * back[:, 0] / back[:, 2] + m.cx
    v = m.fx * back[:, 1] / back[:, 2] + m.cy
    eu, ev = m.project(pts[:, 0] / pts[:, 2], pts[:, 1] / pts[:, 2])
    err = np.hypot(u - eu, v - ev)
    assert err.max() < 1e-9, f"max {err.max()} px at vertex {int(err.argmax())}"
    np.testing.assert_array_equal(back[:, 2], pts[:, 2])  # planar depth unchanged
    assert np.all(np.isfinite(distort_points(m, np.array([[1.0, 2.0, -3.0], [0.0, 0.0, 0.0]]))))


def test_clip_margin_is_zero_for_a_pinhole_and_positive_for_barrel():
    assert clip_region(model()).margin_d == 0.0
    assert clip_region(model(k1=-0.3)).margin_d > 0.05
    assert clip_region(model(k1=0.3)).margin_d == 0.0  # pincushion corners see less than the pinhole
    r = clip_region(model(), 0.1)
    # the box [−1.1, 1.1] in NDC: its left edge in normalised units
    assert r.x0 == pytest.approx(((-1.1 + 1) * 61 / 2 - 0.5 - 30.3) / 50.0)


def test_subdivision_keeps_area_and_meets_the_chord_error(rng):
    m = model(k1=-0.3, k2=0.1)
    # a wall at 2 m that lies well inside the image: nothing is clipped
    quad = np.array([[[-1.0, -0.7, 2.0], [1.0, -0.7, 2.0], [1.0, 0.7, 2.0]],
                     [[-1.0, -0.7, 2.0], [1.0, 0.7, 2.0], [-1.0, 0.7, 2.0]]])
    stats = SubdivisionStats()
    out = subdivide(quad, m, clip_region(m), error_px=0.05, max_levels=10, stats=stats)
    area = lambda t: 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=-1).sum()
    assert area(out) == pytest.approx(area(quad), rel=1e-12)
    assert len(out) > 20 and stats.levels < 10
    for k in range(3):
        a, b = out[:, k], out[:, (k + 1) % 3]
        pa, pb, pm = project_distorted(m, a), project_distorted(m, b), project_distorted(m, 0.5 * (a + b))
        assert np.linalg.norm(pm - 0.5 * (pa + pb), axis=-1).max() <= 0.05
    # a pinhole needs no subdivision
    assert len(subdivide(quad, model(), clip_region(model()), error_px=0.05)) == 2


def test_subdivision_is_crack_free_edges_shared_by_two_triangles():
    """Every interior edge of the refined mesh of a two-triangle quad is shared by exactly two
    triangles (no T-junction): count undirected edges."""
    m = model(k1=-0.4)
    quad = np.array([[[-1.0, -0.7, 2.0], [1.0, -0.7, 2.0], [1.0, 0.7, 2.0]],
                     [[-1.0, -0.7, 2.0], [1.0, 0.7, 2.0], [-1.0, 0.7, 2.0]]])
    out = subdivide(quad, m, clip_region(m), error_px=0.02, max_levels=8)
    edges = {}
    for k in range(3):
        for a, b in zip(out[:, k], out[:, (k + 1) % 3]):
            key = tuple(sorted((tuple(a), tuple(b))))
            edges[key] = edges.get(key, 0) + 1
    def on_border(e):
        (xa, ya, _), (xb, yb, _) = e
        return (abs(xa) == 1.0 and xa == xb) or (abs(ya) == 0.7 and ya == yb)

    bad = [e for e, n in edges.items() if n != 2 and not on_border(e)]
    assert not bad, f"{len(bad)} edges without a partner, e.g. {bad[0]}"


@pytest.mark.slow
def test_end_to_end_ids_and_depth_match_the_exact_ray_cast():
    scene = DemoScene.default()
    w, h = 97, 65
    m = OpenCVModel(w, h, 84.0, 84.0, 48.0, 32.0, k1=-0.25, k2=0.08, p1=0.002)
    r = GeometryDistortionRenderer(scene, m, error_px=0.2)
    try:
        f = r.render(0)
    finally:
        r.close()
    ref = render_reference(scene, m, 0)
    ids, rid = f.metadata["object_id"], ref.metadata["object_id"]
    mismatch = float((ids != rid).mean())
    assert mismatch < 0.01, f"{mismatch:.3%} of pixels see another object than the exact ray cast"
    same = (ids == rid) & np.isfinite(ref.depth) & (ids >= 0)
    rel = np.abs(f.depth[same] / ref.depth[same] - 1)
    assert np.median(rel) < 2e-3
    for a in (f.color, f.velocity, f.alpha):
        assert np.all(np.isfinite(a))
    gd = f.metadata["geometry_distortion"]
    assert gd["triangles_out"] > 0 and gd["margin_d_ndc"] > 0


@pytest.mark.parametrize("kw, word", [(dict(error_px=0.0), "error_px"), (dict(error_px=math.nan), "error_px"),
                                      (dict(max_levels=-1), "max_levels"), (dict(delta_ndc=-0.1), "delta_ndc")])
def test_bad_parameters_name_the_fix(kw, word):
    with pytest.raises(InputError, match=word):
        GeometryDistortionRenderer(DemoScene.default(), model(k1=-0.1), **kw)


def test_bad_scene_or_model_type():
    with pytest.raises(InputError, match="OpenCVModel"):
        GeometryDistortionRenderer(DemoScene.default(), {"k1": 0.1})
    with pytest.raises(InputError, match="DemoScene"):
        GeometryDistortionRenderer("scene", model())


@pytest.mark.slow
def test_cli_demo_geometry_distortion_writes_frames_and_refuses_without_calibration(tmp_path):
    import json

    from clpost.cli import main

    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps({"camera_matrix": [[100.0, 0, 47.5], [0, 100.0, 31.5], [0, 0, 1]],
                               "distortion_coefficients": [-0.2, 0.05, 0.0, 0.0],
                               "image_width": 96, "image_height": 64}))
    out = tmp_path / "out"
    assert main(["demo", str(out), "--frames", "1", "--size", "96x64", "--static-camera",
                 "--calibration", str(cal), "--lens-model", "geometry-distortion", "--stages", "exposure"]) == 0
    assert (out / "clpost.0001.exr").exists() and (out / "preview" / "clpost.0001.png").exists()
    with pytest.raises(InputError, match="--calibration"):
        from clpost.demo import run_demo

        run_demo(tmp_path / "x", size=(96, 64), n_frames=1, log=lambda s: None, lens_model="geometry-distortion")
