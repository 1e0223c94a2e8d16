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
bellows factor is compensated automatically, as on a real SLR.
"""
from __future__ import annotations

import math

K_REFLECTED = 12.5
"""ISO 2720 reflected-light meter calibration constant K (cd·s/m², ISO 100 convention)."""

SATURATION_EXPOSURE_ISO = 78.0
"""ISO 12232 saturation-based speed: H_sat = 78 / S lux·s."""


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
