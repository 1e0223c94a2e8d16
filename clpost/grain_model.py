r"""Statistics of the Boolean grain model (Newson et al. 2017) — host-side, float64.

A developed dye layer of image density :math:`D` (above D_min) is modelled as a Boolean model of
discs of radius r whose centres form a Poisson process of intensity λ. A point is clear (transmits)
iff no disc covers it, so the mean transmittance is :math:`T = e^{-λπr^2}`; Nutting's relation
:math:`D = -\log_{10}T` then fixes

.. math::

    λ = \frac{D \ln 10}{\pi r^2}.

The clear-indicator has covariance (Serra, *Image Analysis and Mathematical Morphology*, 1982)

.. math::

    C(h) = T^2\left(e^{λ\,γ(h)} - 1\right),\qquad
    γ(h) = 2r^2\arccos\frac{h}{2r} - \frac{h}{2}\sqrt{4r^2 - h^2}\quad (h < 2r),

γ the overlap area of two discs at distance h. A pixel (unit box) averages the indicator; its
variance and the covariance of neighbours are integrals of C against the box overlap —
:func:`pixel_covariance` evaluates them, for the continuous box (``samples_side=None``) or for the
jittered-stratified Monte-Carlo estimator with ``samples_side``² samples that the ``final`` kernel
uses. Selwyn's law (σ_D·√A constant for apertures A ≫ r²) follows from the continuous form.

Granularity of a stock: its *effective* grain radius is calibrated so that the model's diffuse RMS
granularity (σ_D over a 48 µm circular aperture at D = 1, the datasheet convention ×1000) equals
a representative value :math:`G = 4\sqrt{S/100}` — fine-grain ISO 100 colour negatives quote
≈ 4, and granularity grows with the square root of speed (grain area ∝ speed). These are
representative numbers, not read from the three datasheets here.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

LN10 = math.log(10.0)


def overlap_area(h, r):
    """γ(h): area shared by two discs of radius r at centre distance h (0 beyond 2r)."""
    h = np.minimum(np.abs(np.asarray(h, np.float64)), 2 * r)
    return 2 * r * r * np.arccos(h / (2 * r)) - 0.5 * h * np.sqrt(np.maximum(4 * r * r - h * h, 0.0))


def covariance(h, d_img, r):
    """C(h) of the clear-indicator at image density ``d_img`` (broadcasts)."""
    lam = np.asarray(d_img, np.float64) * LN10 / (math.pi * r * r)
    t = 10.0 ** -np.asarray(d_img, np.float64)
    return t * t * np.expm1(lam * overlap_area(h, r))


def pixel_covariance(d_img, r_px: float, lag=(0, 0), samples_side: int | None = None, n_quad: int = 64):
    r"""Covariance of two pixels' clear fractions at offset ``lag`` (pixels), per ``d_img``.

    Continuous box: :math:`\iint C(h)\,(1-|h_x-l_x|)_+(1-|h_y-l_y|)_+\,dh`, by a midpoint rule on
    the support |h| < 2r. Monte Carlo estimator with n×n jittered strata: the mean of C over all
    sample pairs, jitter averaged with ``n_quad`` Sobol-like pairs.
    """
    d = np.atleast_1d(np.asarray(d_img, np.float64))
    if samples_side is None:
        m = 96
        edge = np.linspace(-2 * r_px, 2 * r_px, m + 1)
        c = 0.5 * (edge[1:] + edge[:-1])
        hx, hy = np.meshgrid(c, c, indexing="ij")
        wgt = np.clip(1 - np.abs(hx + lag[0]), 0, None) * np.clip(1 - np.abs(hy + lag[1]), 0, None)
        cov = covariance(np.hypot(hx, hy)[None], d[:, None, None], r_px)
        return (cov * wgt[None]).sum(axis=(1, 2)) * (edge[1] - edge[0]) ** 2
    n = samples_side
    rng = np.random.default_rng(12345)  # fixed quadrature nodes: deterministic statistics
    j = rng.random((n_quad, 4))
    total = np.zeros_like(d)
    for di in range(-(n - 1), n):
        for dj in range(-(n - 1), n):
            mult = (n - abs(di)) * (n - abs(dj))
            same = di == 0 and dj == 0 and lag == (0, 0)
            if same:
                total += mult * covariance(0.0, d, r_px)
                continue
            hx = (di + j[:, 0] - j[:, 1]) / n + lag[0]
            hy = (dj + j[:, 2] - j[:, 3]) / n + lag[1]
            total += mult * covariance(np.hypot(hx, hy)[None], d[:, None], r_px).mean(axis=1)
    return total / float(n ** 4)


def rms_granularity(r_um: float, d_img: float = 1.0) -> float:
    """Model σ_D ×1000 over a 48 µm diameter circular aperture (A ≫ r², Selwyn limit)."""
    h = np.linspace(0, 2 * r_um, 4001)[1:]
    dh = h[1] - h[0]
    integral = float((covariance(h - dh / 2, d_img, r_um) * 2 * math.pi * (h - dh / 2)).sum() * dh)
    area = math.pi * 24.0 ** 2
    sigma_t = math.sqrt(integral / area)
    t = 10.0 ** -d_img
    return 1000.0 * sigma_t / (t * LN10)


@lru_cache(maxsize=None)
def grain_radius_um(iso: float) -> float:
    """Effective grain radius (µm) giving representative RMS granularity 4·√(S/100) at D = 1."""
    target = 4.0 * math.sqrt(iso / 100.0)
    # σ_D ∝ r for apertures ≫ r (Selwyn): one evaluation fixes the scale.
    return target / rms_granularity(1.0)
