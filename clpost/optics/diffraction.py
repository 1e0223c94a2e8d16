r"""Diffraction by the bladed aperture, and veiling glare: the point-spread functions of the glare stage.

**Fraunhofer PSF.** The image of a point is the squared modulus of the Fourier transform of the
pupil P (Goodman, *Introduction to Fourier Optics*, 3rd ed., §4.2 and §6.2):

.. math::

    \mathrm{PSF}(x) \propto \Big|\int P(\xi)\,e^{-2\pi i\,\xi\cdot x/(\lambda f)}\,d\xi\Big|^2 .

With the pupil's diameter D sampled by Q points of an M × M grid, the discrete transform's image
spacing is :math:`(Q/M)\,\lambda N` (N = f/D the working f-number): every aperture has one unit
PSF in units of λN (:func:`unit_psf`, computed once per shape), and a wavelength and f-number
only rescale it. The pupil is the DoF stage's aperture shape (blades, rotation, roundness;
:func:`clpost.stages.dof.aperture_radius`) with a 1-sample coverage ramp at its edge. Checks
(tests): a round pupil's first dark ring at :math:`1.2197\,\lambda N` (Airy), and an N-bladed
aperture's 2N spikes for odd N and N for even N (opposite edges are parallel for even N, so
their spikes coincide).

**On pixels.** :func:`pixel_psf` integrates the unit PSF over square pixels of pitch p (box
integration on the summed-area table, bilinear at fractional pixel edges), centred on the
kernel's middle pixel, and normalises it to 1 over its window (the light diffracted beyond
:math:`Q\lambda N/2` from the source — a fraction of order :math:`2/(\pi^2 Q)` for a round pupil —
is put back into the window).

**Veiling glare.** Light scattered by the lens's surfaces, barrel and coatings spreads a fraction
g of every point's flux over the whole frame. Model: the two-dimensional Cauchy density

.. math::

    K_g(r) = \frac{r_0}{2\pi\,(r^2 + r_0^2)^{3/2}},\qquad \int_{\mathbb R^2} K_g = 1,

a long-tailed kernel (∝ r⁻³ far out, the fall-off measured for lens glare spread functions,
e.g. McCann & Rizzi, *The Art and Science of HDR Imaging*, 2012, ch. 10), with g the veiling
glare index of ISO 9358 (about 0.5–3 % for modern multicoated lenses). Sampled at pixel centres
and normalised to 1 over the convolution's window.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

AIRY_FIRST_ZERO = 1.2196698912665045
"""First zero of the Airy pattern in units of λN: j₁,₁/π."""
PUPIL_SAMPLES = {"draft": 256, "preview": 512, "final": 1024}
"""Q: samples across the pupil (the FFT is 2Q × 2Q; the kernel spans Q λN)."""


def pupil(q: int, m: int, blades: int, rotation_deg: float, roundness: float) -> np.ndarray:
    """(m, m) float64 aperture of diameter q samples, centred at (m/2, m/2), coverage ramp 1 sample."""
    from ..stages.dof import aperture_radius

    y, x = (np.mgrid[0:m, 0:m] - m / 2).astype(np.float64)
    rho = aperture_radius(np.arctan2(y, x), blades, rotation_deg, roundness)
    return np.clip(0.5 * q * rho - np.hypot(x, y) + 0.5, 0.0, 1.0)


def unit_amplitude(q: int, m: int, blades: int, rotation_deg: float, roundness: float) -> np.ndarray:
    """(m, m) complex amplitude FFT(pupil) with the pupil's centre at sample 0 (real for a
    centrosymmetric pupil), frequencies in numpy's order (zero first)."""
    return np.fft.fft2(np.fft.ifftshift(pupil(q, m, blades, rotation_deg, roundness)))


@lru_cache(maxsize=8)
def unit_psf(q: int, blades: int, rotation_deg: float, roundness: float, oversample: int = 2) -> np.ndarray:
    """(m, m) PSF of the aperture, m = oversample·q, centred at (m/2, m/2), sum 1; sample spacing
    λN/oversample (module docstring)."""
    m = oversample * q
    amp = unit_amplitude(q, m, blades, rotation_deg, roundness)
    psf = np.fft.fftshift(amp.real ** 2 + amp.imag ** 2)
    psf /= psf.sum()
    psf.setflags(write=False)
    return psf


def pixel_psf(psf: np.ndarray, spacing_ln: float, pitch_ln: float) -> np.ndarray:
    """Integrate a centred PSF sampled every ``spacing_ln`` (units of λN) over pixels of
    ``pitch_ln`` (λN): (k, k) float64, k odd, centred, sum 1."""
    m = psf.shape[0]
    half_extent = (m / 2 - 1) * spacing_ln  # the samples' reach from the centre
    k = max(1, int(2 * math.floor(half_extent / pitch_ln - 0.5) + 1))
    sat = np.zeros((m + 1, m + 1))
    sat[1:, 1:] = psf.cumsum(0).cumsum(1)  # sat[i, j] = sum of psf[:i, :j]
    # pixel edges in sample-edge coordinates: sample j covers [j, j+1); the centre sample m/2's
    # centre is at m/2 + 0.5
    edges = m / 2 + 0.5 + (np.arange(k + 1) - k / 2) * (pitch_ln / spacing_ln)
    edges = np.clip(edges, 0.0, m)

    def interp_sat(ei, ej):
        i0 = np.clip(np.floor(ei).astype(int), 0, m - 1)
        j0 = np.clip(np.floor(ej).astype(int), 0, m - 1)
        fi, fj = (ei - i0)[:, None], (ej - j0)[None, :]
        s = sat
        return ((1 - fi) * (1 - fj) * s[np.ix_(i0, j0)] + fi * (1 - fj) * s[np.ix_(i0 + 1, j0)]
                + (1 - fi) * fj * s[np.ix_(i0, j0 + 1)] + fi * fj * s[np.ix_(i0 + 1, j0 + 1)])

    big = interp_sat(edges, edges)
    out = big[1:, 1:] - big[:-1, 1:] - big[1:, :-1] + big[:-1, :-1]
    out = np.maximum(out, 0.0)
    return out / out.sum()


def cauchy_kernel(shape: tuple[int, int], r0_px: float) -> np.ndarray:
    """The veiling-glare kernel K_g on an (h, w) grid centred at (0, 0) with wrap-around, sum 1."""
    h, w = shape
    y = np.fft.fftfreq(h, 1.0 / h)[:, None]
    x = np.fft.fftfreq(w, 1.0 / w)[None, :]
    k = r0_px / (2 * math.pi * (x * x + y * y + r0_px * r0_px) ** 1.5)
    return k / k.sum()


def embed_centred(kernel: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A centred odd (k, k) kernel placed on an (h, w) grid with its centre at (0, 0), wrapping."""
    out = np.zeros(shape)
    k = kernel.shape[0]
    r = k // 2
    idx = (np.arange(k) - r)
    out[np.ix_(idx % shape[0], idx % shape[1])] += kernel
    return out


def airy_first_zero(q: int = 128, oversample: int = 8) -> float:
    """First zero (units of λN) of a round pupil's amplitude along x, where the real amplitude
    changes sign (linear between samples)."""
    a = unit_amplitude(q, oversample * q, 0, 0.0, 0.0).real[0, : oversample * q // 2]
    i = int(np.argmax(np.sign(a[1:]) != np.sign(a[:-1])))
    return (i + a[i] / (a[i] - a[i + 1])) / oversample


def spike_count(psf: np.ndarray, r1: float, r2: float, samples: int = 720) -> int:
    """Number of spikes of a centred PSF: local maxima above 20 % of the largest in its angular
    profile, the PSF × r³ summed over the band r1..r2 samples (the sum washes out the rings)."""
    m = psf.shape[0]
    phi = (np.arange(samples) + 0.5) * 2 * math.pi / samples
    rs = np.linspace(r1, r2, 200)[:, None]
    x = np.round(m / 2 + rs * np.cos(phi)).astype(int)
    y = np.round(m / 2 + rs * np.sin(phi)).astype(int)
    v = (psf[y, x] * rs ** 3).sum(0)
    peak = (v > np.roll(v, 1)) & (v >= np.roll(v, -1)) & (v > 0.2 * v.max())
    return int(peak.sum())
