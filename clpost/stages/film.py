r"""film: normalised sensor signal → developed dye densities of a film stock, per layer.

.. math::

    H = \text{signal}\cdot\frac{78}{S_{cam}}\ \text{lux·s},\qquad
    D_c = \mathcal{D}_c(\log_{10} H)

:math:`\mathcal{D}_c` is the stock's characteristic curve of dye layer c (red-, green-,
blue-sensitive; RGB channel c exposes layer c) — a monotone PCHIP through the datasheet points
(:mod:`clpost.film_stock`), clamped to D_min/D_max outside the data. The kernel looks the curve up
in a ``FILM_LUT_SIZE``-entry table uniform in log10 H (built on the host from the PCHIP, uploaded
as a buffer) with linear interpolation: with 1024 entries over ≤ 14 decades the table error is
< 5e-4 density (3.4e-4 worst, Superia 400; tested against the float64 PCHIP).

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
    """(lut, lo, inv_step) of a stock: its (3, FILM_LUT_SIZE) float32 table (read-only, built once
    per stock — the pipeline uploads an unchanged read-only table once) and the grid's start and
    inverse step in log10 H."""
    s = load_stock(film)
    lo, hi, inv = lut_params(s)
    lut = s.lut(FILM_LUT_SIZE, lo, hi).astype(np.float32)
    lut.setflags(write=False)
    return lut, lo, inv


class Film(PointwiseStage):
    name = "film"
    order = 80.0
    role = "the film's response: characteristic curves, exposure → density"
    domains = ("signal", "density")
    requires = ("exposure",)
    params = FilmParams
    args = (("__global const float *", "lut"), ("float", "log_offset"), ("float", "lo"),
            ("float", "inv_step"))

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
        lut, lo, inv = stock_lut(camera.film)
        return (lut, np.float32(math.log10(SATURATION_EXPOSURE_ISO / camera.iso)), np.float32(lo),
                np.float32(inv))

    def reference(self, camera, frame, color):
        s = load_stock(camera.film)
        x = log_exposure(camera, color)
        x = np.where(np.isneginf(x), -1e300, x)
        return s.density_at(x)
