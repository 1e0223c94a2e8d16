"""isp: demosaic = colour-demosaicing's Malvar-He-Cutler; kernel = reference; a flat colour comes back
exactly; tone curve and sRGB closed forms; the demosaiced noise power spectrum is the CFA + demosaic's
(not white); camera JPEG output; bad input."""
import json

import numpy as np
import pytest

from clpost import Camera, Frame, Pipeline, sensor_calibration as calib
from clpost.errors import InputError
from clpost.stages.isp import colour_matrix, mhc_demosaic, srgb_encode, tone, white_balance_gains
from clpost.stages.raw import camera_matrix, cfa_channels

from conftest import assert_planned

BAYER = ["RGGB", "BGGR", "GRBG", "GBRG"]


def _cam(**kw):
    kw.setdefault("raw_calibration", "a7s2-like")
    return Camera(iso=800, isp=True, **kw)


def _isp_only(cam, mosaic):
    """The isp stage alone on a given (H, W) mosaic (the raw stage's output form)."""
    pipe = Pipeline(cam, stages=["isp"], already_applied=("exposure", "raw"))
    frame = Frame(np.repeat(np.asarray(mosaic, np.float32)[..., None], 3, axis=2))
    return pipe, frame


def _clean_mosaic(cam, rgb, h, w, pat):
    y, x = np.mgrid[0:h, 0:w]
    return camera_matrix(cam)[cfa_channels(pat)[y % 2, x % 2]] @ np.asarray(rgb, np.float64)


@pytest.mark.parametrize("pat", BAYER)
def test_demosaic_equals_colour_demosaicing_malvar2004(rng, pat):
    from colour_demosaicing import demosaicing_CFA_Bayer_Malvar2004

    cfa = rng.random((23, 37))
    ours = mhc_demosaic(cfa, pat)
    # colour-demosaicing repeats the edge photosite beyond the border (scipy's default "reflect"),
    # which breaks the pattern's parity there; given the mosaic already mirrored by 2 photosites
    # (what ours does) the two agree everywhere
    theirs = demosaicing_CFA_Bayer_Malvar2004(np.pad(cfa, 2, mode="reflect"), pat)[2:-2, 2:-2]
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-12)
    # and inside the 2-photosite rim with no help at all
    np.testing.assert_allclose(ours[2:-2, 2:-2], demosaicing_CFA_Bayer_Malvar2004(cfa, pat)[2:-2, 2:-2], atol=1e-12)


@pytest.mark.parametrize("pat, white", [("RGGB", 0.0), ("BGGR", 4.0), ("GRBG", 1.0), ("GBRG", 0.0),
                                        ("RCCB", 8.0)])
def test_kernel_matches_reference_odd_size(rng, pat, white):
    cam = _cam(cfa_pattern=pat, isp_tone_white=white)
    pipe, frame = _isp_only(cam, rng.uniform(-0.01, 1.2, (23, 37)))
    assert_planned(pipe, frame, "isp")
    out, ref = pipe.run(frame).color, pipe.reference(frame)
    err = np.abs(out - ref)
    assert err.max() < 2e-5, f"largest error {err.max():.3g} at {np.unravel_index(err.argmax(), err.shape)}"


@pytest.mark.parametrize("pat", BAYER + ["RCCB"])
def test_a_flat_colour_comes_back_exactly(pat):
    # MHC is exact on a flat colour, the white balance and colour matrix invert the camera's response
    cam = _cam(cfa_pattern=pat)
    rgb = np.array([0.42, 0.2, 0.08])
    pipe, frame = _isp_only(cam, _clean_mosaic(cam, rgb, 9, 11, pat))
    out = pipe.run(frame).color
    np.testing.assert_allclose(out, np.broadcast_to(srgb_encode(rgb), out.shape), atol=3e-6)


def test_white_balance_and_colour_matrix():
    cam = _cam()
    wb, cm = white_balance_gains(cam), colour_matrix(cam)
    assert wb[1] == pytest.approx(1.0) and wb[0] > wb[2] > 1.0  # a daylight balance: red gained most
    np.testing.assert_allclose(cm.sum(axis=1), 1.0, atol=1e-12)  # white stays white
    np.testing.assert_allclose(cm @ np.diag(wb) @ camera_matrix(cam)[:3], np.eye(3), atol=1e-12)


def test_tone_curve_and_srgb_encoding_closed_forms():
    import colour

    x = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(srgb_encode(x), colour.cctf_encoding(x, "sRGB"), atol=1e-12)
    for w in (1.0, 4.0, 16.0):
        assert tone(np.array(w), w) == pytest.approx(1.0)
        y = tone(np.linspace(0, w, 500), w)
        assert np.all(np.diff(y) > 0)
        assert tone(np.array(1e-4), w) == pytest.approx(1e-4, rel=1e-3)  # linear at the toe
    np.testing.assert_array_equal(tone(x, 0.0), x)


# -- the done-when test: demosaiced raw noise is not white -------------------------------------

def _nps(images):
    """Mean 2-D noise power spectrum (periodogram, mean removed) of same-size images."""
    return np.mean([np.abs(np.fft.fft2(im - im.mean())) ** 2 / im.size for im in images], axis=0)


def _hf_over_lf(nps):
    n = nps.shape[0]
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(n), np.fft.fftfreq(n)))
    return nps[f > 0.35].mean() / nps[(f > 0) & (f < 0.15)].mean()


def test_demosaiced_grey_card_noise_has_the_cfa_and_demosaic_spectrum(tmp_path):
    # A flat grey card through the device raw sensor + ISP. Its noise power spectrum is predicted
    # independently: the card's noise-free mosaic plus white Gaussian noise per photosite with the
    # photon-transfer variance K·S + σ_read² + 1/12 (DN², per filter), developed by the numpy ISP,
    # with numpy's own random numbers. Row/column noise are off here (they are not per photosite).
    doc = json.loads(open(calib.load("a7s2-like").path).read())
    doc["iso"] = [{"iso": 800, "gain_dn_per_e": 0.8464, "read_noise_dn": 3.0, "row_noise_dn": 0.0,
                   "column_noise_dn": 0.0, "dsnu_dn": 0.0, "prnu": 0.0}]
    (tmp_path / "white.json").write_text(json.dumps(doc))
    cam = Camera(iso=800, raw_calibration=str(tmp_path / "white.json"), isp=True)
    c = calib.load(cam.raw_calibration)
    n, span = c.at_iso(800), c.white_level_dn - c.black_level_dn
    size, frames, grey = 256, 4, 0.15
    pipe = Pipeline(cam, stages=["raw", "isp"], already_applied=("exposure",))
    card = np.full((size, size, 3), grey, np.float32)
    assert_planned(pipe, Frame(card), "raw", "isp")
    dev = [pipe.run(Frame(card, metadata={"frame_index": k})).color.astype(np.float64) for k in range(frames)]

    clean = _clean_mosaic(cam, [grey] * 3, size, size, "RGGB")
    sigma = np.sqrt(n.gain_dn_per_e * clean * span + n.read_noise_dn ** 2 + 1 / 12) / span
    rng = np.random.default_rng(2020)

    def develop(mosaic):
        lin = (mhc_demosaic(mosaic, "RGGB") * white_balance_gains(cam)) @ colour_matrix(cam).T
        return srgb_encode(np.maximum(lin, 0.0))

    pred = [develop(clean + sigma * rng.standard_normal(clean.shape)) for _ in range(frames)]
    white = _nps([rng.standard_normal((size, size)) for _ in range(frames)])
    assert _hf_over_lf(white) == pytest.approx(1.0, abs=0.05)
    for k, name in enumerate("RGB"):
        a, b = _nps([d[..., k] for d in dev]), _nps([p[..., k] for p in pred])
        # 16×16 bands of the spectrum (1024 periodogram values each): the shapes agree
        band = lambda s: np.fft.fftshift(s).reshape(16, 16, 16, 16).mean(axis=(1, 3))  # noqa: E731
        ratio = band(a) / band(b)
        assert np.median(ratio) == pytest.approx(1.0, abs=0.03), name
        assert np.abs(ratio - 1.0).max() < 0.25, f"{name}: band ratio {ratio.min():.3f}..{ratio.max():.3f}"
        assert a.mean() == pytest.approx(b.mean(), rel=0.03), name  # total noise power
        # and the spectrum is far from white: high frequencies (|f| > 0.35 cycles/px) carry a small
        # fraction of the low ones' power (measured 0.24 R, 0.01 G, 0.10 B; white noise: 1)
        assert _hf_over_lf(a) == pytest.approx(_hf_over_lf(b), rel=0.1), name
        assert _hf_over_lf(a) < 0.4, name


# -- output and bad input -----------------------------------------------------------------------

def test_camera_jpeg_at_the_chosen_quality(tmp_path):
    from PIL import Image

    from clpost import raw_io

    y, x = np.mgrid[0:40, 0:48] / 48.0
    img = np.stack([0.2 + 0.6 * x, 0.3 + 0.4 * y, 0.5 + 0.3 * np.sin(6 * x * y)], axis=-1)  # smooth
    sizes = {}
    for q in (30, 95):
        path = tmp_path / f"q{q}.jpg"
        raw_io.write_developed(path, img, _cam(isp_jpeg_quality=q))
        sizes[q] = path.stat().st_size
        with Image.open(path) as im:
            # Pillow's own quantisation tables for that quality: the file was written at it
            ref_path = tmp_path / f"ref{q}.jpg"
            Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(ref_path, quality=q, subsampling=2)
            with Image.open(ref_path) as ref:
                assert im.quantization == ref.quantization
            assert im.info.get("icc_profile")
            back = np.asarray(im, np.float64) / 255
        assert np.abs(back - img).mean() < (0.02 if q == 30 else 0.006)
    assert sizes[30] < sizes[95]


def test_cli_writes_a_camera_jpeg(tmp_path):
    from PIL import Image

    from clpost import exr
    from clpost.cli import main

    exr.write_frame(tmp_path / "a.exr", Frame(np.full((12, 16, 3), 0.1, np.float32)))
    assert main(["process", str(tmp_path / "a.exr"), "-o", str(tmp_path / "a.jpg"), "--raw-calibration",
                 "a7s2-like", "--isp", "on", "--isp-tone-white", "4", "--jpeg-quality", "80"]) == 0
    with Image.open(tmp_path / "a.jpg") as im:
        assert im.size == (16, 12) and im.mode == "RGB"
        px = np.asarray(im, np.float64)
    assert 20 < px.mean() < 235  # a developed grey, neither black nor clipped
    assert not (tmp_path / "a.raw.json").exists()


def test_bad_input_named():
    with pytest.raises(InputError, match="needs a raw sensor to develop"):
        Camera.from_options({"isp": True})
    with pytest.raises(InputError, match="isp_tone_white=0.5 must be 0"):
        _cam(isp_tone_white=0.5)
    with pytest.raises(InputError, match="isp_jpeg_quality=0 must be an integer from 1 to 100"):
        _cam(isp_jpeg_quality=0)
    pipe, frame = _isp_only(_cam(), np.zeros((2, 5)))
    with pytest.raises(InputError, match="at least 3x3"):
        pipe.run(frame)


def test_skipped_when_off():
    frame = Frame(np.ones((4, 4, 3), np.float32))
    cam = Camera(iso=800, raw_calibration="a7s2-like")
    assert Pipeline(cam, stages=["isp"], already_applied=("exposure", "raw")).kernels(frame) == []


def test_kernel_matches_reference_with_an_odd_overscan(rng):
    from clpost.frame import Windows

    w, h = 17, 11
    win = Windows(((-1, -3), (w - 1, h - 1 + 2)), ((0, 0), (w - 1, h - 1)))
    cam = _cam(cfa_pattern="GRBG")
    mosaic = rng.uniform(0, 1, (h + 5, w + 1)).astype(np.float32)
    frame = Frame(np.repeat(mosaic[..., None], 3, axis=2), metadata={"windows": win})
    pipe = Pipeline(cam, stages=["isp"], already_applied=("exposure", "raw"))
    assert_planned(pipe, frame, "isp")
    assert np.abs(pipe.run(frame).color - pipe.reference(frame)).max() < 2e-5
    # a flat colour recorded with the same overscan comes back: the phases of raw and isp agree
    rgb = np.array([0.42, 0.2, 0.08])
    y, x = np.mgrid[0:h + 5, 0:w + 1]
    clean = camera_matrix(cam)[cfa_channels("GRBG")[(y + 3) % 2, (x + 1) % 2]] @ rgb
    out = pipe.run(Frame(np.repeat(clean[..., None], 3, axis=2).astype(np.float32), metadata={"windows": win})).color
    np.testing.assert_allclose(out, np.broadcast_to(srgb_encode(rgb), out.shape), atol=3e-6)


def test_an_acescg_camera_develops_to_the_same_srgb():
    # the raw stage records through the working space's matrix; the ISP always develops to sRGB:
    # the same light given in ACEScg or in Rec. 709 gives the same picture
    import colour

    rgb709 = np.array([0.3, 0.2, 0.1])
    aces = colour.RGB_to_RGB(rgb709, "ITU-R BT.709", "ACEScg", chromatic_adaptation_transform="Bradford")
    outs = []
    for ws, rgb in (("rec709", rgb709), ("acescg", aces)):
        cam = _cam(working_space=ws)
        y, x = np.mgrid[0:9, 0:11]
        clean = camera_matrix(cam)[cfa_channels("RGGB")[y % 2, x % 2]] @ rgb
        pipe, frame = _isp_only(cam, clean)
        outs.append(pipe.run(frame).color)
    np.testing.assert_allclose(outs[0], outs[1], atol=2e-3)
    np.testing.assert_allclose(outs[0], np.broadcast_to(srgb_encode(rgb709), outs[0].shape), atol=3e-6)
