"""The OpenEXR project's sample images: every valid file reads, goes through ``clpost process``
and comes back with its windows and its pixels where they were (tests/data/openexr-images/,
README there; the whole corpus when ``CLPOST_OPENEXR_IMAGES`` names a checkout of it)."""
import os
from pathlib import Path

import numpy as np
import OpenEXR
import pytest

from clpost import exr
from clpost.cli import main
from clpost.errors import InputError
from clpost.exr import yca
from clpost.exr.deep import flatten

DATA = Path(__file__).parent / "data" / "openexr-images"
NAN_FILES = {"AllHalfValues.exr", "BrightRingsNanInf.exr"}
"""Files with NaN pixels: refused in one line (NaN is never valid input)."""


def _files(root: Path) -> list[Path]:
    return sorted(p for p in root.rglob("*.exr") if "Damaged" not in p.parts)


def _valid(root: Path) -> list[Path]:
    return [p for p in _files(root) if p.name not in NAN_FILES]


def _union_data_window(path: Path, view_parts=None):
    heads = exr.read_header(path)
    wins = [h.data_window for h in heads]
    return ((min(w[0][0] for w in wins), min(w[0][1] for w in wins)),
            (max(w[1][0] for w in wins), max(w[1][1] for w in wins))), heads[0].display_window


def _process_round_trip(src: Path, tmp_path: Path, capsys) -> None:
    """``clpost process`` with a planned pointwise stage (--ev -1: gain ½, so the plan is not
    empty and no value overflows) writes the input's windows back, every pixel halved in place."""
    out = tmp_path / (src.stem + "_out.exr")
    assert main(["process", str(src), "-o", str(out), "--ev", "-1", "--quiet"]) == 0, capsys.readouterr().err
    got, want = exr.read_frame(out), exr.read_frame(src)
    head_in, head_out = exr.read_header(src)[0], exr.read_header(out)[0]
    assert head_out.display_window == head_in.display_window
    assert head_out.data_window == want.windows.data  # the union of the parts' data windows
    assert got.windows == want.windows and got.size == want.size
    np.testing.assert_allclose(got.color, want.color * np.float32(0.5), rtol=1e-6, atol=0)
    if want.alpha is not None:
        np.testing.assert_array_equal(got.alpha, want.alpha)


@pytest.mark.parametrize("src", _valid(DATA), ids=lambda p: f"{p.parent.name}/{p.name}")
def test_every_vendored_file_processes_and_round_trips_its_windows(src, tmp_path, capsys):
    _process_round_trip(src, tmp_path, capsys)


@pytest.mark.parametrize("name", sorted(NAN_FILES))
def test_nan_files_are_refused_in_one_line(name, tmp_path, capsys):
    src = DATA / "TestImages" / name
    assert main(["process", str(src), "-o", str(tmp_path / "o.exr"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert name in err and "NaN" in err and "\n" not in err
    assert not (tmp_path / "o.exr").exists()


@pytest.mark.skipif(not os.environ.get("CLPOST_OPENEXR_IMAGES"),
                    reason="set CLPOST_OPENEXR_IMAGES to a checkout of AcademySoftwareFoundation/openexr-images")
@pytest.mark.slow
def test_the_whole_corpus(tmp_path, capsys):
    root = Path(os.environ["CLPOST_OPENEXR_IMAGES"])
    files = _valid(root)
    assert len(files) >= 60, f"{root}: expected the OpenEXR sample images, found {len(files)} files"
    for src in files:
        _process_round_trip(src, tmp_path, capsys)
        for p in tmp_path.iterdir():
            p.unlink()


def test_display_window_files_place_the_same_pixels_where_their_data_windows_say():
    """The DisplayWindow files hold the same 400×300 pixels at different data windows: each
    frame's pixels at its data window equal t01's, and outside it there is no data."""
    ref = exr.read_frame(DATA / "DisplayWindow" / "t01.exr").color
    for src in sorted((DATA / "DisplayWindow").glob("t*.exr")):
        f = exr.read_frame(src)
        (x0, y0), (x1, y1) = f.windows.data
        ox, oy = f.windows.origin
        np.testing.assert_array_equal(f.color[y0 - oy:y1 - oy + 1, x0 - ox:x1 - ox + 1], ref, err_msg=src.name)
        if f.alpha is not None:
            inside = np.zeros(f.alpha.shape, bool)
            inside[y0 - oy:y1 - oy + 1, x0 - ox:x1 - ox + 1] = True
            assert np.all(f.alpha[inside] == 1) and np.all(f.alpha[~inside] == 0), src.name
    t09 = exr.read_frame(DATA / "DisplayWindow" / "t09.exr")  # apart: data (0,0)-(399,299), display (400,0)-(599,299)
    assert t09.size == (600, 300) and t09.windows.display_offset == (400, 0)


def test_luminance_chroma_matches_the_rgb_image_it_was_made_from():
    """Rec709_YC.exr is Rec709.exr encoded as Y + 2×2 subsampled chroma: the reconstruction
    (OpenEXR's RgbaInputFile algorithm) gives it back to the chroma subsampling's loss."""
    yc = exr.read_frame(DATA / "Chromaticities" / "Rec709_YC.exr").color.astype(np.float64)
    rgb = exr.read_frame(DATA / "Chromaticities" / "Rec709.exr").color.astype(np.float64)
    w = yca.luminance_weights()
    assert np.abs(yc @ w - rgb @ w).mean() < 1e-3  # luminance is stored at full resolution (half)
    err = np.abs(yc - rgb)
    assert err.mean() < 0.01 and np.median(err) < 0.003, (err.mean(), np.median(err))
    assert np.abs(yc.mean(axis=(0, 1)) - rgb.mean(axis=(0, 1))).max() < 2e-3


def test_luminance_weights_are_the_y_row_of_the_primaries_matrix():
    import colour

    m = yca.rgb_to_xyz()
    want = colour.normalised_primary_matrix(np.array([[0.64, 0.33], [0.30, 0.60], [0.15, 0.06]]),
                                            np.array([0.3127, 0.3290]))
    np.testing.assert_allclose(m, want, atol=1e-12)
    np.testing.assert_allclose(yca.luminance_weights(), want[1] / want[1].sum(), atol=1e-12)
    # XYZ "primaries" (a y of 0) work as in Imath: Y weights (0, 1, 0)
    np.testing.assert_allclose(yca.luminance_weights((1, 0, 0, 1, 0, 0, 1 / 3, 1 / 3)), [0, 1, 0], atol=1e-12)
    with pytest.raises(InputError, match="collinear"):
        yca.rgb_to_xyz((0.2, 0.2, 0.3, 0.3, 0.4, 0.4, 0.3127, 0.329))


def test_yc_reconstruction_is_exact_for_grey_and_for_a_flat_colour():
    rng = np.random.default_rng(3)
    y = rng.uniform(0.1, 4.0, (10, 14)).astype(np.float16).astype(np.float32)
    zero = np.zeros((5, 7), np.float32)
    rgb = yca.yca_to_rgb(y, zero, zero)
    for c in range(3):
        np.testing.assert_array_equal(rgb[..., c], y)  # chroma 0: R = G = B = Y exactly
    r, g, b = 0.8, 0.5, 0.2
    wr, wg, wb = yca.luminance_weights()
    lum = wr * r + wg * g + wb * b
    ry, by = (r - lum) / lum, (b - lum) / lum
    flat = yca.yca_to_rgb(np.full((10, 14), lum, np.float32), np.full((5, 7), ry, np.float32),
                          np.full((5, 7), by, np.float32))
    np.testing.assert_allclose(flat, np.broadcast_to([r, g, b], flat.shape), rtol=3e-3)


def test_luminance_only_and_single_channel_files_are_grey():
    for rel in ("LuminanceChroma/Garden.exr", "TestImages/GrayRampsHorizontal.exr", "TestImages/WideFloatRange.exr"):
        f = exr.read_frame(DATA / rel)
        np.testing.assert_array_equal(f.color[..., 0], f.color[..., 1])
        np.testing.assert_array_equal(f.color[..., 2], f.color[..., 1])
    raw = OpenEXR.File(str(DATA / "TestImages/WideFloatRange.exr"), separate_channels=True).parts[0].channels["G"].pixels
    np.testing.assert_array_equal(exr.read_frame(DATA / "TestImages/WideFloatRange.exr").color[..., 1], raw)


def test_multi_view_reads_the_default_view_or_the_one_named(tmp_path, capsys):
    src = DATA / "MultiView" / "Fog.exr"
    planes = OpenEXR.File(str(src), separate_channels=True).parts[0].channels
    left, right = exr.read_frame(src), exr.read_frame(src, view="right")
    assert left.metadata["view"] == "left" and right.metadata["view"] == "right"
    np.testing.assert_array_equal(left.color[..., 0], planes["Y"].pixels.astype(np.float32))
    np.testing.assert_array_equal(right.color[..., 0], planes["right.Y"].pixels.astype(np.float32))
    assert not np.array_equal(left.color, right.color)
    with pytest.raises(InputError, match=r"Fog\.exr: --view centre: the file's views are left, right"):
        exr.read_frame(src, view="centre")
    with pytest.raises(InputError, match="no views"):
        exr.read_frame(DATA / "TestImages" / "stripes.exr", view="left")
    out = tmp_path / "r.exr"
    assert main(["process", str(src), "-o", str(out), "--view", "right", "--quiet"]) == 0
    np.testing.assert_array_equal(exr.read_frame(out).color, right.color)


def _flatten_one_pixel(samples: dict[str, np.ndarray]) -> dict[str, float]:
    """Front-to-back *over* of one pixel's samples, a plain loop (the oracle of the flattening)."""
    order = np.argsort(samples["Z"], kind="stable")
    out = {c: 0.0 for c in "RGBA"}
    t = 1.0
    for i in order:
        for c in "RGBA":
            out[c] += t * float(samples[c][i])
        t *= 1.0 - min(max(float(samples["A"][i]), 0.0), 1.0)
    out["Z"] = float(samples["Z"][order[0]]) if len(order) else np.inf
    return out


def test_deep_images_are_flattened_front_to_back():
    src = DATA / "v2" / "LowResLeftView" / "Trunks.exr"
    part = OpenEXR.File(str(src), separate_channels=True).parts[0]
    deep = {k: v.pixels for k, v in part.channels.items()}
    flat = flatten(deep)
    counts = np.vectorize(lambda a: 0 if a is None else len(a), otypes=[int])(deep["A"])
    assert counts.max() > 1  # pixels with several samples are there to composite
    rng = np.random.default_rng(5)
    picks = list(zip(*np.nonzero(counts > 1)))
    for j, i in [picks[k] for k in rng.choice(len(picks), 200, replace=False)] + [tuple(np.argwhere(counts == 0)[0])]:
        want = _flatten_one_pixel({c: np.asarray(deep[c][j, i] if counts[j, i] else [], np.float64) for c in deep})
        for c in "RGBAZ":
            assert flat[c][j, i] == pytest.approx(want[c], rel=1e-6, abs=1e-7), (c, j, i)
    f = exr.read_frame(src)
    assert f.windows.data == ((0, 141), (1023, 575)) and f.size == (1024, 576)
    assert np.all(np.isinf(f.depth[:141])) and np.all(f.alpha[:141] == 0)


def test_tiled_mip_maps_read_level_0():
    f = exr.read_frame(DATA / "MultiResolution" / "ColorCodedLevels.exr")
    assert f.size == (512, 512)
