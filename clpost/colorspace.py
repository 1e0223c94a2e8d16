"""Colour helpers, all matrices and transfer functions from colour-science (nothing hand-typed).

The working space is linear Rec.709/sRGB primaries with a D65 white (CONVENTIONS.md).
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


def encode_preview(signal: np.ndarray, encoding: str = "sRGB", bits: int = 8) -> np.ndarray:
    """Display-encode a linear image for a PNG preview: clip to [0, 1], apply the encoding's
    inverse-EOTF/OETF (colour.cctf_encoding), quantise to ``bits`` (8 or 16)."""
    import colour

    x = np.clip(np.asarray(signal, dtype=np.float64), 0.0, 1.0)
    enc = colour.cctf_encoding(x, function=encoding)
    scale = (1 << bits) - 1
    dtype = np.uint8 if bits == 8 else np.uint16
    return np.round(enc * scale).astype(dtype)
