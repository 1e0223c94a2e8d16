r"""Photographic exposure: image-plane illuminance, sensor normalisation and metering constants.

One place for the formulas every stage and the meter share.

Image-plane illuminance of a Lambertian scene patch of luminance L seen on axis through a lens of
f-number N and transmittance T (Ray, *Applied Photographic Optics*, 3rd ed., §12; Kingslake,
*Optics in Photography*, ch. 6):

.. math::

    E = \frac{\pi\,T\,L}{4\,N_w^2}, \qquad N_w = N\,(1 + |m|) = N\,\frac{v}{f}

The π converts luminance (cd/m²) to the illuminance of a Lambertian source (E = π L sin²θ with
sin θ = 1/2N_w). The talk writes E = TL/4N², i.e. luminance in units where the π is absorbed
(apostilbs: 1 asb = 1/π cd/m²); the factor only rescales and we keep SI units. N_w is the working
(effective) f-number: focusing closer moves the film away (image distance v) and dims the image by
the bellows factor; with lateral magnification m = v/f − 1 and pupil magnification P (exit over
entrance pupil diameter; 1 for a thin lens), :math:`N_w = N\,(1 + m/P)` (Ray, §12.3), which is
N·v/f for a thin lens. Off-axis falloff (cos⁴θ) and
vignetting belong to the vignetting stage, not here.

Exposure :math:`H = E\,t` (lux·s). The sensor signal is normalised by the ISO 12232
saturation-based speed S: :math:`H_{sat} = 78/S` lux·s, signal = H / H_sat, 1.0 = saturation.

Reflected-light metering (ISO 2720), calibration constant K = 12.5 cd·s/m²: the meter picks
settings with :math:`N_w^2 / t = L\,S / K`. A uniform scene so metered lands at

.. math::

    \frac{H}{H_{sat}} = \frac{\pi T}{4}\,\frac{L t}{N_w^2}\,\frac{S}{78} = q\,\frac{K}{78},
    \qquad q = \frac{\pi T}{4}

which is 0.104 of saturation for T = 0.83 (q = 0.652, the value ISO 2720 assumes).

The meter is through-the-lens: it sees the image-plane illuminance, so N_w (not N) enters and the
bellows factor is compensated automatically, as on a real SLR — and so are the lens's transmittance
T and a neutral-density filter. Its calibration assumes a lens of :data:`METER_TRANSMITTANCE`, so
whatever the glass, a metered uniform scene lands at the same exposure

.. math::

    H_g = \frac{\pi T_m K}{4 S}\,2^{EC},\qquad \frac{H_g}{H_{sat}} = \frac{\pi T_m K}{4\cdot 78}\,2^{EC}
    = 0.1133\cdot 2^{EC}\ (T_m = 0.9)

(:func:`metered_grey_exposure`, :data:`MID_GREY_SIGNAL`); an automatic printer prints this
exposure as mid-grey. A camera's exposure is then a function of H alone: two lenses differing
only in T, with shutters in the inverse ratio, give the same negative and the same print.

Exposure modes (:func:`exposure_mode`; the ``exposure`` stage applies the gain):

- ``passthrough`` (no luminance scale, no reference exposure — the default): the plate's values
  are the sensor signal, gain exactly 1 (pbrt-v4's imaging ratio 1). Only exposure compensation
  EC and an ND filter of ``nd`` stops change it: :math:`g = 2^{EC - nd}`.
- ``physical`` (a luminance scale s, cd/m² of Y = 1): the formula above,
  :math:`g = s\,\frac{\pi T 2^{-nd}}{4 N_w^2}\,t\,\frac{S}{78}\,2^{EC}` (EC as a gain only in manual
  exposure; in auto-exposure the meter applies it).
- ``relative`` (a reference exposure N_r, t_r, S_r, T_r that the plate was made at): the plate is
  the signal of the camera at the reference settings, and the camera's settings change it as
  they change light on film, :math:`g = \frac{T 2^{-nd}}{T_r}\left(\frac{N_r}{N}\right)^2\frac{t}{t_r}
  \frac{S}{S_r}\,2^{EC}` — at the reference settings g = 1 exactly. The bellows factor is taken
  as the render's own (it cancels). For the meter the plate's luminance scale is the one that
  makes the reference camera's gain 1 (:func:`reference_luminance_scale`).
"""
from __future__ import annotations

import math

K_REFLECTED = 12.5
"""ISO 2720 reflected-light meter calibration constant K (cd·s/m², ISO 100 convention)."""

SATURATION_EXPOSURE_ISO = 78.0
"""ISO 12232 saturation-based speed: H_sat = 78 / S lux·s."""

METER_TRANSMITTANCE = 0.9
"""Lens transmittance T_m the TTL meter's calibration assumes (the camera's default T); the meter
compensates any other T (and ND) as it sees through the lens."""

MID_GREY_SIGNAL = math.pi * METER_TRANSMITTANCE * K_REFLECTED / (4.0 * SATURATION_EXPOSURE_ISO)
"""Sensor signal (1.0 = saturation) of a metered uniform scene: π T_m K / (4·78) = 0.1133."""

EXPOSURE_MODES = ("passthrough", "physical", "relative")


def metered_grey_exposure(iso: float, ev: float = 0.0) -> float:
    """H_g = π T_m K 2^EC / (4 S) lux·s: the exposure the meter gives a uniform scene at ISO S."""
    return math.pi * METER_TRANSMITTANCE * K_REFLECTED * 2.0 ** ev / (4.0 * iso)


def exposure_mode(camera) -> str:
    """``passthrough``, ``physical`` (a luminance scale) or ``relative`` (a reference exposure)."""
    if camera.luminance_scale is not None:
        return "physical"
    if getattr(camera, "reference_exposure", None) is not None:
        return "relative"
    return "passthrough"


def nd_factor(camera) -> float:
    """Transmittance of the ND filter: 2^-nd."""
    return 2.0 ** -getattr(camera, "nd_stops", 0.0)


def reference_luminance_scale(camera) -> float:
    r"""The luminance scale (cd/m² of Y = 1) at which the reference camera's gain is 1:
    :math:`s = \frac{4\cdot 78\,(N_r b)^2}{\pi T_r t_r S_r}`, b the camera's bellows factor."""
    n_r, t_r, s_r, tr_r = camera.reference_exposure
    b = camera_bellows_factor(camera)
    return 4.0 * SATURATION_EXPOSURE_ISO * (n_r * b) ** 2 / (math.pi * tr_r * t_r * s_r)


def scene_luminance_scale(camera) -> float | None:
    """cd/m² of the plate's Y = 1 as the meter sees it: the given luminance scale (physical), the
    reference's (relative) or None (passthrough: the plate carries no light level)."""
    mode = exposure_mode(camera)
    if mode == "physical":
        return camera.luminance_scale
    if mode == "relative":
        return reference_luminance_scale(camera)
    return None


def exposure_gain(camera) -> float:
    """Sensor signal per unit input Y of a fully set (manual or metered) camera, every mode (the
    module docstring). A camera resolved by the meter carries ``metered=True`` (set by
    :func:`clpost.metering.resolve`): its EC is already in the shutter or f-number."""
    ec = 0.0 if camera.__dict__.get("metered", False) else camera.exposure_compensation_ev
    mode = exposure_mode(camera)
    if mode == "passthrough":
        return 2.0 ** (ec - camera.nd_stops)
    if mode == "relative":
        n_r, t_r, s_r, tr_r = camera.reference_exposure
        return ((camera.transmittance * nd_factor(camera) / tr_r) * (n_r / camera.f_number) ** 2
                * (camera.shutter_s / t_r) * (camera.iso / s_r) * 2.0 ** ec)
    n_w = camera.f_number * camera_bellows_factor(camera)
    return sensor_gain(f_number_w=n_w, shutter_s=camera.shutter_s, iso=camera.iso,
                       transmittance=camera.transmittance * nd_factor(camera),
                       luminance_scale=camera.luminance_scale) * 2.0 ** ec


def working_f_number(f_number: float, focal_length_mm: float, image_distance_mm: float,
                     pupil_magnification: float = 1.0) -> float:
    """N_w = N · (1 + m/P), m = v/f − 1 (N·v/f for a thin lens, P = 1)."""
    return f_number * bellows_factor(focal_length_mm, image_distance_mm, pupil_magnification)


def bellows_factor(focal_length_mm: float, image_distance_mm: float, pupil_magnification: float = 1.0) -> float:
    """N_w / N = 1 + (v/f − 1)/P."""
    return 1.0 + (image_distance_mm / focal_length_mm - 1.0) / pupil_magnification


def camera_bellows_factor(camera) -> float:
    """The camera's N_w / N: its lens's pupil magnification for a traced lens, 1 for a thin one."""
    p = 1.0 if camera.optics is None else camera.optics.paraxial.pupil_magnification
    return bellows_factor(camera.focal_length_mm, camera.image_distance_mm, p)


def sensor_gain(*, f_number_w: float, shutter_s: float, iso: float, transmittance: float,
                luminance_scale: float) -> float:
    r"""Sensor signal per unit input Y: :math:`s\,\frac{\pi T}{4 N_w^2}\,t\,\frac{S}{78}`.

    Computed in float64; the product spans ~1e-12 … 1e6 over f/0.7–f/64, 1/8000–30 s and
    ISO 25–102400, well inside float32 once formed.
    """
    illuminance_per_cd = math.pi * transmittance / (4.0 * f_number_w * f_number_w)
    h_sat = SATURATION_EXPOSURE_ISO / iso
    return luminance_scale * illuminance_per_cd * shutter_s / h_sat
