"""Viewable outputs: display encoding of a known value, embedded ICC profiles checked against
LittleCMS, extensions, previews beside the EXR, and an unknown extension refused."""
import io

import numpy as np
import pytest

from clpost import Frame, exr
from clpost.cli import main
from clpost.display_image import icc_profile, output_format, write_image


def _lin_to_code(v, fn="sRGB"):
    import colour

    return int(np.round(colour.cctf_encoding(v, function=fn) * 255))


@pytest.mark.parametrize("ext", ["png", "jpg", "tif"])
def test_known_value_is_encoded_and_the_profile_embedded(tmp_path, ext):
    from PIL import Image, ImageCms

    path = tmp_path / f"grey.{ext}"
    write_image(path, np.full((6, 8, 3), 0.18, np.float32))
    im = Image.open(path)
    assert im.format == {"png": "PNG", "jpg": "JPEG", "tif": "TIFF"}[ext] and im.mode == "RGB"
    # IEC 61966-2-1: 0.18 → 0.4614 → 118 of 255
    assert _lin_to_code(0.18) == 118
    assert im.getpixel((3, 3)) == (118, 118, 118)
    prof = ImageCms.ImageCmsProfile(io.BytesIO(im.info["icc_profile"]))
    assert "sRGB" in ImageCms.getProfileDescription(prof)


def test_p3_profile_agrees_with_colour_science_through_littlecms():
    import colour
    from PIL import Image, ImageCms

    codes = np.array([[[200, 100, 50], [30, 180, 90], [128, 128, 128], [255, 0, 0]]], np.uint8)
    p3 = ImageCms.ImageCmsProfile(io.BytesIO(icc_profile("display-p3")))
    t = ImageCms.buildTransform(p3, ImageCms.createProfile("sRGB"), "RGB", "RGB",
                                renderingIntent=ImageCms.Intent.RELATIVE_COLORIMETRIC)
    got = np.asarray(ImageCms.applyTransform(Image.fromarray(codes), t)).astype(float)
    lin = colour.cctf_decoding(codes / 255.0, "sRGB")
    srgb = colour.RGB_to_RGB(lin, colour.RGB_COLOURSPACES["Display P3"], colour.RGB_COLOURSPACES["sRGB"],
                             chromatic_adaptation_transform="Bradford")
    want = colour.cctf_encoding(np.clip(srgb, 0, 1), "sRGB") * 255
    assert np.abs(got - want).max() <= 1.0  # one code value (8-bit rounding in LittleCMS)
    # and our sRGB profile is an identity against LittleCMS's built-in sRGB
    ours = ImageCms.ImageCmsProfile(io.BytesIO(icc_profile("srgb")))
    t2 = ImageCms.buildTransform(ours, ImageCms.createProfile("sRGB"), "RGB", "RGB",
                                 renderingIntent=ImageCms.Intent.RELATIVE_COLORIMETRIC)
    same = np.asarray(ImageCms.applyTransform(Image.fromarray(codes), t2)).astype(int)
    assert np.abs(same - codes).max() <= 1


def test_display_p3_png_is_encoded_in_p3(tmp_path):
    from PIL import Image

    red = np.zeros((2, 2, 3), np.float32)
    red[..., 0] = 1.0  # Rec.709 red lies inside P3: less than full P3 red, some green
    write_image(tmp_path / "r.png", red, display="display-p3")
    px = Image.open(tmp_path / "r.png").getpixel((0, 0))
    assert px[0] < 255 and px[1] > 50 and "Display P3" in Image.open(tmp_path / "r.png").info["icc_profile"].decode("latin1")


def test_output_format_by_extension():
    assert output_format("a.EXR") == "EXR" and output_format("b.####.png") == "PNG"
    assert output_format("c.jpeg") == "JPEG" and output_format("d.tiff") == "TIFF"
    from clpost import InputError

    with pytest.raises(InputError, match=r"unknown extension '\.bmp'"):
        output_format("x.bmp")


def _plate(tmp_path, value=0.18):
    src = tmp_path / "plate.exr"
    exr.write_frame(src, Frame(np.full((8, 12, 3), value, np.float32)))
    return src


def test_cli_unknown_extension_is_one_line_exit_2_and_nothing_written(tmp_path, capsys):
    src = _plate(tmp_path)
    assert main(["process", str(src), "-o", str(tmp_path / "out.xyz")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("clpost: error: -o ") and ".xyz" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plate.exr"]


def test_cli_png_output_and_previews_beside_the_exr(tmp_path, capsys):
    from PIL import Image

    src = _plate(tmp_path)
    assert main(["process", str(src), "-o", str(tmp_path / "out.png"), "--quiet"]) == 0
    im = Image.open(tmp_path / "out.png")
    assert im.format == "PNG" and im.getpixel((0, 0)) == (118, 118, 118) and "icc_profile" in im.info
    assert main(["process", str(src), "-o", str(tmp_path / "cam.exr"), "--preview", str(tmp_path / "pv"),
                 "--display", "display-p3", "--quiet"]) == 0
    assert exr.info(tmp_path / "cam.exr") is not None
    pv = Image.open(tmp_path / "pv" / "cam.png")
    assert pv.format == "PNG" and b"Display P3" in pv.info["icc_profile"]
    # the EXR stays linear and passthrough: the plate's values exactly
    np.testing.assert_array_equal(exr.read_frame(tmp_path / "cam.exr").color, np.full((8, 12, 3), 0.18, np.float32))


def test_cli_warnings_are_one_line(tmp_path, capsys):
    src = _plate(tmp_path, 200.0)
    assert main(["process", str(src), "-o", str(tmp_path / "p.exr"), "--quiet"]) == 0
    assert not capsys.readouterr().err.strip()  # passthrough: the plate's exposure is the user's
    assert main(["process", str(src), "-o", str(tmp_path / "o.exr"), "--quiet", "--luminance-scale", "100",
                 "--shutter", "1/15"]) == 0
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert err and all(ln.startswith("clpost: warning: ") for ln in err), err
    assert "above mid-grey" in err[0] and "--ev -" in err[0] and ".py" not in err[0]


@pytest.mark.slow
def test_cli_previews_on_a_local_dask_cluster(tmp_path):
    from PIL import Image

    src = _plate(tmp_path)
    assert main(["process", str(src), "-o", str(tmp_path / "cam.exr"), "--preview", str(tmp_path / "pv"),
                 "--workers", "1", "--quiet"]) == 0
    assert Image.open(tmp_path / "pv" / "cam.png").getpixel((0, 0)) == (118, 118, 118)
