r"""The camera's reflected-light meter: auto-exposure as a real camera does it.

The meter measures a weighted mean of scene luminance L (cd/m²) through the lens and solves
the ISO 2720 meter equation for the setting the photographer left open
(formulas in :mod:`clpost.photometry`, K = 12.5):

.. math::

    \frac{N_w^2}{t} = \frac{L\,S\,T'}{K\,2^{EC}\,T_m},\qquad T' = T\,2^{-nd}

- aperture priority (``shutter_s=None``): :math:`t = N_w^2 K 2^{EC} T_m / (L S T')`
- shutter priority (``f_number=None``): :math:`N = \frac{f}{v}\sqrt{L S t T' / (K 2^{EC} T_m)}`

EC is the exposure compensation in EV (+1 = one stop more light). The meter is through the lens:
it sees the lens's transmittance T and an ND filter of nd stops, and its calibration assumes
:data:`clpost.photometry.METER_TRANSMITTANCE` T_m, so a metered uniform scene lands at the same
exposure H (:func:`clpost.photometry.metered_grey_exposure`) whatever the glass. L is the plate's
luminance times its scale (:func:`clpost.photometry.scene_luminance_scale`: the given
``luminance_scale``, or the one implied by a ``reference_exposure``). Results outside the camera's
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

import functools
import math
import warnings

import numpy as np

from .colorspace import luminance
from .errors import InputError
from .colorspace import WORKING_SPACES
from .photometry import (K_REFLECTED, METER_TRANSMITTANCE, MID_GREY_SIGNAL, camera_bellows_factor,
                         exposure_gain, exposure_mode, nd_factor, scene_luminance_scale)

SHUTTER_RANGE_S = (1 / 8000, 30.0)
F_NUMBER_RANGE = (0.7, 64.0)
SPOT_AREA_FRACTION = 0.03
CENTRE_SIGMA_OF_HEIGHT = 0.25


@functools.lru_cache(maxsize=8)
def metering_weights(mode: str, height: int, width: int) -> np.ndarray:
    """Normalised (sum 1) weights of a metering pattern, float64 (H, W), read-only: cached per
    (mode, size), as every frame of a sequence (and every redraw of ``clpost view``) meters
    with the same pattern."""
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
    w = w / w.sum()
    w.flags.writeable = False
    return w


def metered_luminance(camera, frame) -> float:
    """The meter reading L (cd/m²) of a frame for the camera's metering mode."""
    y = luminance(frame.color, WORKING_SPACES[camera.working_space]) * scene_luminance_scale(camera)
    w = metering_weights(camera.metering, frame.height, frame.width)
    return float(np.sum(w * y))


class ExposureWarning(UserWarning):
    """The exposure is far from what a meter would choose (printed as one line by the CLI)."""


WARN_EV = 3.0
"""How far (EV) from mid-grey a manually exposed frame may be metered before a warning."""


def exposure_offset_ev(camera, frame) -> float | None:
    """How many EV the camera's signal, read by its metering pattern, is above mid-grey
    (:data:`clpost.photometry.MID_GREY_SIGNAL`); None for a black frame. Reads every 4th pixel."""
    c = frame.color[::4, ::4, :3]
    y = luminance(c, WORKING_SPACES[camera.working_space]) * exposure_gain(camera)
    w = metering_weights(camera.metering, c.shape[0], c.shape[1])
    m = float(np.sum(w * y))
    return math.log2(m / MID_GREY_SIGNAL) if m > 0 and math.isfinite(m) else None


def check_exposure(camera, frame) -> float | None:
    """Warn (:class:`ExposureWarning`, one line) when a manually set physical exposure, or a relative
    one more than :data:`WARN_EV` from its reference, meters more than :data:`WARN_EV` from
    mid-grey, naming the flag that fixes it; returns the offset in EV. A passthrough plate is the user's own exposure (its average may well sit far from
    grey: a few bright lamps), and a metered camera is at grey by construction: neither warns."""
    if camera.__dict__.get("metered", False) or exposure_mode(camera) == "passthrough":
        return None
    off = exposure_offset_ev(camera, frame)
    if off is None or abs(off) <= WARN_EV:
        return off
    mode = exposure_mode(camera)
    if mode == "relative" and abs(math.log2(exposure_gain(camera))) <= WARN_EV:
        return off  # the plate as made (its own average) or near it: the user's exposure
    fix = {"physical": f"--ev {-off:+.1f}, a --luminance-scale {2 ** -off:.3g}× this one, or --shutter auto",
           "relative": f"--ev {-off:+.1f}, or --shutter auto"}[mode]
    src = frame.metadata.get("path")
    warnings.warn(f"{src or 'frame'}: metered {abs(off):.1f} EV {'above' if off > 0 else 'below'} mid-grey "
                  f"({mode} exposure); fix with {fix}", ExposureWarning, stacklevel=2)
    return off


def resolve(camera, frame):
    """The camera with its missing f-number or shutter chosen by the meter (manual: unchanged)."""
    if not camera.is_auto_exposure:
        return camera
    if scene_luminance_scale(camera) is None:
        raise InputError("auto-exposure (--shutter auto / --f-number auto) meters the scene's light "
                         "level, which a passthrough camera does not know: give --luminance-scale "
                         "(cd/m² of Y = 1) or --reference-exposure (e.g. f/2,1/50,100)")
    lum = metered_luminance(camera, frame)
    if not lum > 0:
        raise InputError(
            "auto-exposure: the frame is black (metered luminance 0), nothing to meter; "
            "give both --f-number and --shutter"
        )
    # TTL: the meter sees the bellows factor, T and the ND filter; it is calibrated for T_m
    s = camera.iso
    k = K_REFLECTED * 2.0 ** camera.exposure_compensation_ev * METER_TRANSMITTANCE / (
        camera.transmittance * nd_factor(camera))
    bellows = camera_bellows_factor(camera)  # N_w = N * bellows
    if camera.shutter_s is None:
        t = (camera.f_number * bellows) ** 2 * k / (lum * s)
        lo, hi = SHUTTER_RANGE_S
        if camera.frame_rate_fps is not None:  # a frame's shutter cannot outlast the frame
            hi = min(hi, 1.0 / camera.frame_rate_fps)
        t_c = min(max(t, lo), hi)
        if t_c != t:
            warnings.warn(f"auto-exposure: shutter {t:.3g} s is outside {lo:.3g}–{hi:.3g} s; using {t_c:.3g} s, "
                          f"so the frame is {math.log2(t_c / t):+.2f} EV off the meter", stacklevel=2)
        return _metered(camera.with_(shutter_s=t_c))
    n = math.sqrt(lum * s * camera.shutter_s / k) / bellows
    lo, hi = F_NUMBER_RANGE
    if camera.optics is not None:  # the lens's own aperture range
        lo, hi = max(lo, camera.optics.max_aperture), min(hi, camera.optics.min_aperture)
    n_c = min(max(n, lo), hi)
    if n_c != n:
        warnings.warn(f"auto-exposure: f/{n:.3g} is outside the {camera.lens} range f/{lo:.3g}–f/{hi:.3g}; "
                      f"using f/{n_c:.3g}, so the frame is {2 * math.log2(n / n_c):+.2f} EV off the meter",
                      stacklevel=2)
    return _metered(camera.with_(f_number=n_c))


def _metered(camera):
    """Mark a camera as set by the meter: its EC is in the chosen shutter/f-number, so
    :func:`clpost.photometry.exposure_gain` must not apply it again (not a field: never in a header
    or a structure key)."""
    object.__setattr__(camera, "metered", True)
    return camera
