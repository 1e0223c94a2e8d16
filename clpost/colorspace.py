"""Colour helpers, all matrices and transfer functions from colour-science (nothing hand-typed).

The working space is linear Rec.709/sRGB primaries with a D65 white (CONVENTIONS.md); ACEScg
(AP1 primaries, ACES white ≈ D60) is selectable with ``Camera.working_space = "acescg"``.
Preview encodings (:data:`DISPLAYS`): sRGB (IEC 61966-2-1 piecewise curve), Rec.709 (the BT.709
OETF) and Display P3 (P3 primaries, D65, the sRGB curve). Conversions between primaries use
colour-science's RGB_to_RGB with Bradford chromatic adaptation (the white of ACEScg differs).
EXR outputs stay linear in the working space; only previews are display-encoded.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

WORKING_SPACE = "ITU-R BT.709"


@lru_cache(maxsize=None)
def luminance_weights(space: str = WORKING_SPACE) -> np.ndarray:
    """Row Y of the space's RGB→XYZ matrix: Y = w · (R, G, B)."""
    import colour

    return np.asarray(colour.RGB_COLOURSPACES[space].matrix_RGB_to_XYZ[1], dtype=np.float64)


def luminance(rgb: np.ndarray, space: str = WORKING_SPACE) -> np.ndarray:
    """Relative luminance Y of linear RGB (..., 3), float64."""
    return np.asarray(rgb, dtype=np.float64) @ luminance_weights(space)


def cctf_encode(linear: np.ndarray, function: str = "sRGB") -> np.ndarray:
    """Clip a linear image to [0, 1] and apply a display encoding (colour.cctf_encoding), float64."""
    import colour

    return colour.cctf_encoding(np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0), function=function)


def quantise(encoded: np.ndarray, bits: int = 8) -> np.ndarray:
    """Code values in [0, 1] → uint8 or uint16."""
    scale = (1 << bits) - 1
    return np.round(encoded * scale).astype(np.uint8 if bits == 8 else np.uint16)


WORKING_SPACES = {"rec709": "ITU-R BT.709", "acescg": "ACEScg"}
"""Camera.working_space → colour-science colourspace name."""

DISPLAYS = {
    # name: (colour-science colourspace for the primaries/white, colour.cctf_encoding function)
    "srgb": ("sRGB", "sRGB"),
    "rec709": ("ITU-R BT.709", "ITU-R BT.709"),
    "display-p3": ("Display P3", "sRGB"),
}


def working_to_display_linear(rgb: np.ndarray, working_space: str = "rec709",
                              display: str = "srgb") -> np.ndarray:
    """Linear working-space RGB → linear RGB in the display's primaries (float64, unclipped)."""
    import colour

    if working_space not in WORKING_SPACES:
        from .errors import InputError

        raise InputError(f"working space {working_space!r} is unknown: use one of {', '.join(WORKING_SPACES)}")
    if display not in DISPLAYS:
        from .errors import InputError

        raise InputError(f"display {display!r} is unknown: use one of {', '.join(DISPLAYS)}")
    src = colour.RGB_COLOURSPACES[WORKING_SPACES[working_space]]
    dst = colour.RGB_COLOURSPACES[DISPLAYS[display][0]]
    x = np.asarray(rgb, dtype=np.float64)
    if src.name == dst.name:
        return x
    return colour.RGB_to_RGB(x, src, dst, chromatic_adaptation_transform="Bradford")


def display_encode(signal: np.ndarray, working_space: str = "rec709", display: str = "srgb",
                   bits: int = 8) -> np.ndarray:
    """Working-space linear image (1.0 = display white) → display code values (uint8/16):
    convert primaries, clip to [0, 1], apply the display's encoding, quantise."""
    return quantise(cctf_encode(working_to_display_linear(signal, working_space, display),
                                DISPLAYS[display][1]), bits)
