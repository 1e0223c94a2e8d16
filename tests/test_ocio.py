"""OpenColorIO displays: previews equal OCIO's own CPU processor (built here independently of
clpost's pipeline) to 1e-4 on held-out HDR images for several display/view pairs and a look; the
input space from EXR chromaticities agrees with OCIO's named colour spaces and with colour-science;
ICC/cICP tags; options and bad names in one line."""
import math
import warnings

import numpy as np
import pytest

ocio = pytest.importorskip("PyOpenColorIO")

from clpost import exr  # noqa: E402
from clpost import ocio as O  # noqa: E402
from clpost.cli import main  # noqa: E402
from clpost.display_image import encode_display, icc_profile  # noqa: E402
from clpost.errors import InputError  # noqa: E402

CONFIG = "ocio://studio-config-latest"
AP0 = (0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.077, 0.32168, 0.33767)
AP1 = (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767)
ODD = (0.66, 0.33, 0.25, 0.70, 0.15, 0.05, 0.31, 0.33)  # no colour space of the config has these

PAIRS = [  # (display, view, looks)
    ("sRGB - Display", "ACES 2.0 - SDR 100 nits (Rec.709)", ""),
    ("Display P3 - Display", "ACES 2.0 - SDR 100 nits (P3 D65)", ""),
    ("Rec.2100-PQ - Display", "ACES 2.0 - HDR 1000 nits (P3 D65)", ""),
    ("sRGB - Display", "Un-tone-mapped", ""),
    ("sRGB - Display", "ACES 2.0 - SDR 100 nits (Rec.709)", "ACES 1.3 Reference Gamut Compression"),
]


def held_out_image(seed: int, h=29, w=41) -> np.ndarray:
    """HDR scene-linear values: a log-uniform spread over 2^-12 … 2^10, saturated colours,
    black, small negatives (out of gamut) — not the values any clpost code was tuned on."""
    rng = np.random.default_rng(seed)
    img = 2.0 ** rng.uniform(-12, 10, (h, w, 3))
    img[::5] *= rng.random((1, w, 3)) ** 4  # saturated
    img[0, :4] = 0.0
    img[1, :4] = [-0.01, 0.5, 2.0]
    img[2, :4] = 1000.0
    return img.astype(np.float32)


def ocio_reference(src: str, display: str, view: str, looks: str, img: np.ndarray) -> np.ndarray:
    """OCIO's CPU processor for src → [looks] → display/view, assembled here as a GroupTransform
    (not LegacyViewingPipeline as clpost does)."""
    cfg = ocio.Config.CreateFromFile(CONFIG)
    group = ocio.GroupTransform()
    if looks:
        group.appendTransform(ocio.LookTransform(src=src, dst=src, looks=looks))
    group.appendTransform(ocio.DisplayViewTransform(src=src, display=display, view=view))
    out = img.reshape(-1, 3).copy()
    cfg.getProcessor(group).getDefaultCPUProcessor().applyRGB(out)
    return out.reshape(img.shape)


@pytest.mark.parametrize("display,view,looks", PAIRS)
@pytest.mark.parametrize("chroma,src", [(AP0, "ACES2065-1"), (AP1, "ACEScg")])
def test_preview_equals_ocio_cpu_processor(display, view, looks, chroma, src):
    img = held_out_image(hash((display, view, looks, src)) % 1000)
    v = O.OcioView.resolve(CONFIG, display, view, looks)
    assert v.source_space("rec709", chroma).name == src  # the file's chromaticities, by name
    got = v.encode(img, "rec709", chroma)
    want = ocio_reference(src, display, view, looks, img)
    assert np.all(np.isfinite(want))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-4)
    codes, _, _ = encode_display(img, v, "rec709", chroma)  # what a PNG holds
    assert np.max(np.abs(codes.astype(int) - np.round(np.clip(want, 0, 1) * 255))) == 0


def test_the_look_and_the_view_change_the_image():
    img = held_out_image(3)
    base = O.OcioView.resolve(CONFIG, *PAIRS[0][:2]).encode(img, "acescg")
    look = O.OcioView.resolve(CONFIG, *PAIRS[4]).encode(img, "acescg")
    raw = O.OcioView.resolve(CONFIG, "sRGB - Display", "Un-tone-mapped").encode(img, "acescg")
    assert np.max(np.abs(look - base)) > 1e-3 and np.max(np.abs(raw - base)) > 1e-2


def test_working_space_and_flag_choose_the_input_space():
    v = O.OcioView.resolve(CONFIG)
    assert v.display == "sRGB - Display" and v.view.startswith("ACES 2")  # the config's defaults
    assert v.source_space("rec709").name == "Linear Rec.709 (sRGB)"
    assert v.source_space("acescg").name == "ACEScg"
    flagged = O.OcioView.resolve(CONFIG, input_colorspace="Linear P3-D65")
    s = flagged.source_space("rec709", AP0)  # the flag wins over the file
    assert s.name == "Linear P3-D65" and s.source == "--input-colorspace"


def test_unmatched_chromaticities_become_a_matrix_equal_to_colour_science():
    import colour

    v = O.OcioView.resolve(CONFIG, "sRGB - Display", "ACES 2.0 - SDR 100 nits (Rec.709)")
    s = v.source_space("rec709", ODD)
    assert s.matrix is not None and s.name == "ACEScg"  # the config's scene_linear
    # colour-science's own conversion (Bradford) from ODD to ACEScg, then OCIO's ACEScg view
    odd = colour.RGB_Colourspace("odd", np.reshape(ODD[:6], (3, 2)), ODD[6:])
    img = held_out_image(11)
    acescg = colour.RGB_to_RGB(img.astype(np.float64), odd, colour.RGB_COLOURSPACES["ACEScg"],
                               chromatic_adaptation_transform="Bradford").astype(np.float32)
    want = ocio_reference("ACEScg", v.display, v.view, "", acescg)
    np.testing.assert_allclose(v.encode(img, "rec709", ODD), want, rtol=0, atol=1e-4)
    # and the named match: AP0 chromaticities → the config's ACES2065-1 equals colour-science's matrix
    m_cfg = dict(O._linear_spaces(CONFIG))["ACES2065-1"]
    np.testing.assert_allclose(m_cfg, O.rgb_to_xyz_d65(AP0), atol=O.MATCH_TOL)


def test_display_tags():
    srgb = O.OcioView.resolve(CONFIG, "sRGB - Display", "ACES 2.0 - SDR 100 nits (Rec.709)")
    assert O.display_tags(srgb) == ("srgb", (1, 13, 0, 1))
    p3 = O.OcioView.resolve(CONFIG, "Display P3 - Display", "Un-tone-mapped")
    assert O.display_tags(p3) == ("display-p3", (12, 13, 0, 1))
    g22 = O.OcioView.resolve(CONFIG, "Gamma 2.2 Rec.709 - Display", "Un-tone-mapped")
    assert O.display_tags(g22) == ("gamma22-rec709", (1, 4, 0, 1))
    assert icc_profile("gamma22-rec709")[36:40] == b"acsp"
    pq = O.OcioView.resolve(CONFIG, "Rec.2100-PQ - Display", "ACES 2.0 - HDR 1000 nits (P3 D65)")
    assert O.display_tags(pq) == (None, (9, 16, 0, 1))
    hlg = O.OcioView.resolve(CONFIG, "Rec.2100-HLG - Display", "Un-tone-mapped")
    with pytest.warns(UserWarning, match="written untagged"):
        assert O.display_tags(hlg) == (None, None)


def test_gamma22_icc_matches_littlecms():
    from io import BytesIO

    from PIL import ImageCms

    prof = ImageCms.ImageCmsProfile(BytesIO(icc_profile("gamma22-rec709")))
    assert "gamma 2.2" in ImageCms.getProfileDescription(prof)


def _aces_exr(path, chroma=AP0):
    import OpenEXR

    img = held_out_image(5, 12, 16)
    ch = {"R": img[..., 0].copy(), "G": img[..., 1].copy(), "B": img[..., 2].copy()}
    hdr = {"compression": OpenEXR.ZIP_COMPRESSION}
    if chroma is not None:
        hdr["chromaticities"] = tuple(chroma)
    OpenEXR.File(hdr, ch).write(str(path))
    return img


def _png(path):
    from PIL import Image

    data = path.read_bytes()
    cicp = data.find(b"cICP")
    return np.asarray(Image.open(path).convert("RGB")), (tuple(data[cicp + 4:cicp + 8]) if cicp > 0 else None), \
        Image.open(path).info.get("icc_profile")


def test_cli_png_preview_is_ocio(tmp_path, monkeypatch):
    monkeypatch.delenv("OCIO", raising=False)
    img = _aces_exr(tmp_path / "in.exr")
    assert O.file_chromaticities(tmp_path / "in.exr") == pytest.approx(AP0, abs=1e-6)
    args = ["process", tmp_path / "in.exr", "-o", tmp_path / "out.exr", "--quiet", "--stages", "exposure",
            "--f-number", "2", "--preview", tmp_path / "prev", "--ocio-config", CONFIG,
            "--display", "Display P3 - Display", "--ocio-view", "ACES 2.0 - SDR 100 nits (P3 D65)"]
    assert main([str(a) for a in args]) == 0
    codes, cicp, icc = _png(tmp_path / "prev" / "out.png")
    want = ocio_reference("ACES2065-1", "Display P3 - Display", "ACES 2.0 - SDR 100 nits (P3 D65)", "", img)
    assert np.max(np.abs(codes.astype(int) - np.round(np.clip(want, 0, 1) * 255))) == 0
    assert cicp == (12, 13, 0, 1) and icc == icc_profile("display-p3")
    # the EXR output stays linear and unchanged (passthrough exposure)
    np.testing.assert_array_equal(exr.read_frame(tmp_path / "out.exr").color, img)


def test_ocio_env_and_none(tmp_path, monkeypatch, capsys):
    img = _aces_exr(tmp_path / "in.exr", chroma=None)  # no chromaticities: the working space
    monkeypatch.setenv("OCIO", CONFIG)
    base = ["process", tmp_path / "in.exr", "--quiet", "--stages", "exposure", "--f-number", "2"]
    assert main([str(a) for a in base + ["-o", tmp_path / "env.png"]]) == 0
    codes, cicp, _ = _png(tmp_path / "env.png")
    want = ocio_reference("Linear Rec.709 (sRGB)", "sRGB - Display", "ACES 2.0 - SDR 100 nits (Rec.709)", "", img)
    assert np.max(np.abs(codes.astype(int) - np.round(np.clip(want, 0, 1) * 255))) == 0
    assert cicp == (1, 13, 0, 1)
    # --ocio-config none: clpost's own sRGB encoding, as before
    assert main([str(a) for a in base + ["-o", tmp_path / "own.png", "--ocio-config", "none"]]) == 0
    from clpost.colorspace import display_encode

    codes, cicp, icc = _png(tmp_path / "own.png")
    np.testing.assert_array_equal(codes, display_encode(img, "rec709", "srgb"))
    assert cicp == (1, 13, 0, 1) and icc == icc_profile("srgb")
    # with $OCIO, a clpost encoding name is not a display of the config: one line with the choices
    assert main([str(a) for a in base + ["-o", tmp_path / "x.png", "--display", "display-p3"]]) == 2
    err = capsys.readouterr().err
    assert "is not a display of the OCIO config" in err and "'sRGB - Display'" in err and err.count("\n") == 1


@pytest.mark.parametrize("extra,msg", [
    (["--ocio-config", "/nonexistent/config.ocio"], "no such file"),
    (["--ocio-config", CONFIG, "--display", "nope"], "is not a display of the OCIO config"),
    (["--ocio-config", CONFIG, "--ocio-view", "nope"], "is not a view of display 'sRGB - Display'"),
    (["--ocio-config", CONFIG, "--look", "nope"], "is not a look of the OCIO config"),
    (["--ocio-config", CONFIG, "--input-colorspace", "nope"], "is not a colour space of the OCIO config"),
    (["--ocio-view", "Raw"], "needs an OpenColorIO config"),
    (["--display", "Display P3 - Display"], "is not one of clpost's encodings"),
])
def test_bad_names_are_one_line(tmp_path, monkeypatch, capsys, extra, msg):
    monkeypatch.delenv("OCIO", raising=False)
    _aces_exr(tmp_path / "in.exr")
    args = ["process", tmp_path / "in.exr", "-o", tmp_path / "o.png", "--quiet", "--stages", "exposure",
            "--f-number", "2", *extra]
    assert main([str(a) for a in args]) == 2
    err = capsys.readouterr().err
    assert msg in err and err.count("\n") == 1, err
    assert not (tmp_path / "o.png").exists()


def test_bad_chromaticities_are_refused():
    with pytest.raises(InputError, match="degenerate"):
        O.rgb_to_xyz_d65((0.3, 0.3, 0.3, 0.3, 0.3, 0.3, 0.3127, 0.329))
    with pytest.raises(InputError, match="8 finite numbers"):
        O.rgb_to_xyz_d65((0.3, math.nan, 0, 0, 0, 0, 0, 0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert O.file_chromaticities(None) is None


def test_explain_names_the_view_and_input_space(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("OCIO", raising=False)
    _aces_exr(tmp_path / "in.exr", chroma=ODD)
    args = ["process", tmp_path / "in.exr", "-o", tmp_path / "o.png", "--stages", "exposure", "--f-number", "2",
            "--ocio-config", CONFIG, "--explain"]
    assert main([str(a) for a in args]) == 0
    out = capsys.readouterr().out
    assert ("display-referred outputs: OCIO sRGB - Display / ACES 2.0 - SDR 100 nits (Rec.709)" in out
            and "input colour space 'ACEScg' via a matrix from the chromaticities (from the input's chromaticities)"
            in out), out
