r"""RGB from luminance/chroma (``Y``, ``RY``, ``BY``) and luminance-only (``Y``) OpenEXR images.

OpenEXR stores "luminance/chroma" images (``RgbaOutputFile`` with ``WRITE_YC``) as full-resolution
luminance and chroma subsampled 2 × 2 (OpenEXR technical introduction, "Luminance/Chroma Images";
``ImfRgbaYca.h``). Luminance is a weighted sum of the file's RGB, chroma two ratios:

.. math::

    Y = w_R R + w_G G + w_B B, \qquad RY = \frac{R - Y}{Y}, \qquad BY = \frac{B - Y}{Y}

with the weights :math:`w` the Y row of the RGB → XYZ matrix of the file's ``chromaticities``
(Rec. ITU-R BT.709 primaries and D65 when the attribute is absent), normalised to sum 1
(``computeYw``). Reading inverts this as ``RgbaInputFile`` does (``ImfRgbaFile.cpp``,
``FromYca::readPixels``, and ``ImfRgbaYca.cpp``; OpenEXR 3.x, BSD-3-Clause), step by step with
the values rounded to half where OpenEXR stores them:

1. chroma samples sit at even columns of even rows; the odd columns of an even row are filled by
   the symmetric 14-tap filter :data:`CHROMA_TAPS` over the samples at odd distances ±1, ±3, …,
   ±13 (``reconstructChromaHoriz``; the row is extended by its first sample on the left and by
   its last on the right);
2. odd rows take the same filter vertically over the even rows at odd distances
   (``reconstructChromaVert``; rows beyond the image repeat the first / last even row);
3. :math:`R = (RY + 1) Y,\ B = (BY + 1) Y,\ G = (Y - w_R R - w_B B)/w_G`; where both chroma values
   are 0, R = G = B = Y exactly (``YCAtoRGBA``);
4. a pixel much more saturated than its four diagonal neighbours is desaturated towards its
   brightest channel, keeping Y (``fixSaturation``: saturation s = 1 − min/max; the pixel is
   scaled to s_max = 1 − (1 − s̄)/4 when above it, s̄ the neighbours' mean, capped at 1).

A ``Y``-only file is grey, R = G = B = Y (``RgbaInputFile::readPixels``). (The reader also takes
a file with one lone R, G or B channel as grey — a monochrome image; OpenEXR's RGBA interface
and Nuke would show it in that channel alone.)

The RGB that comes out is in the file's primaries (its ``chromaticities``), which the reader
records in ``Frame.metadata["chromaticities"]``.
"""
from __future__ import annotations

import numpy as np

from ..errors import InputError

REC709_CHROMATICITIES = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)
"""(red x, y, green x, y, blue x, y, white x, y): OpenEXR's default (Rec. 709 primaries, D65)."""

CHROMA_TAPS = (0.627123, -0.186077, 0.087929, -0.043159, 0.019597, -0.007540, 0.002128)
"""Weights of the chroma samples at distances ±1, ±3, … ±13 px (``ImfRgbaYca.cpp``,
``reconstructChromaHoriz``/``Vert``: a 27-pixel windowed sinc, every other tap zero)."""


def rgb_to_xyz(chromaticities=REC709_CHROMATICITIES) -> np.ndarray:
    r"""3 × 3 matrix M with XYZ = M · RGB for RGB of the given primaries and white, normalised so
    that RGB = (1, 1, 1) has Y = 1 (SMPTE RP 177-1993): the columns are the primaries'
    (x, y, 1 − x − y) scaled by S = P⁻¹ W, W the white's XYZ at Y = 1 — in this form (Imath's
    ``RGBtoXYZ``) a primary may have y = 0, as the XYZ "primaries" (1, 0), (0, 1), (0, 0) do."""
    rx, ry, gx, gy, bx, by, wx, wy = (float(c) for c in chromaticities)
    bad = f"chromaticities {tuple(round(float(c), 6) for c in chromaticities)}"
    if not wy > 0:
        raise InputError(f"{bad}: the white point's y is not > 0; the file's chromaticities attribute is "
                         "invalid — fix or remove it")
    p = np.array([[x, y, 1 - x - y] for x, y in ((rx, ry), (gx, gy), (bx, by))]).T
    w = np.array([wx / wy, 1.0, (1 - wx - wy) / wy])
    if abs(np.linalg.det(p)) < 1e-12:
        raise InputError(f"{bad}: the primaries are collinear; the file's chromaticities attribute is "
                         "invalid — fix or remove it")
    return p * np.linalg.solve(p, w)[None, :]


def luminance_weights(chromaticities=REC709_CHROMATICITIES) -> np.ndarray:
    """(w_R, w_G, w_B): the Y row of :func:`rgb_to_xyz`, divided by its sum (``computeYw``)."""
    y = rgb_to_xyz(chromaticities)[1]
    return y / y.sum()


def _half(a: np.ndarray) -> np.ndarray:
    """float32 values rounded to half, as OpenEXR's ``Rgba`` buffers store them."""
    return a.astype(np.float16).astype(np.float32)


def _odd_fill(c: np.ndarray, axis: int, m: np.ndarray) -> np.ndarray:
    """The samples halfway between sample m and m + 1 of ``c`` along ``axis``:
    Σ_k t_k (c[m − k] + c[m + 1 + k]), indices clamped to ``c``'s ends (the padding of steps 1
    and 2 of the module docstring)."""
    n = c.shape[axis]
    out = 0.0
    for k, t in enumerate(CHROMA_TAPS):
        lo = np.take(c, np.clip(m - k, 0, n - 1), axis=axis)
        hi = np.take(c, np.clip(m + 1 + k, 0, n - 1), axis=axis)
        out = out + np.float32(t) * (lo + hi)
    return np.asarray(out, np.float32)


def _upsample(c: np.ndarray, width: int, rows: np.ndarray) -> np.ndarray:
    """Full-resolution chroma of the image rows ``rows`` (which may lie one beyond the image)
    from the 2 × 2 subsampled plane ``c`` (steps 1 and 2)."""
    c = np.asarray(c, np.float32)
    h2, w2 = c.shape
    even = np.empty((h2, 2 * w2), np.float32)
    even[:, 0::2] = c
    even[:, 1::2] = _half(_odd_fill(c, 1, np.arange(w2)))
    even = even[:, :width]
    n = rows // 2  # even row 2n; odd row 2n + 1 lies between even rows n and n + 1
    odd = _half(_odd_fill(even, 0, n))
    return np.where((rows % 2 == 0)[:, None], even[np.clip(n, 0, h2 - 1)], odd)


def _saturation(rgb: np.ndarray) -> np.ndarray:
    mx, mn = rgb.max(axis=-1), rgb.min(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(mx > 0, 1 - mn / np.where(mx > 0, mx, 1), 0.0).astype(np.float32)


def _fix_saturation(rgb: np.ndarray, yw: np.ndarray) -> np.ndarray:
    """Step 4 on rows 1 … n−2 of ``rgb`` (n + 2 rows: one virtual row above and below)."""
    s = _saturation(rgb)
    w = s.shape[1]
    left, right = np.clip(np.arange(w) - 1, 0, w - 1), np.clip(np.arange(w) + 1, 0, w - 1)
    mean = np.minimum(1.0, 0.25 * (s[:-2][:, left] + s[:-2][:, right] + s[2:][:, left] + s[2:][:, right]))
    mid, s_mid = rgb[1:-1], s[1:-1]
    s_max = np.minimum(1.0, 1 - (1 - mean) * 0.25)
    fix = (s_mid > mean) & (s_mid > s_max)
    if not fix.any():
        return mid
    f = np.where(fix, s_max / np.where(fix, s_mid, 1), 1.0).astype(np.float32)[..., None]
    mx = mid.max(axis=-1, keepdims=True)
    out = np.maximum(mx - (mx - mid) * f, 0.0)
    y_in, y_out = mid @ yw.astype(np.float32), out @ yw.astype(np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where((y_out > 0)[..., None], out * (y_in / np.where(y_out > 0, y_out, 1))[..., None], out)
    return np.where(fix[..., None], _half(out.astype(np.float32)), mid)


def yca_to_rgb(y: np.ndarray, ry: np.ndarray, by: np.ndarray,
               chromaticities=REC709_CHROMATICITIES) -> np.ndarray:
    """(H, W, 3) float32 RGB of a luminance/chroma image: ``y`` (H, W) full resolution, ``ry`` and
    ``by`` (⌈H/2⌉, ⌈W/2⌉) sampled at the even columns of the even rows (see the module docstring)."""
    y = np.asarray(y, np.float32)
    h, w = y.shape
    rows = np.arange(-1, h + 1)  # a virtual row above and below for step 4
    # OpenEXR reads the line above the image as the first line and the one below as the last
    # even line (ImfRgbaFile.cpp, readYCAScanLine)
    yrows = y[np.where(rows < 0, 0, np.where(rows > h - 1, max(h - 2, 0), rows))]
    cr, cb = _upsample(ry, w, rows), _upsample(by, w, rows)
    yw = luminance_weights(chromaticities).astype(np.float32)
    r = _half((cr + 1) * yrows)
    b = _half((cb + 1) * yrows)
    g = _half((yrows - r * yw[0] - b * yw[2]) / yw[1])
    grey = (cr == 0) & (cb == 0)
    rgb = np.stack([np.where(grey, yrows, r), np.where(grey, yrows, g), np.where(grey, yrows, b)], -1)
    return _fix_saturation(rgb.astype(np.float32), yw)
