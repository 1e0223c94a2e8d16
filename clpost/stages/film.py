r"""film: normalised sensor signal → developed dye densities of a film stock, per layer.

.. math::

    H = \text{signal}\cdot\frac{78}{S_{cam}}\ \text{lux·s},\qquad
    D_c = \mathcal{D}_c(\log_{10} H)

:math:`\mathcal{D}_c` is the stock's characteristic curve of dye layer c (red-, green-,
blue-sensitive; RGB channel c exposes layer c) — a monotone PCHIP through the datasheet points
(:mod:`clpost.film_stock`), clamped to D_min/D_max outside the data. The kernel looks the curve up
in a ``FILM_LUT_SIZE``-entry table uniform in log10 H (built on the host from the PCHIP, uploaded
as a buffer) with linear interpolation: with 1024 entries over ≤ 14 decades the table error is
< 5e-4 density (3.4e-4 worst, Superia 400; tested against the float64 PCHIP). Each entry packs the
density (20 bits) and the step to the next entry (12 bits, ≥ 0: the curves are monotone) in one
uint (:func:`packed_lut`), so a lane reads one word per layer, not two floats; the packing adds
< 1e-5 density (tested).

Why a table and not a closed form: the datasheet curves are PCHIPs through 30–40 digitised
points whose second derivative jumps at every point; least-squares fits measured against the
float64 PCHIP (Ektar, Gold, Superia) stay above the 5e-4 budget — a global Chebyshev polynomial
of degree 32: 5.4e-4 – 1.7e-3; uniform piecewise cubics with 64 segments (whose coefficients a lane
would have to gather, 4 per layer): 6e-4 – 1.9e-3.

Output: densities (Status M) — the grain stage perturbs them, the print stage turns them into a
viewable image. Domain: signal ≥ 0 (0 → D_min); range [D_min, D_max] per layer, always finite.
Speed: see :mod:`clpost.film_stock` for how ``Camera.iso`` relates to the stock's box speed.
References: Kodak E-4046 (Ektar 100), E-7022 (Gold 200), Fujifilm Superia X-TRA 400 datasheets;
ISO 5800:2001 (colour negative speed).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import InputError
from ..film_stock import load_stock
from ..photometry import SATURATION_EXPOSURE_ISO
from ..params import param, show_none
from .base import PointwiseStage


def _check_film(name, value):
    if value is None:
        return None
    if not isinstance(value, str):
        raise InputError(f"Camera.{name}={value!r} must be a film stock name or a stock .toml path")
    try:
        load_stock(value)
    except InputError as exc:
        raise InputError(f"Camera.{name}: {exc}") from None
    return value


@dataclass(frozen=True)
class FilmParams:
    """film: the negative's stock (``clpost.film_stock.stock_names()`` or a stock .toml path)."""

    film: str | None = param(None, unit="stock", flag="--film", check=_check_film, header="clpost.film",
                             show=show_none, scalar=False,
                             help="film stock: neutral-100, kodak-ektar-100, kodak-gold-200, fuji-superia-400, "
                                  "or a stock .toml")


FILM_LUT_SIZE = 1024


def lut_params(stock):
    lo, hi = stock.log_h_range()
    return lo, hi, (FILM_LUT_SIZE - 1) / (hi - lo)


def log_exposure(camera, signal):
    """log10 H (lux·s) of a normalised signal, float64; 0 maps to -inf (→ D_min)."""
    with np.errstate(divide="ignore"):
        return np.log10(np.asarray(signal, np.float64) * (SATURATION_EXPOSURE_ISO / camera.iso))


@lru_cache(maxsize=16)
def stock_lut(film: str) -> tuple[np.ndarray, float, float]:
    """(lut, lo, inv_step) of a stock: its (3, FILM_LUT_SIZE) float64 table of densities and the
    grid's start and inverse step in log10 H."""
    s = load_stock(film)
    lo, hi, inv = lut_params(s)
    lut = s.lut(FILM_LUT_SIZE, lo, hi)
    lut.setflags(write=False)
    return lut, lo, inv


VALUE_BITS, STEP_BITS = 20, 12


def pack_lut(lut: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(words, dec): a (3, N) monotone table as (3, N) uint32 words ``v << 12 | dv`` and the
    (9,) float32 decoding [offset_c, value scale_c, step scale_c]: entry i of layer c is
    ``v·scale + offset`` and the step to entry i + 1 ``dv·step_scale`` (rounded to nearest: at
    most half a unit of each: an interpolated density is off by at most span/(2·(2²⁰ − 1)) + largest
    step/(2·(2¹² − 1)) — under 1e-5 D for the packaged stocks, ~1e-4 D for a table with a 1 D jump
    between neighbouring entries). Read-only."""
    lut = np.asarray(lut, np.float64)
    off = lut.min(axis=1)
    vs = np.maximum(lut.max(axis=1) - off, 1e-12) / (2 ** VALUE_BITS - 1)
    v = np.rint((lut - off[:, None]) / vs[:, None]).astype(np.uint32)
    step = np.zeros_like(lut)
    step[:, :-1] = np.maximum(np.diff(lut, axis=1), 0.0)
    ds = np.maximum(step.max(axis=1), 1e-12) / (2 ** STEP_BITS - 1)
    dv = np.rint(step / ds[:, None]).astype(np.uint32)
    words = (v << np.uint32(STEP_BITS)) | dv
    dec = np.concatenate([off, vs, ds]).astype(np.float32)
    words.setflags(write=False)
    dec.setflags(write=False)
    return words, dec


def unpack_lut(words: np.ndarray, dec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(values, steps) of :func:`pack_lut`'s words in float64, as the kernel decodes them."""
    d = np.asarray(dec, np.float64)
    v = (words >> np.uint32(STEP_BITS)).astype(np.float64) * d[3:6, None] + d[0:3, None]
    s = (words & np.uint32(2 ** STEP_BITS - 1)).astype(np.float64) * d[6:9, None]
    return v, s


@lru_cache(maxsize=16)
def packed_lut(film: str) -> tuple[np.ndarray, np.ndarray]:
    """:func:`pack_lut` of the stock's table, built once per stock (the pipeline uploads an
    unchanged read-only table once)."""
    return pack_lut(stock_lut(film)[0])


class Film(PointwiseStage):
    name = "film"
    order = 80.0
    role = "the film's response: characteristic curves, exposure → density"
    domains = ("signal", "density")
    requires = ("exposure",)
    params = FilmParams
    args = (("__global const uint *", "lut"), ("__global const float *", "dec"), ("float", "log_offset"),
            ("float", "lo"), ("float", "inv_step"))

    def skip_reason(self, camera, frame):
        return None if camera.film else "no film stock (Camera.film is None)"

    def reason_needed(self, camera, frame):
        s = load_stock(camera.film)
        stops = math.log2(s.iso / camera.iso)
        return (f"{s.title}: characteristic curves, box speed ISO {s.iso:g} rated at ISO {camera.iso:g} "
                f"({stops:+.2f} EV exposure vs box speed)")

    def defines(self, camera):
        return {"FILM_LUT_SIZE": FILM_LUT_SIZE}

    def values(self, camera, frame):
        _, lo, inv = stock_lut(camera.film)
        words, dec = packed_lut(camera.film)
        return (words, dec, np.float32(math.log10(SATURATION_EXPOSURE_ISO / camera.iso)), np.float32(lo),
                np.float32(inv))

    def reference(self, camera, frame, color):
        s = load_stock(camera.film)
        x = log_exposure(camera, color)
        x = np.where(np.isneginf(x), -1e300, x)
        return s.density_at(x)
