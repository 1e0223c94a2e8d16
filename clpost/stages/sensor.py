r"""sensor: a digital sensor's raw recording of the normalised exposure signal.

Per pixel and channel (electrons e⁻, digital numbers DN):

.. math::

    \bar e = \text{signal}\cdot e_{sat},\quad e_{sat} = FW\,\frac{S_0}{S},\qquad
    e = \min(\mathrm{Poisson}(\bar e),\ FW) + \sigma_r\,\mathcal N(0,1)

.. math::

    DN = \mathrm{clamp}\big(\mathrm{round}(B + e\,g),\ 0,\ 2^{bits}-1\big),\quad
    g = \frac{2^{bits}-1-B}{e_{sat}},\qquad
    \text{out} = \frac{DN - B}{2^{bits}-1-B}

FW full-well capacity, S₀ base ISO (the ISO whose saturation exposure fills the well exactly),
S the camera ISO (analogue gain S/S₀; below base ISO the well clips before the ADC), σ_r read
noise, B black level, ``bits`` ADC depth. The output is the black-subtracted raw normalised so
that 1.0 is the clipping point — linear, with noise; slightly negative values below black are kept
as real raw files keep them. Shot noise: exact Poisson by inversion for means ≤ 32 e⁻, else the
normal approximation with the Poisson variance (error of the normal approximation to Poisson at
mean 32 is < 1 % in σ). Means above 2·FW are clipped to the well with certainty and capped there.

Randomness: counter-based hash of (``Camera.noise_seed``, ``metadata["frame_index"]``, pixel
index, 4·channel + k) — :mod:`clpost.random` reproduces it bit for bit: k = 0 the exact Poisson
search's uniform, k = 3 a Box–Muller draw whose cosine branch is the read noise and whose sine
branch the normal approximation's (kernels/sensor.cl).

Presets are *representative* of their sensor classes (orders of magnitude from published
photon-transfer measurements, e.g. sensorgen.info and EMVA 1288 reports), not specific products.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import random as rnd
from ..errors import InputError
from ..params import param, show_none
from .base import PointwiseStage

POISSON_EXACT_MAX = 32.0


@dataclass(frozen=True)
class SensorPreset:
    full_well_e: float
    read_noise_e: float
    base_iso: float
    bits: int
    black_level_dn: int
    description: str


SENSOR_PRESETS = {
    "fullframe-cmos": SensorPreset(50000, 3.0, 100, 14, 512, "representative 36×24 mm back-side CMOS, ~6 µm pixels"),
    "apsc-cmos": SensorPreset(25000, 2.5, 100, 14, 512, "representative APS-C CMOS, ~4 µm pixels"),
    "smartphone": SensorPreset(6000, 2.0, 50, 10, 64, "representative phone sensor, ~1.2 µm pixels"),
    "machine-vision": SensorPreset(10500, 2.4, 100, 12, 16, "representative global-shutter machine-vision CMOS"),
}


def _check_preset(name, value):
    if value is not None and (not isinstance(value, str) or value not in SENSOR_PRESETS):
        raise InputError(f"Camera.{name}={value!r} is unknown: use one of {', '.join(SENSOR_PRESETS)}")
    return value


@dataclass(frozen=True)
class SensorParams:
    """sensor: a digital sensor preset; the camera records on film or on a sensor, not both."""

    sensor_preset: str | None = param(None, unit="preset", flag="--sensor-preset", check=_check_preset,
                                      header="clpost.sensorPreset", show=show_none, scalar=False,
                                      help=f"digital sensor: {', '.join(SENSOR_PRESETS)}")

    @staticmethod
    def validate(camera, inputs):
        if getattr(camera, "film", None) is not None and camera.sensor_preset is not None:
            raise InputError(f"Camera: film={camera.film!r} and sensor_preset={camera.sensor_preset!r} are both "
                             "set; a camera records on one medium — give --film or --sensor-preset, not both")


def frame_index(frame) -> int:
    """The frame counter of the noise hash (:attr:`clpost.frame.Frame.index`)."""
    return frame.index


def sensor_scalars(camera):
    p = SENSOR_PRESETS[camera.sensor_preset]
    e_sat = p.full_well_e * p.base_iso / camera.iso
    white = float((1 << p.bits) - 1)
    return p, e_sat, white


class Sensor(PointwiseStage):
    name = "sensor"
    order = 85.0
    role = "a digital sensor's response: shot and read noise, full well, quantisation"
    domains = ("signal", "raw")
    requires = ("exposure",)
    params = SensorParams
    args = (("float", "e_sat"), ("float", "full_well"), ("float", "read_noise"), ("float", "black"),
            ("float", "white"), ("uint", "seed"), ("uint", "frame"))

    def skip_reason(self, camera, frame):
        return None if camera.sensor_preset else "no digital sensor (Camera.sensor_preset is None)"

    def reason_needed(self, camera, frame):
        p, e_sat, _ = sensor_scalars(camera)
        return (f"{camera.sensor_preset}: {e_sat:.0f} e⁻ at saturation (FW {p.full_well_e:g}, ISO {camera.iso:g}/"
                f"{p.base_iso:g}), read noise {p.read_noise_e:g} e⁻, {p.bits} bit, black {p.black_level_dn}")

    def replay_key(self, camera, frame):
        return (super().replay_key(camera, frame), frame_index(frame))  # the noise hash's frame counter

    def values(self, camera, frame):
        p, e_sat, white = sensor_scalars(camera)
        return (np.float32(e_sat), np.float32(p.full_well_e), np.float32(p.read_noise_e),
                np.float32(p.black_level_dn), np.float32(white), np.uint32(camera.noise_seed),
                np.uint32(frame_index(frame)))

    def reference(self, camera, frame, color):
        p, e_sat, white = sensor_scalars(camera)
        h, w, _ = color.shape
        i = np.arange(h * w, dtype=np.uint32).reshape(h, w, 1)
        ch = np.arange(3, dtype=np.uint32).reshape(1, 1, 3)
        seed, fr = camera.noise_seed, frame_index(frame)
        mean = np.minimum(np.maximum(np.asarray(color, np.float64), 0.0) * e_sat, 2.0 * p.full_well_e)
        u = rnd.uniform(rnd.hash4(seed, fr, i, ch * 4))
        h3 = rnd.hash4(seed, fr, i, ch * 4 + 3)
        g_read, g_shot = rnd.normal_pair(h3, rnd.mix(h3 ^ np.uint32(0x5BD1E995)))
        e = np.where(mean > POISSON_EXACT_MAX,
                     np.maximum(np.round(mean + np.sqrt(mean) * g_shot), 0.0),
                     rnd.poisson_inversion(np.minimum(mean, POISSON_EXACT_MAX), u))
        e = np.minimum(e, p.full_well_e) + p.read_noise_e * g_read
        dn = np.clip(np.round(p.black_level_dn + e * (white - p.black_level_dn) / e_sat), 0.0, white)
        return (dn - p.black_level_dn) / (white - p.black_level_dn)

