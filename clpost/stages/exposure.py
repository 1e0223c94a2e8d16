r"""exposure: scene luminance → normalised sensor signal (1.0 = saturation).

.. math::

    \text{signal} = Y_{in} \cdot s \cdot \frac{\pi T}{4 N_w^2} \cdot t \cdot \frac{S}{78}

with s = ``Camera.luminance_scale`` (cd/m² of Y = 1), T transmittance, N_w the working f-number,
t shutter (s) and S the ISO speed; all formulas and sources are in :mod:`clpost.photometry`.
Applied alike to R, G and B so chromaticity is unchanged. Auto-exposure (a missing f-number or
shutter) is resolved per frame by :mod:`clpost.metering` before this stage runs.

Domain/range: any finite input ≥ 0 → output ≥ 0; no clipping here (highlights above 1.0 stay for
the blurs and the film/sensor stages, which saturate physically).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..params import finite, param, parse_fraction
from ..photometry import camera_bellows_factor, sensor_gain
from .base import PointwiseStage

METERING_MODES = ("average", "centre", "spot")


def _check_metering(name, value):
    if value not in METERING_MODES:
        raise InputError(f"Camera.{name}={value!r} must be one of {', '.join(METERING_MODES)}")
    return value


@dataclass(frozen=True)
class ExposureParams:
    """The reflected-light meter's pattern and compensation (auto-exposure, :mod:`clpost.metering`)."""

    metering: str = param("average", unit="pattern", flag="--metering", check=_check_metering,
                          header="clpost.metering", scalar=True,
                          help=f"metering pattern for auto-exposure: {', '.join(METERING_MODES)}")
    exposure_compensation_ev: float = param(
        0.0, unit="EV", flag="--ev", parse=parse_fraction, header="clpost.exposureCompensation_ev", scalar=True,
        check=finite("EV", "e.g. +1 for one stop brighter"),
        help="exposure compensation of auto-exposure in EV (+1 = one stop brighter)")

    @staticmethod
    def check_options(camera, given):
        if not camera.is_auto_exposure and ({"metering", "exposure_compensation_ev"} & given):
            # a silently ignored option is worse than an error: the meter only acts in auto-exposure
            raise InputError("--metering/--ev act only in auto-exposure: add --shutter auto (aperture "
                             "priority) or --f-number auto (shutter priority)")


def exposure_gain(camera) -> float:
    """Sensor signal per unit input for a fully set (manual or resolved) camera."""
    n_w = camera.f_number * camera_bellows_factor(camera)
    return sensor_gain(f_number_w=n_w, shutter_s=camera.shutter_s, iso=camera.iso,
                       transmittance=camera.transmittance, luminance_scale=camera.luminance_scale)


class Exposure(PointwiseStage):
    name = "exposure"
    order = 70.0
    role = "luminance → exposure → normalised sensor signal (linear)"
    domains = ("image", "signal")
    params = ExposureParams
    args = (("float", "gain"),)

    def skip_reason(self, camera, frame):
        if exposure_gain(camera) == 1.0:
            return "gain is exactly 1 (input already in sensor units)"
        return None

    def reason_needed(self, camera, frame):
        return (f"gain {exposure_gain(camera):.4g} (f/{camera.f_number:g}, {camera.shutter_s:g} s, "
                f"ISO {camera.iso:g}, T {camera.transmittance:g})")

    def values(self, camera, frame):
        return (np.float32(exposure_gain(camera)),)

    def reference(self, camera, frame, color):
        return np.asarray(color, dtype=np.float64) * exposure_gain(camera)
