"""Colour: working spaces and preview encodings come from colour-science; conversions are exact."""
import colour
import numpy as np
import pytest

from clpost import Camera
from clpost.colorspace import DISPLAYS, display_encode, working_to_display_linear
from clpost.errors import InputError


@pytest.mark.parametrize("display", list(DISPLAYS))
def test_white_and_black_encode_to_the_ends(display):
    img = np.array([[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]])
    np.testing.assert_array_equal(display_encode(img, "rec709", display), [[[0, 0, 0], [255, 255, 255]]])


def test_srgb_mid_grey_uses_the_piecewise_curve():
    # IEC 61966-2-1: 0.18 linear → 0.4614 → code 118
    assert display_encode(np.full((1, 1, 3), 0.18))[0, 0, 0] == 118
    # BT.709 OETF: 0.18 → 0.409 → code 104
    assert display_encode(np.full((1, 1, 3), 0.18), display="rec709")[0, 0, 0] == 104


def test_rec709_red_sits_inside_p3_and_acescg_matches_colour_science(rng):
    p3 = working_to_display_linear(np.array([1.0, 0.0, 0.0]), "rec709", "display-p3")
    assert np.all(p3 >= 0) and np.all(p3 <= 1) and p3[0] < 1  # a smaller gamut maps inside
    x = rng.random((5, 7, 3))
    ref = colour.RGB_to_RGB(x, colour.RGB_COLOURSPACES["ACEScg"], colour.RGB_COLOURSPACES["sRGB"],
                            chromatic_adaptation_transform="Bradford")
    np.testing.assert_allclose(working_to_display_linear(x, "acescg", "srgb"), ref, rtol=1e-12)
    # neutral stays neutral (white adaptation ACES ≈ D60 → D65)
    g = working_to_display_linear(np.array([0.5, 0.5, 0.5]), "acescg", "srgb")
    np.testing.assert_allclose(g, 0.5, atol=2e-3)


def test_bad_names_are_refused():
    with pytest.raises(InputError, match="display"):
        working_to_display_linear(np.zeros(3), "rec709", "p3")
    with pytest.raises(InputError, match="working_space"):
        Camera(working_space="aces")
