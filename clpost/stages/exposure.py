r"""exposure: the plate → normalised sensor signal (1.0 = saturation), in one of three modes.

.. math::

    \text{signal} = Y_{in} \cdot g

- ``passthrough`` (default: no ``luminance_scale``, no ``reference_exposure``): g = 2^(EC − nd),
  exactly 1 without ``--ev``/``--nd`` — the stage is then not planned;
- ``physical`` (``--luminance-scale s``): :math:`g = s\,\frac{\pi T 2^{-nd}}{4 N_w^2}\,t\,\frac{S}{78}`;
- ``relative`` (``--reference-exposure N,t,S[,T]``): the camera's settings relative to the ones
  the plate was made at, :math:`g = \frac{T 2^{-nd}}{T_r}(N_r/N)^2\,\frac{t}{t_r}\,\frac{S}{S_r}`.

T transmittance, N_w the working f-number, t shutter (s), S the ISO speed, EC exposure
compensation (a gain in manual exposure; the meter's target in auto), nd an ND filter in stops;
every formula and its source is in :mod:`clpost.photometry`. Applied alike to R, G and B so
chromaticity is unchanged. Auto-exposure (a missing f-number or shutter) is resolved per frame
by :mod:`clpost.metering` before this stage runs; it needs a light level (physical or relative).

Domain/range: any finite input ≥ 0 → output ≥ 0; no clipping here (highlights above 1.0 stay for
the blurs and the film/sensor stages, which saturate physically).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..params import at_least, finite, param, parse_fraction
from ..photometry import exposure_gain, exposure_mode
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
        help="exposure compensation in EV (+1 = one stop brighter), every mode; in auto-exposure "
             "the meter applies it (longer shutter or wider aperture)")
    nd_stops: float = param(
        0.0, unit="stops", flag="--nd", parse=parse_fraction, header="clpost.nd_stops", scalar=True,
        check=at_least(0.0, "stops", "e.g. 3 for an ND8 filter", "0 = no filter"),
        help="neutral-density filter in stops (ND8 = 3): 2^-nd of the light, every mode; the TTL "
             "meter of auto-exposure compensates it with a longer shutter")
    reference_exposure: tuple | None = param(
        None, unit="f-number, seconds, ISO, transmittance", flag="--reference-exposure",
        parse=lambda text: parse_reference_exposure(text), show=lambda v: show_reference_exposure(v),
        header="clpost.referenceExposure", scalar=True, check=lambda name, v: check_reference_exposure(name, v),
        help="the exposure the plate was made at, 'f/N,SHUTTER,ISO[,T]' (e.g. f/2,1/50,100; T "
             "default 0.9): exposure becomes relative — the camera's f-number, shutter, ISO and T "
             "change the plate as they change light on film, and equal settings leave it unchanged")

    @staticmethod
    def validate(camera, inputs):
        if camera.reference_exposure is not None and camera.luminance_scale is not None:
            raise InputError("Camera: luminance_scale and reference_exposure both set; give one: "
                             "--luminance-scale for physical exposure, or --reference-exposure for "
                             "exposure relative to the render's")

    @staticmethod
    def check_options(camera, given):
        if not camera.is_auto_exposure and "metering" in given:
            # a silently ignored option is worse than an error: the meter only acts in auto-exposure
            raise InputError("--metering: metering patterns act only in auto-exposure: add --shutter auto (aperture "
                             "priority) or --f-number auto (shutter priority)")

    @staticmethod
    def extra_header(camera) -> dict[str, str]:
        out = {"clpost.exposureMode": exposure_mode(camera)}
        ev = camera.exposure_compensation_ev
        if camera.__dict__.get("metered") and ev:
            # the metered f-number/shutter already hold the compensation: recorded as applied, so a
            # camera read back from this header (--camera-from) does not apply it a second time
            out["clpost.exposureCompensation_ev"] = "0"
            out["clpost.meteredCompensation_ev"] = f"{ev:g}"
        return out


def parse_reference_exposure(text: str) -> tuple:
    """``f/N,SHUTTER,ISO[,T]`` (``f/2,1/50,100`` or ``2,0.02,100,0.9``) → (N, t_s, S, T)."""
    import argparse

    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) not in (3, 4):
        raise argparse.ArgumentTypeError(f"{text!r} is not 'f/N,SHUTTER,ISO[,T]', e.g. f/2,1/50,100")
    n = parts[0][2:] if parts[0].lower().startswith("f/") else parts[0]
    vals = [parse_fraction(v) for v in [n, parts[1].rstrip("s"), parts[2]] + parts[3:]]
    return tuple(vals) + ((0.9,) if len(vals) == 3 else ())


def check_reference_exposure(name, value):
    if value is None:
        return None
    if isinstance(value, str):
        import argparse

        try:
            value = parse_reference_exposure(value)
        except argparse.ArgumentTypeError as exc:
            raise InputError(f"Camera.{name}: {exc}") from None
    try:
        vals = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        vals = ()
    if len(vals) == 3:
        vals += (0.9,)
    import math

    if len(vals) != 4 or not all(math.isfinite(v) and v > 0 for v in vals) or vals[3] > 1:
        raise InputError(f"Camera.{name}={value!r} must be (f-number, shutter s, ISO[, T]) all > 0 with "
                         "T <= 1, e.g. (2, 1/50, 100) or 'f/2,1/50,100'")
    return vals


def show_reference_exposure(value) -> str | None:
    if value is None:
        return None
    n, t, s, tr = value
    return f"f/{n:g},{t:g},{s:g},{tr:g}"


class Exposure(PointwiseStage):
    name = "exposure"
    order = 70.0
    role = "luminance → exposure → normalised sensor signal (linear)"
    domains = ("image", "signal")
    params = ExposureParams
    example = {"reference_exposure": (2.0, 1 / 50, 100.0, 0.9)}
    args = (("float", "gain"),)

    def skip_reason(self, camera, frame):
        if exposure_gain(camera) == 1.0:
            return (f"{exposure_mode(camera)}: gain is exactly 1 (input already in sensor units)"
                    if exposure_mode(camera) != "passthrough" else
                    "passthrough: gain is exactly 1 (no --luminance-scale, --reference-exposure, --ev or --nd)")
        return None

    def reason_needed(self, camera, frame):
        mode = exposure_mode(camera)
        if mode == "passthrough":
            return f"passthrough: gain {exposure_gain(camera):.4g} (EV {camera.exposure_compensation_ev:+g}, ND {camera.nd_stops:g})"
        return (f"{mode}: gain {exposure_gain(camera):.4g} (f/{camera.f_number:g}, {camera.shutter_s:g} s, "
                f"ISO {camera.iso:g}, T {camera.transmittance:g}, ND {camera.nd_stops:g})")

    def values(self, camera, frame):
        return (np.float32(exposure_gain(camera)),)

    def reference(self, camera, frame, color):
        return np.asarray(color, dtype=np.float64) * exposure_gain(camera)
