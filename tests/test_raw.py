"""raw: kernel = bit-exact hash reference; CFA sampling; photon-transfer curve per channel; row,
column and fixed-pattern noise; calibration file (interpolation, errors); 16-bit raw output."""
import json

import numpy as np
import pytest

from clpost import Camera, Frame, Pipeline, sensor_calibration as calib
from clpost.errors import InputError
from clpost.stages.raw import camera_matrix, cfa_channels

from conftest import assert_planned

A7S2 = calib.load("a7s2-like")


def _cam(iso=800, **kw):
    kw.setdefault("raw_calibration", "a7s2-like")
    return Camera(f_number=2.8, shutter_s=1 / 100, iso=iso, luminance_scale=1.0, **kw)


def _run(cam, color, index=0):
    pipe = Pipeline(cam, stages=["raw"], already_applied=("exposure",))
    return pipe.run(Frame(np.asarray(color, np.float32), metadata={"frame_index": index})).color


def write_calibration(path, **over):
    """A calibration file like the shipped one with some fields replaced (``iso`` rows: dicts)."""
    doc = json.loads(open(A7S2.path).read())
    doc.update(over)
    path.write_text(json.dumps(doc))
    return str(path)


def _one_iso(tmp_path, name="c.json", **noise):
    row = {"iso": 800, "gain_dn_per_e": 0.8, "read_noise_dn": 2.0, "row_noise_dn": 0.0, "column_noise_dn": 0.0,
           "dsnu_dn": 0.0, "prnu": 0.0}
    row.update(noise)
    return write_calibration(tmp_path / name, iso=[row])


@pytest.mark.parametrize("cfa", ["RGGB", "BGGR", "GRBG", "GBRG", "RCCB"])
def test_kernel_matches_reference_odd_size(rng, cfa):
    c = (10.0 ** rng.uniform(-6, 0.5, (23, 37, 3))).astype(np.float32)
    c[:8] *= 1e-3  # low light: the exact-Poisson branch
    frame = Frame(c, metadata={"frame_index": 7})
    pipe = Pipeline(_cam(iso=1000, cfa_pattern=cfa), stages=["raw"], already_applied=("exposure",))
    assert_planned(pipe, frame, "raw")
    out, ref = pipe.run(frame).color, pipe.reference(frame)
    step = 1.0 / (A7S2.white_level_dn - A7S2.black_level_dn)
    dn_err = np.abs(out - ref) / step
    # float32 Box-Muller/Poisson vs float64 may round one DN differently, very rarely
    assert np.isfinite(out).all() and dn_err.max() <= 1.0 + 1e-3
    assert (dn_err > 1e-3).mean() < 2e-3, f"{(dn_err > 1e-3).sum()} values differ by 1 DN"
    assert np.array_equal(out[..., 0], out[..., 1]) and np.array_equal(out[..., 0], out[..., 2])


def test_each_photosite_records_its_filters_channel(tmp_path):
    # a saturated-free, nearly noise-free sensor (huge well, tiny gain noise): the mean of each
    # CFA phase is that filter's response M_c · rgb
    path = _one_iso(tmp_path, read_noise_dn=0.0)
    rgb = np.array([0.3, 0.5, 0.2])
    for cfa in ("GBRG", "RCCB"):
        cam = _cam(raw_calibration=path, cfa_pattern=cfa)
        out = _run(cam, np.broadcast_to(rgb, (64, 64, 3)))[..., 0]
        m = camera_matrix(cam)
        ch = cfa_channels(cfa)
        for py in range(2):
            for px in range(2):
                expect = m[ch[py, px]] @ rgb
                got = out[py::2, px::2].mean()
                assert got == pytest.approx(expect, rel=2e-3), (cfa, py, px)


def test_gray_gives_the_calibrations_channel_gains():
    # the per-channel gains are the responses to a D65 (working-space) white: G = 1, R and B below
    m = camera_matrix(_cam())
    gains = m.sum(axis=1)
    assert gains[1] == pytest.approx(1.0) and 0.3 < gains[0] < 0.45 and 0.6 < gains[2] < 0.8
    assert gains[3] == pytest.approx(gains[:3].sum())


@pytest.mark.parametrize("signal", [0.002, 0.05, 0.4])
def test_photon_transfer_curve_per_channel(tmp_path, signal):
    # shot + read noise alone: DN variance = K·(mean DN − B) + σ_read² + 1/12 (quantisation), per
    # channel — the photon-transfer curve (EMVA 1288 eq. 9); means = K·e_sat·M_c·rgb
    path = _one_iso(tmp_path, read_noise_dn=3.0)
    cam = _cam(raw_calibration=path)
    c = calib.load(path)
    n = c.at_iso(800)
    span = c.white_level_dn - c.black_level_dn
    out = _run(cam, np.full((256, 256, 3), signal, np.float32))[..., 0] * span  # DN − B
    m = camera_matrix(cam)
    for name, (py, px) in {"R": (0, 0), "G": (0, 1), "B": (1, 1)}.items():
        dn = out[py::2, px::2].astype(np.float64)
        mean_expect = signal * m["RGB".index(name)].sum() * span
        assert dn.mean() == pytest.approx(mean_expect, rel=0.01, abs=0.05), name
        var_expect = n.gain_dn_per_e * mean_expect + n.read_noise_dn ** 2 + 1 / 12
        assert dn.var() == pytest.approx(var_expect, rel=0.06), name


def test_all_noise_terms_add_up_to_the_closed_form(tmp_path):
    # var = K·S + σ_read² + σ_row² + σ_col² + σ_DSNU² + (PRNU·S)² + 1/12 (S: mean DN above black)
    path = _one_iso(tmp_path, read_noise_dn=2.0, row_noise_dn=1.5, column_noise_dn=1.0, dsnu_dn=1.2, prnu=0.01)
    cam = _cam(raw_calibration=path, cfa_pattern="RGGB")
    c = calib.load(path)
    n = c.at_iso(800)
    span = c.white_level_dn - c.black_level_dn
    out = _run(cam, np.full((512, 512, 3), 0.2, np.float32))[..., 0] * span
    g = out[0::2, 1::2].astype(np.float64)
    s = 0.2 * span
    expect = (n.gain_dn_per_e * s + n.read_noise_dn ** 2 + n.row_noise_dn ** 2 + n.column_noise_dn ** 2
              + n.dsnu_dn ** 2 + (n.prnu * s) ** 2 + 1 / 12)
    assert g.var() == pytest.approx(expect, rel=0.1)


def test_row_and_column_noise_are_lines_and_fixed_pattern_repeats(tmp_path):
    dark = np.zeros((128, 128, 3), np.float32)
    span = A7S2.white_level_dn - A7S2.black_level_dn
    rows = _run(_cam(raw_calibration=_one_iso(tmp_path, "r.json", read_noise_dn=0.0, row_noise_dn=4.0)), dark)[..., 0]
    # one value per row (up to 1 DN of rounding), rows differ with σ ≈ 4 DN
    assert np.abs(rows - rows.mean(axis=1, keepdims=True)).max() * span <= 1.0
    assert np.std(rows.mean(axis=1) * span) == pytest.approx(4.0, rel=0.2)
    cols = _run(_cam(raw_calibration=_one_iso(tmp_path, "c.json", read_noise_dn=0.0, column_noise_dn=4.0)), dark)[..., 0]
    assert np.abs(cols - cols.mean(axis=0, keepdims=True)).max() * span <= 1.0
    assert np.std(cols.mean(axis=0) * span) == pytest.approx(4.0, rel=0.2)
    # row noise is temporal: another frame, other rows; DSNU is fixed: another frame, the same pattern
    rows2 = _run(_cam(raw_calibration=_one_iso(tmp_path, "r.json", read_noise_dn=0.0, row_noise_dn=4.0)), dark, 1)
    assert abs(np.corrcoef(rows.ravel(), rows2[..., 0].ravel())[0, 1]) < 0.3
    fpn = _cam(raw_calibration=_one_iso(tmp_path, "d.json", read_noise_dn=1.0, dsnu_dn=4.0))
    a, b = _run(fpn, dark, 1)[..., 0], _run(fpn, dark, 2)[..., 0]
    r = np.corrcoef(a.ravel(), b.ravel())[0, 1]
    assert r == pytest.approx(16.0 / (16.0 + 1.0 + 1 / 12), abs=0.05)
    other_seed = _run(_cam(raw_calibration=fpn.raw_calibration, noise_seed=5), dark, 1)[..., 0]
    assert abs(np.corrcoef(a.ravel(), other_seed.ravel())[0, 1]) < 0.05


def test_black_white_level_and_bit_depth():
    # ISO 200: the ADC clips (at white) before the well fills (at ISO 100 both meet)
    out = _run(_cam(iso=200), np.array([[[0.0] * 3, [1e3] * 3, [0.5] * 3]], np.float32))[0, :, 0]
    span = A7S2.white_level_dn - A7S2.black_level_dn
    dn = out.astype(np.float64) * span + A7S2.black_level_dn
    np.testing.assert_allclose(dn, np.round(dn), atol=1e-3)  # whole DN
    assert dn[1] == A7S2.white_level_dn  # clipped at the white level
    assert abs(dn[0] - A7S2.black_level_dn) < 6 * A7S2.at_iso(200).read_noise_dn  # dark: black ± noise


def test_calibration_interpolates_log_log_between_isos():
    a, b = A7S2.at_iso(400), A7S2.at_iso(1600)
    mid = A7S2.at_iso(800)  # the geometric middle of 400 and 1600
    for k in calib.NOISE_KEYS:
        assert getattr(mid, k) == pytest.approx(np.sqrt(getattr(a, k) * getattr(b, k)), rel=1e-12), k
    assert A7S2.at_iso(1600) == A7S2.table[2]
    # the gain is proportional to ISO in this file (to its 5 digits), and log-log interpolation keeps that
    assert A7S2.at_iso(3000).gain_dn_per_e == pytest.approx(A7S2.table[0].gain_dn_per_e * 30, rel=1e-4)
    # at base ISO the well fills exactly at white
    assert (A7S2.white_level_dn - A7S2.black_level_dn) / A7S2.at_iso(100).gain_dn_per_e == pytest.approx(
        A7S2.full_well_e, rel=1e-4)


@pytest.mark.parametrize("over, words", [
    ({"format": "x"}, "'format' must be"),
    ({"bits": 20}, "'bits'=20 must be <= 16"),
    ({"black_level_dn": 20000}, "levels must satisfy"),
    ({"cfa_pattern": "RGBW"}, "'cfa_pattern'='RGBW'"),
    ({"xyz_to_camera": [[1, 0, 0], [0, 1, 0]]}, "invertible 3x3"),
    ({"iso": []}, "non-empty list"),
    ({"iso": [{"iso": 100, "gain_dn_per_e": -1, "read_noise_dn": 1, "row_noise_dn": 0, "column_noise_dn": 0,
               "dsnu_dn": 0, "prnu": 0}]}, "must be >= 0.0"),
    ({"iso": [{"iso": 100, "gain_dn_per_e": 1, "read_noise_dn": "x", "row_noise_dn": 0, "column_noise_dn": 0,
               "dsnu_dn": 0, "prnu": 0}]}, "'read_noise_dn' must be a finite number"),
])
def test_bad_calibration_file_named_in_one_line(tmp_path, over, words):
    path = write_calibration(tmp_path / f"bad{abs(hash(words))}.json", **over)
    with pytest.raises(InputError) as e:
        _cam(raw_calibration=path)
    msg = str(e.value)
    assert words in msg and path in msg and "docs/raw_isp.md" in msg and "\n" not in msg


def test_bad_camera_settings_named():
    with pytest.raises(InputError, match=r"ISO 100–102400"):
        _cam(iso=50)
    with pytest.raises(InputError, match="no such file and not a built-in sensor"):
        _cam(raw_calibration="/nonexistent/cal.json")
    with pytest.raises(InputError, match="needs a raw sensor"):
        Camera.from_options({"cfa_pattern": "RGGB"})
    with pytest.raises(InputError, match="one medium"):
        _cam(sensor_preset="smartphone")
    with pytest.raises(InputError, match="cfa_pattern='XYZW'"):
        _cam(cfa_pattern="XYZW")


def test_skipped_without_calibration_and_fused_with_exposure():
    frame = Frame(np.ones((3, 3, 3), np.float32))
    assert Pipeline(_cam(raw_calibration=None), stages=["raw"], already_applied=("exposure",)).kernels(frame) == []
    assert Pipeline(_cam()).kernels(frame) == ["exposure__raw"]


# -- raw output (clpost.raw_io) ---------------------------------------------------------------

def test_raw_png_and_tiff_are_16_bit_dn_with_a_sidecar(tmp_path):
    import cv2

    from clpost import raw_io

    cam = _cam(cfa_pattern="GRBG")
    out = _run(cam, np.random.default_rng(2).uniform(0, 0.9, (21, 33, 3)), 4)
    for ext in (".png", ".tif"):
        path = tmp_path / f"raw{ext}"
        raw_io.write_raw(path, out, cam, frame_index=4)
        back = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        assert back.dtype == np.uint16 and back.shape == (21, 33)
        span = A7S2.white_level_dn - A7S2.black_level_dn
        np.testing.assert_array_equal(back, np.round(out[..., 0].astype(np.float64) * span + A7S2.black_level_dn))
        meta = json.loads(raw_io.sidecar_path(path).read_text())
        assert meta["format"] == "clpost-raw/1" and meta["cfa_pattern"] == "GRBG"
        assert (meta["black_level_dn"], meta["white_level_dn"], meta["bits"]) == (512, 16383, 14)
        assert meta["frame_index"] == 4 and meta["iso"] == 800
        cm, wb = np.array(meta["camera_to_srgb"]), np.array(meta["white_balance_gains"])
        np.testing.assert_allclose(cm.sum(axis=1), 1.0, atol=1e-12)  # white stays white
        np.testing.assert_allclose(cm @ (wb[:, None] * camera_matrix(cam)[:3]), np.eye(3), atol=1e-12)
    assert not list(tmp_path.glob(".*tmp*"))


def test_cli_writes_raw_and_refuses_a_raw_jpeg(tmp_path):
    from clpost import exr
    from clpost.cli import main

    exr.write_frame(tmp_path / "a.exr", Frame(np.full((12, 16, 3), 0.1, np.float32)))
    assert main(["process", str(tmp_path / "a.exr"), "-o", str(tmp_path / "a.jpg"), "--raw-calibration",
                 "a7s2-like"]) == 2
    assert not (tmp_path / "a.jpg").exists()
    assert main(["process", str(tmp_path / "a.exr"), "-o", str(tmp_path / "r.png"), "--raw-calibration",
                 "a7s2-like", "--iso", "1600", "--cfa", "BGGR"]) == 0
    meta = json.loads((tmp_path / "r.raw.json").read_text())
    assert meta["cfa_pattern"] == "BGGR" and meta["iso"] == 1600
    from PIL import Image

    assert Image.open(tmp_path / "r.png").mode in ("I;16", "I")


def test_the_pattern_starts_at_the_display_window_with_overscan(tmp_path):
    # overscan of 3 px left and 1 px top: the sensor (display window) still starts with the declared
    # pattern, the kernel and the reference agree, and the written raw's sidecar says that pattern
    from clpost import raw_io
    from clpost.batch import display_window
    from clpost.frame import Windows

    w, h = 20, 12
    win = Windows(((-3, -1), (w - 1 + 2, h - 1)), ((0, 0), (w - 1, h - 1)))
    path = _one_iso(tmp_path, read_noise_dn=0.0)
    cam = _cam(raw_calibration=path, cfa_pattern="GBRG")
    rgb = np.array([0.6, 0.3, 0.1], np.float32)
    frame = Frame(np.broadcast_to(rgb, (h + 1, w + 5, 3)).copy(), metadata={"windows": win, "frame_index": 2})
    pipe = Pipeline(cam, stages=["raw"], already_applied=("exposure",))
    assert_planned(pipe, frame, "raw")
    out = pipe.run(frame)
    ref = pipe.reference(frame)
    assert np.abs(out.color - ref).max() * (A7S2.white_level_dn - A7S2.black_level_dn) <= 1.0 + 1e-3
    sensor = display_window(out).color[..., 0]
    m, ch = camera_matrix(cam), cfa_channels("GBRG")
    for py in range(2):
        for px in range(2):
            assert sensor[py::2, px::2].mean() == pytest.approx(m[ch[py, px]] @ rgb, rel=0.01), (py, px)
    raw_io.write_raw(tmp_path / "o.png", display_window(out).color, cam)
    assert json.loads((tmp_path / "o.raw.json").read_text())["cfa_pattern"] == "GBRG"
