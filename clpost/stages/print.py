r"""print: the developed negative → a viewable image (display-referred print or re-linearised).

Negative film must be printed (or scanned and inverted) to be seen; ``Camera.film_output`` picks:

``print`` — a colour paper print, display-referred (1.0 = paper white). The paper sees the light
through the negative, :math:`\log_{10} H_p = c_c - D_c` (printer light :math:`c_c` per
channel), and responds with a logistic characteristic curve of a representative RA-4 paper
(γ_p = 2.0, density range 2.2 above paper base; *representative*, not a measured paper):

.. math::

    D_p = \frac{\Delta D_p}{1 + e^{-k(c_c - D_c)}},\quad k = \frac{4\gamma_p}{\Delta D_p},\qquad
    \text{out}_c = 10^{-D_p}

The printer lights are set as an automatic printer sets them: a metered mid-grey (the exposure
the TTL meter aims at, :math:`H_g = \pi T_m K/(4S)`, :func:`clpost.photometry.metered_grey_exposure`)
prints as 18 % reflectance, neutral in every channel. The printer sees only the negative: the
print is a function of the exposure H alone, never of the lens (T) or shutter that made it. System contrast is γ_neg·γ_p ≈ 1.1–1.4 in the mid-tones; the paper's toe and
shoulder roll off highlights and shadows.

``linear`` — re-linearised scene-linear, as a scanner's "linear" inversion: each layer's
straight-line fit :math:`D = γ_c\log_{10}H + b_c` is inverted,
:math:`\text{out}_c = 10^{(D_c - b_c)/γ_c}\cdot S/78` (sensor-signal units), so exposures on
the straight line come back unchanged and the film's toe and shoulder compression remain.

``negative`` — this stage is skipped; the output is the densities.

Range: print in (10^-2.2, 1]; linear > 0, finite. References: Hunt, *The Reproduction of Colour*,
6th ed., ch. 13 (negative–positive systems); ISO 2720 (K = 12.5).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..film_stock import load_stock
from ..photometry import SATURATION_EXPOSURE_ISO, metered_grey_exposure
from ..params import one_of, param
from .base import PointwiseStage, per_camera


@dataclass(frozen=True)
class PrintParams:
    """print: what a negative film stage outputs."""

    film_output: str = param("print", unit="mode", flag="--film-output", check=one_of("print", "linear", "negative"),
                             header="clpost.filmOutput", scalar=False,
                             help="negative film output: print (display-referred paper print), linear "
                                  "(re-linearised scene-linear), negative (the densities)")


PAPER_GAMMA = 2.0
PAPER_RANGE = 2.2
GREY_REFLECTANCE = 0.18
MODES = {"print": 0, "linear": 1}


def print_params(camera) -> np.ndarray:
    """(9,) float64: per channel (a_c, b_c) and the shared (k, range, mode-independent scale).

    print: a = printer light c_c, b unused; linear: a = b_c intercept, b = 1/γ_c.
    Layout: [a0, a1, a2, b0, b1, b2, k, range, scale]."""
    stock = load_stock(camera.film)
    if camera.film_output == "print":
        k = 4 * PAPER_GAMMA / PAPER_RANGE
        h_grey = metered_grey_exposure(camera.iso)  # the negative's grey, whatever lens made it
        d_grey = stock.density_at(np.full(3, math.log10(h_grey)))
        f = -math.log10(GREY_REFLECTANCE) / PAPER_RANGE
        x = math.log(f / (1 - f)) / k
        a = d_grey + x
        return np.concatenate([a, np.zeros(3), [k, PAPER_RANGE, 1.0]])
    gam, icp = stock.straight_line()
    return np.concatenate([icp, 1.0 / gam, [0.0, 0.0, camera.iso / SATURATION_EXPOSURE_ISO]])


class Print(PointwiseStage):
    name = "print"
    order = 95.0
    role = "negative → paper print (or re-linearised), the last step"
    domains = ("density", "print")
    requires = ("film",)
    params = PrintParams
    args = (("__global const float *", "params"),)

    def skip_reason(self, camera, frame):
        if not camera.film:
            return "no film stock (Camera.film is None)"
        if camera.film_output == "negative":
            return "Camera.film_output='negative': the densities are the output"
        return None

    def reason_needed(self, camera, frame):
        if camera.film_output == "print":
            return f"paper print (γ {PAPER_GAMMA:g}, range {PAPER_RANGE:g} D), grey → 18 %, display-referred"
        return "re-linearised through each layer's straight-line fit (scene-linear signal units)"

    def defines(self, camera):
        return {"PRINT_MODE": MODES.get(camera.film_output, 0)}

    @per_camera
    def _table(self, camera) -> np.ndarray:
        return print_params(camera).astype(np.float32)

    def values(self, camera, frame):
        return (self._table(camera),)

    def reference(self, camera, frame, color):
        p = print_params(camera)
        d = np.asarray(color, np.float64)
        a, b = p[0:3], p[3:6]
        if camera.film_output == "print":
            k, rng = p[6], p[7]
            dp = rng / (1 + np.exp(-k * (a - d)))
            return 10.0 ** (-dp)
        return 10.0 ** ((d - a) * b) * p[8]
