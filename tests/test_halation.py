"""halation: the base-reflection kernel's closed forms, kernel vs the float64 reference on odd
sizes, energy, red dominance, the skip rule (skipped <=> identity) and bad input."""
import math

import numpy as np
import pytest

from clpost import Camera, Frame, Pipeline
from clpost.errors import InputError
from clpost.stages import halation as H

from conftest import assert_planned

CAM = dict(film="kodak-gold-200", halation=True, shutter_s=1 / 100, f_number=4, sensor_mm=(8.0, 6.0))


def lamp_frame(w=83, h=61, value=500.0, at=(30, 40), seed=3):
    rng = np.random.default_rng(seed)
    color = (rng.random((h, w, 3)) * 0.05).astype(np.float32)
    color[at] = value
    return Frame(color)


def run(cam, frame):
    pipe = Pipeline(cam, stages=["halation"])
    return pipe.run(frame).color, pipe


def test_kernel_is_a_ring_at_the_critical_angle():
    st = H.STOCKS["kodak-gold-200"]
    d = st.base_um * 1e-3
    r_c = 2 * d * math.tan(math.asin(1 / st.n_base))
    k = H.radial_kernel(np.array([0.0, 0.9 * r_c, 1.02 * r_c, 2 * d * math.tan(math.radians(76))]), st.base_um,
                        st.n_base)
    assert k[0] == pytest.approx(((st.n_base - 1) / (st.n_base + 1)) ** 2, rel=1e-9)  # normal incidence
    # total internal reflection beyond r_c: R = 1, K = cos⁴θ — the halation ring
    assert k[2] == pytest.approx(math.cos(math.atan(1.02 * r_c / (2 * d))) ** 4, rel=1e-12)
    assert k[2] > 3 * k[1] > 3 * k[0]
    assert k[3] == 0.0  # beyond THETA_MAX nothing returns
    # Lambertian reflectance: the TIR part is sin²θmax − sin²θc exactly, Fresnel adds a little below θc
    tir = math.sin(math.radians(H.THETA_MAX_DEG)) ** 2 - 1 / st.n_base ** 2
    assert tir < H.diffuse_reflectance(st.n_base) < tir + 0.06


def test_taps_sum_to_one_and_are_symmetric():
    k = H.kernel_taps(H.STOCKS["fuji-superia-400"], 0.03)
    assert k.sum() == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(k, k[::-1, ::-1])
    np.testing.assert_allclose(k, k.T)


def test_taps_of_a_cell_larger_than_the_kernel_are_the_identity():
    # a 3-px-wide frame on a 36 mm sensor: cells of 12 mm, K's whole reach (< 1 mm) between the
    # centre cell's sub-samples — the taps were 0/0 = NaN
    for cell in (12.0, 36.0):
        k = H.kernel_taps(H.STOCKS["kodak-ektar-100"], cell)
        assert np.isfinite(k).all() and k.sum() == 1.0 and k[k.shape[0] // 2, k.shape[1] // 2] == 1.0


@pytest.mark.parametrize("w, h, sensor", [(83, 61, (8.0, 6.0)), (37, 23, (2.0, 1.5)), (200, 31, (36.0, 6.0))])
def test_kernel_matches_reference_on_odd_sizes(w, h, sensor):
    frame = lamp_frame(w, h, at=(h // 2, w // 3))
    cam = Camera(**{**CAM, "sensor_mm": sensor})
    out, pipe = run(cam, frame)
    assert_planned(pipe, frame, "halation")
    ref = pipe.reference(frame)
    assert out.dtype == np.float32
    err = np.abs(out - ref) / (np.abs(ref) + 1e-3)
    assert err.max() < 1e-5, np.unravel_index(int(np.argmax(err)), err.shape)


def test_energy_is_conserved_and_the_halo_is_red():
    frame = lamp_frame()
    out, _ = run(Camera(**CAM), frame)
    src = frame.color.astype(np.float64)
    np.testing.assert_allclose(out.astype(np.float64).sum((0, 1)), src.sum((0, 1)), rtol=0.01)
    # around the lamp (a ring at r_c, 2-12 px here) red gains, green a little, blue nothing
    gain = out.astype(np.float64) - src
    yy, xx = np.mgrid[0:61, 0:83]
    ring = (np.hypot(yy - 30, xx - 40) > 2) & (np.hypot(yy - 30, xx - 40) < 12)
    r, g, b = (gain[..., c][ring].sum() for c in range(3))
    assert r > 5 * g > 0 and b == 0.0


def test_skipped_means_identity():
    dim = lamp_frame(value=0.05)  # no highlight: halo bound below 1 % of middle grey
    for cam, frame in ((Camera(**{**CAM, "halation": False}), lamp_frame()),
                       (Camera(**{**CAM, "film": "neutral-100"}), lamp_frame()),
                       (Camera(**CAM), dim)):
        out, pipe = run(cam, frame)
        assert "halation" not in [s.name for s in pipe.plan(frame)]
        np.testing.assert_array_equal(out, frame.color)
    expl = [str(e) for e in Pipeline(Camera(**CAM), stages=["halation"]).explain(dim)]
    assert any("halation" in e and "no highlight bright enough" in e for e in expl)


def test_bad_value_is_named():
    with pytest.raises(InputError, match="halation"):
        Camera(halation="sometimes")
