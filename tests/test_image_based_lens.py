"""Image-based lens model (Heidrich et al.) preprocessing: backward trace = forward trace
reversed, COP fit of rays through a known point, single projection for a small field, subdivision
below the threshold, bad inputs."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from clpost.errors import InputError
from clpost.optics import get_lens
from clpost.optics.trace import trace
from clpost.render.image_based_lens import angle_errors_deg, build, fit_cop, mirrored_table, trace_back


def test_backward_trace_retraced_forward_returns_to_the_film_point():
    lens = get_lens("thorlabs-ac254-050-a")
    pres = lens.focused(3000.0, 8.0)
    table, zf = mirrored_table(pres, lens.stop_radius_mm(8.0))
    film = np.array([[0.0, 0.0], [1.5, -0.7], [-2.0, 1.0]])
    q, d, ok = trace_back(table, zf, film, np.array([0.3, -0.2, lens.paraxial.z_exit_pupil_mm]))
    assert ok.all()
    fwd = trace(pres, q, -d, stop_radius_mm=lens.stop_radius_mm(8.0))
    assert fwd.ok.all()
    err = np.abs(fwd.pos[:, :2] - film).max()
    assert err < 1e-9, f"max {err} mm"


def test_cop_fit_recovers_the_common_point_of_exact_pinhole_rays(rng):
    e_true = np.array([0.4, -0.3, 2.0])
    d = rng.normal(size=(40, 3)) * [0.2, 0.2, 0.0] + [0, 0, -1.0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    q = e_true + rng.uniform(3, 9, (40, 1)) * d
    e = fit_cop(q, d, np.zeros(3))
    assert np.linalg.norm(e - e_true) < 1e-6
    assert angle_errors_deg(q, d, e).max() < 1e-5  # arccos resolves ~1e-6° near cos = 1


@pytest.mark.parametrize("lens", ["thorlabs-ac254-050-a", "thorlabs-lb1471"])
def test_small_field_is_one_projection_per_sample_and_wide_field_is_subdivided_below_threshold(lens):
    warnings.simplefilter("ignore")
    small = build(lens, 3.0, 8.0, sensor_mm=(4.0, 4.0), pupil_n=2)
    assert small.projections_per_sample().tolist() == [1, 1, 1, 1]
    assert small.max_angle_deg < 0.05
    wide = build(lens, 3.0, 8.0, sensor_mm=(12.0, 8.0), pupil_n=2, threshold_deg=0.05)
    assert wide.projections_per_sample().max() > 1
    assert wide.max_angle_deg < 0.05
    one = build(lens, 3.0, 8.0, sensor_mm=(12.0, 8.0), pupil_n=2, threshold_deg=0.05, max_depth=0)
    assert one.max_angle_deg > 0.05  # without subdivision the error is above the threshold
    for p in wide.projections:
        assert np.all(np.isfinite(p.tex)) and np.all(p.weight >= 0) and p.weight.max() > 0


@pytest.mark.parametrize("kw, word", [(dict(lens="nope"), "lens_data"), (dict(grid=1), "grid"),
                                      (dict(pupil_n=0), "pupil_n"), (dict(threshold_deg=0.0), "threshold_deg"),
                                      (dict(sensor_mm=(36.0, -1.0)), "sensor_mm")])
def test_bad_inputs_name_the_fix(kw, word):
    args = dict(lens="thorlabs-lb1471", focus_distance_m=3.0, f_number=8.0)
    args.update(kw)
    with pytest.raises(InputError, match=word):
        build(**args)
