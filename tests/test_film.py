"""film: datasheet curves round-trip, ISO speed from the curves, kernel vs float64 PCHIP, clamping."""
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from clpost import Camera, Frame, Pipeline
from clpost.errors import InputError
from clpost.film_stock import FilmStock, film_data_dir, load_stock, stock_names
from clpost.stages.film import FILM_LUT_SIZE, lut_params

from conftest import assert_planned

DATASHEET = ["kodak-ektar-100", "kodak-gold-200", "fuji-superia-400"]


def test_stocks_are_listed_with_provenance():
    assert set(DATASHEET) | {"neutral-100"} == set(stock_names())
    for name in DATASHEET:
        s = load_stock(name)
        assert "Entropy512/rgb_led_filmscan" in s.provenance and s.kind == "negative"


@pytest.mark.parametrize("name", DATASHEET)
def test_curves_round_trip_their_datasheet_points(name):
    s = load_stock(name)
    worst = []
    for c in range(3):
        x = np.asarray(s.log_h[c])
        got = s.density_at(np.stack([x] * 3, -1))[:, c]
        np.testing.assert_allclose(got, s.density[c], atol=1e-12)  # exact through the cleaned points
        raw = s.density_at(np.stack([s.datasheet_log_h[c]] * 3, -1))[:, c]
        err = np.abs(raw - s.datasheet_density[c])
        worst.append((err.max(), c, int(err.argmax())))
    e, c, i = max(worst)
    # Only the digitiser's non-monotone wiggles are smoothed away (pool-adjacent-violators).
    assert e < 0.02, f"{name}: raw datasheet point {i} of layer {c} is {e:.4f} D off the curve"


@pytest.mark.parametrize("name", DATASHEET)
def test_curves_are_monotone_and_stored_in_order(name):
    s = load_stock(name)
    x = np.linspace(*s.log_h_range(), 2000)
    d = s.density_at(np.stack([x] * 3, -1))
    assert np.all(np.diff(d, axis=0) >= -1e-12)
    np.testing.assert_allclose(d[0], s.d_min())
    np.testing.assert_allclose(d[-1], s.d_max())


@pytest.mark.parametrize("name", DATASHEET)
def test_iso5800_speed_of_the_curves_is_near_box_speed(name):
    # ISO 5800: S = 0.8 / H_m at D_min + 0.10 of the green layer. Datasheet curves are plotted for
    # the stock's process; the digitised ones give box speed within half a stop.
    s = load_stock(name)
    assert abs(math.log2(s.iso_speed() / s.iso)) < 0.5


def test_parametric_stock_puts_the_speed_point_on_box_speed_and_slope_gamma():
    s = FilmStock.parametric("p", 250.0, gamma=(0.5, 0.6, 0.7), d_min=(0.1, 0.2, 0.3), d_max=(2.0, 2.5, 3.0))
    assert s.iso_speed() == pytest.approx(250.0, rel=0.01)
    gam, _ = s.straight_line()
    np.testing.assert_allclose(gam, [0.5, 0.6, 0.7], rtol=0.05)  # fit over the ≥80 %-slope part


def test_lut_matches_pchip_everywhere():
    for name in stock_names():
        s = load_stock(name)
        lo, hi, _ = lut_params(s)
        x = np.linspace(lo - 1, hi + 1, 20011)
        lut = s.lut(FILM_LUT_SIZE, lo, hi)
        for c in range(3):
            approx = np.interp(x, np.linspace(lo, hi, FILM_LUT_SIZE), lut[c])
            exact = s.density_at(np.stack([x] * 3, -1))[:, c]
            assert np.abs(approx - exact).max() < 5e-4, name


def _film_cam(stock="kodak-ektar-100", **kw):
    return Camera(f_number=2.8, shutter_s=1 / 125, iso=100, luminance_scale=1.0, film=stock,
                  film_output="negative", grain_amount=0.0, **kw)


@pytest.mark.parametrize("stock", ["kodak-gold-200", "neutral-100"])
def test_kernel_matches_reference_odd_size_random_and_adversarial(rng, stock):
    h, w = 23, 37
    c = (10.0 ** rng.uniform(-7, 9, (h, w, 3))).astype(np.float32)
    adversarial = np.array([0.0, 1e-45, 1e-38, 1e-6, 1.0, 1e4, 1e8, 3e38], np.float32)
    c.reshape(-1)[: adversarial.size] = adversarial
    frame = Frame(c)
    pipe = Pipeline(_film_cam(stock))
    assert_planned(pipe, frame, "exposure", "film")
    assert pipe.kernels(frame) == ["exposure__film"]
    out, ref = pipe.run(frame).color, pipe.reference(frame)
    assert out.dtype == np.float32 and np.isfinite(out).all()
    err = np.abs(out - ref)
    y, x, ch = np.unravel_index(int(err.argmax()), err.shape)
    assert err.max() < 5e-4, f"worst {err.max():.2e} D at (x={x}, y={y}, c={ch}), input {c[y, x, ch]:g}"


def test_luminance_extremes_clamp_to_dmin_dmax_without_nan():
    s = load_stock("fuji-superia-400")
    lum = np.array([0.0, 1e-6, 1e-3, 1.0, 1e3, 1e6, 1e8], np.float32)
    frame = Frame(np.repeat(lum[None, :, None], 3, axis=2))
    for out_mode in ("negative", "print", "linear"):
        cam = _film_cam("fuji-superia-400").with_(film_output=out_mode, grain_size=1.0)
        out = Pipeline(cam).run(frame).color[0]
        assert np.isfinite(out).all(), out_mode
        if out_mode == "negative":
            np.testing.assert_allclose(out[0], s.d_min(), atol=1e-3)   # no light: fog + base
            np.testing.assert_allclose(out[-1], s.d_max(), atol=1e-3)  # far past the shoulder
            assert np.all(np.diff(out, axis=0) >= -1e-2)               # monotone up to grain


def test_film_and_sensor_are_exclusive_and_names_are_checked(tmp_path):
    with pytest.raises(InputError, match="one medium"):
        Camera(film="kodak-ektar-100", sensor_preset="smartphone")
    with pytest.raises(InputError, match="kodak-ektar-100"):
        Camera(film="kodak-ektra-100")
    bad = tmp_path / "bad.toml"
    bad.write_text('iso = 100\n[red]\nlog_h = [0, 1]\ndensity = [1, 0]\n')
    with pytest.raises(InputError, match="must not decrease"):
        load_stock(str(bad))
    with pytest.raises(InputError, match="film_output"):
        Camera(film="neutral-100", film_output="slide")


def test_custom_parametric_toml_stock(tmp_path):
    p = tmp_path / "mine.toml"
    p.write_text('name = "mine"\niso = 50\n[parametric]\ngamma = 0.7\nd_min = [0.1, 0.3, 0.5]\nd_max = 2.8\n')
    s = load_stock(str(p))
    assert s.iso_speed() == pytest.approx(50, rel=0.01)
    np.testing.assert_allclose(s.d_min(), [0.1, 0.3, 0.5], atol=3e-3)  # stored toe starts 0.1 % of the range up
    assert Pipeline(Camera(film=str(p), luminance_scale=1.0)).plan(Frame(np.ones((3, 3, 3), np.float32)))[:2] == ["exposure", "film"]


def test_camera_iso_is_metering_not_the_film():
    # The film sees physical exposure H: the same scene and settings give the same densities
    # whatever Camera.iso (which only normalises the signal and steers the meter).
    frame = Frame(np.full((2, 3, 3), 40.0, np.float32))
    a = Pipeline(_film_cam()).run(frame).color
    b = Pipeline(_film_cam().with_(iso=400)).run(frame).color
    np.testing.assert_allclose(a, b, atol=2e-4)


def test_packaged_stock_files_parse_and_are_in_package_data():
    pyproject = tomllib.loads((Path(__file__).parent.parent / "pyproject.toml").read_text())
    assert "*.toml" in pyproject["tool"]["setuptools"]["package-data"]["clpost.lens_data.film"]
    files = sorted(film_data_dir().glob("*.toml"))
    assert len(files) >= 3, f"film stocks missing from {film_data_dir()}"  # also in the installed wheel (CI)
    for f in files:
        assert tomllib.loads(f.read_text())["name"] == f.stem


def test_packed_table_decodes_to_the_table_within_1e_5():
    from clpost.stages.film import FILM_LUT_SIZE, pack_lut, packed_lut, stock_lut, unpack_lut

    for name in stock_names():
        lut = stock_lut(name)[0]
        v, step = unpack_lut(*packed_lut(name))
        assert np.abs(v - lut).max() < 1e-5, name
        # value + step reaches the next entry, so the interpolation is continuous within 1e-5
        assert np.abs(v[:, :-1] + step[:, :-1] - lut[:, 1:]).max() < 1e-5, name
        assert packed_lut(name)[0].shape == (3, FILM_LUT_SIZE) and packed_lut(name)[0].dtype == np.uint32
    flat = np.zeros((3, 8))  # a constant layer (range 0) decodes to itself
    np.testing.assert_allclose(unpack_lut(*pack_lut(flat))[0], flat, atol=1e-12)
