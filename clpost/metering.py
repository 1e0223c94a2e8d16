r"""The camera's reflected-light meter: auto-exposure as a real camera does it.

The meter measures a weighted mean of scene luminance L (cd/m²) through the lens and solves
the ISO 2720 meter equation for the setting the photographer left open
(formulas in :mod:`clpost.photometry`, K = 12.5):

.. math::

    \frac{N_w^2}{t} = \frac{L\,S}{K\,2^{EC}}

- aperture priority (``shutter_s=None``): :math:`t = N_w^2 K 2^{EC} / (L S)`
- shutter priority (``f_number=None``): :math:`N = \frac{f}{v}\sqrt{L S t / (K 2^{EC})}`

EC is the exposure compensation in EV (+1 = one stop more light). Results outside the camera's
range (:data:`SHUTTER_RANGE_S`, :data:`F_NUMBER_RANGE`) are clamped, with a warning, as a camera
does when the scene is too bright or too dark.

Metering patterns (weights over the image, documented per mode):

- ``average``: every pixel alike (arithmetic mean of L — small bright lights raise it, as they do
  a real averaging meter).
- ``centre``: centre-weighted, Gaussian weight :math:`e^{-r^2/2\sigma^2}` with σ = ¼ of the image
  height (≈ 60 % of the weight within the central circle of diameter ½ the height).
- ``spot``: uniform over a central disc covering 3 % of the image area (typical SLR spot 2.5–3.5 %).
"""
from __future__ import annotations

import math
import warnings

import numpy as np

from .colorspace import luminance
from .errors import InputError
from .colorspace import WORKING_SPACES
from .photometry import K_REFLECTED, camera_bellows_factor

SHUTTER_RANGE_S = (1 / 8000, 30.0)
F_NUMBER_RANGE = (0.7, 64.0)
SPOT_AREA_FRACTION = 0.03
CENTRE_SIGMA_OF_HEIGHT = 0.25


def metering_weights(mode: str, height: int, width: int) -> np.ndarray:
    """Normalised (sum 1) weights of a metering pattern, float64 (H, W)."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    r2 = (x - (width - 1) / 2) ** 2 + (y - (height - 1) / 2) ** 2
    if mode == "average":
        w = np.ones((height, width))
    elif mode == "centre":
        sigma = CENTRE_SIGMA_OF_HEIGHT * height
        w = np.exp(-r2 / (2 * sigma * sigma))
    elif mode == "spot":
        radius2 = SPOT_AREA_FRACTION * height * width / math.pi
        w = (r2 <= radius2).astype(np.float64)
        if not w.any():  # tiny images: the centre pixel(s)
            w = (r2 <= r2.min()).astype(np.float64)
    else:
        raise InputError(f"metering mode {mode!r} is unknown: use average, centre or spot")
    return w / w.sum()


def metered_luminance(camera, frame) -> float:
    """The meter reading L (cd/m²) of a frame for the camera's metering mode."""
    y = luminance(frame.color, WORKING_SPACES[camera.working_space]) * camera.luminance_scale
    w = metering_weights(camera.metering, frame.height, frame.width)
    return float(np.sum(w * y))


def resolve(camera, frame):
    """The camera with its missing f-number or shutter chosen by the meter (manual: unchanged)."""
    if not camera.is_auto_exposure:
        return camera
    lum = metered_luminance(camera, frame)
    if not lum > 0:
        raise InputError(
            "auto-exposure: the frame is black (metered luminance 0), nothing to meter; "
            "give both --f-number and --shutter"
        )
    s, k = camera.iso, K_REFLECTED * 2.0 ** camera.exposure_compensation_ev
    bellows = camera_bellows_factor(camera)  # N_w = N * bellows (TTL: the meter sees it)
    if camera.shutter_s is None:
        t = (camera.f_number * bellows) ** 2 * k / (lum * s)
        lo, hi = SHUTTER_RANGE_S
        if camera.frame_rate_fps is not None:  # a frame's shutter cannot outlast the frame
            hi = min(hi, 1.0 / camera.frame_rate_fps)
        t_c = min(max(t, lo), hi)
        if t_c != t:
            warnings.warn(f"auto-exposure: shutter {t:.3g} s is outside {lo:.3g}–{hi:.3g} s; using {t_c:.3g} s, "
                          f"so the frame is {math.log2(t_c / t):+.2f} EV off the meter", stacklevel=2)
        return camera.with_(shutter_s=t_c)
    n = math.sqrt(lum * s * camera.shutter_s / k) / bellows
    lo, hi = F_NUMBER_RANGE
    if camera.optics is not None:  # the lens's own aperture range
        lo, hi = max(lo, camera.optics.max_aperture), min(hi, camera.optics.min_aperture)
    n_c = min(max(n, lo), hi)
    if n_c != n:
        warnings.warn(f"auto-exposure: f/{n:.3g} is outside the {camera.lens} range f/{lo:.3g}–f/{hi:.3g}; "
                      f"using f/{n_c:.3g}, so the frame is {2 * math.log2(n / n_c):+.2f} EV off the meter",
                      stacklevel=2)
    return camera.with_(f_number=n_c)
