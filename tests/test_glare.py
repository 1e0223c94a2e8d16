"""glare: Airy zero and spike count (closed forms), pixel PSF, kernel (pyvkfft and the host FFT) vs numpy reference,
energy, highlights only, skip rule."""
import numpy as np
import pytest

from clpost import Camera, Frame, InputError, Pipeline
from clpost.optics import diffraction as dif
from clpost.stages import glare as glare_mod
from clpost.stages.glare import Glare, fft_shape, nice, threshold_scene

from conftest import assert_planned


def test_round_pupil_first_dark_ring_is_airy():
    assert dif.airy_first_zero() == pytest.approx(dif.AIRY_FIRST_ZERO, rel=0.005)  # measured 0.27 %


@pytest.mark.parametrize("blades,spikes", [(5, 10), (6, 6), (7, 14), (8, 8)])
def test_spike_count_two_n_for_odd_n_for_even(blades, spikes):
    assert dif.spike_count(dif.unit_psf(256, blades, 0.0, 0.0), 20, 120) == spikes


def test_pixel_psf_sums_to_one_and_is_centred():
    k = dif.pixel_psf(dif.unit_psf(256, 6, 0.0, 0.0), 0.5, 10.0)
    assert k.shape[0] % 2 == 1 and k.sum() == pytest.approx(1.0, abs=1e-12)
    c = k.shape[0] // 2
    assert k[c, c] == k.max() and k[c, c] > 0.9  # ~all of the light in the source's own pixel at 10 λN


def test_cauchy_kernel_sums_to_one():
    k = dif.cauchy_kernel((64, 96), 3.0)
    assert k.sum() == pytest.approx(1.0, abs=1e-12) and k[0, 0] == k.max()


def test_nice_sizes():
    assert nice(97) == 98 and nice(121) == 125 and fft_shape(97, 61) == (125, 196)


def _camera(**kw):
    kw = dict(dict(luminance_scale=1.0, lens="thin:50", f_number=11.0, shutter_s=1 / 100, focus_distance_m=3.0,
                   diffraction=True, veiling_glare=0.02, blades=7), **kw)
    return Camera(**kw)


def _lamp(w=97, h=61):
    c = np.full((h, w, 3), 0.01, np.float32)
    c[30, 48] = 1e6
    c[10, 80] = 3e4
    return Frame(c)


@pytest.mark.parametrize("backend", ["vkfft", "host"])
def test_kernel_matches_numpy_reference_and_conserves_energy(backend, monkeypatch):
    """Both FFT paths: VkFFT on the device (when pyvkfft is installed) and scipy on the host (the
    default install's; forced here so it is tested where pyvkfft is installed too)."""
    if backend == "vkfft":
        pytest.importorskip("pyvkfft")
    monkeypatch.setattr(glare_mod, "fft_backend", lambda: backend)
    frame = _lamp()
    pipe = Pipeline(_camera(), stages=["glare"], quality="draft")
    assert_planned(pipe, frame, "glare")
    out = pipe.run(frame).color
    ref = pipe.reference(frame)
    assert np.abs(out - ref).max() <= 1e-6 * np.abs(ref).max()
    cam = pipe.camera_for(frame)
    st = Glare("draft")
    full, pad = st.reference(cam, frame, frame.color, keep_padding=True)
    hi = np.maximum(frame.color.astype(np.float64) - threshold_scene(cam), 0)
    # on the whole padded grid nothing is lost; in the frame, only the glare tail that leaves it
    assert pad.sum((1, 2)) == pytest.approx(hi.sum((0, 1)), rel=1e-9)
    assert np.all(np.abs(full.sum((0, 1)) / frame.color.astype(np.float64).sum((0, 1)) - 1) < 0.01)


def test_below_threshold_pixels_keep_their_value_away_from_highlights():
    frame = _lamp()
    cam = _camera(veiling_glare=0.0)
    st = Glare("draft")
    out = st.reference(cam, frame, frame.color)
    far = np.ones(frame.color.shape[:2], bool)
    far[20:41, 38:59] = False
    far[0:21, 70:91] = False
    assert np.allclose(out[far], frame.color[far], rtol=0, atol=1e-9)


def test_not_planned_without_highlights_or_when_off():
    dim = Frame(np.full((23, 37, 3), 0.01, np.float32))
    e = {x.stage: x for x in Pipeline(_camera()).explain(dim)}["glare"]
    assert not e.planned and "no highlight above" in e.reason
    e = {x.stage: x for x in Pipeline(_camera(diffraction=False, veiling_glare=0.0)).explain(_lamp())}["glare"]
    assert not e.planned and "off" in e.reason


def test_explain_names_the_fft_path(monkeypatch):
    monkeypatch.setattr(glare_mod, "fft_backend", lambda: "host")
    e = {x.stage: x for x in Pipeline(_camera()).explain(_lamp())}["glare"]
    assert e.planned and "FFT by scipy on the host (pyvkfft not installed" in e.reason
    monkeypatch.setattr(glare_mod, "fft_backend", lambda: "vkfft")
    e = {x.stage: x for x in Pipeline(_camera()).explain(_lamp())}["glare"]
    assert "FFT by VkFFT on the device" in e.reason


def test_bad_parameter_is_named():
    with pytest.raises(InputError, match="veiling_glare"):
        _camera(veiling_glare=0.9)
