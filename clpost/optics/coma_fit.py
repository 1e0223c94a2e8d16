r"""Coma of a traced lens: the sagittal-coma coefficient C(r) fitted to its meridional ray fans.

Third-order coma displaces the ray through pupil point :math:`(\rho\cos\phi, \rho\sin\phi)` by
:math:`C\rho^2(2 + \cos 2\phi)` along the meridian: the even part of a meridional fan's
intercepts (relative to the chief ray) is :math:`3C\rho^2`. C is fitted per field angle by least
squares with the pupil-area weight :math:`\rho\,d\rho` (so :math:`\rho^3`) over
:math:`0.07 \le \rho \le` :data:`RHO_FIT`. Used by :mod:`clpost.stages.coma` (``coma_curve``);
the physics of the stage and its oracle live there. Reference: W. J. Smith, *Modern Optical
Engineering*, 4th ed., §3.3 (third-order aberrations, coma).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

RHO_FIT = 0.7
"""C is fitted over ρ ≤ 0.7 (half of the pupil's area), where the third-order ρ² law holds; the
rim zone of a fast lens is dominated by high-order flare (spherical aberration's), which a ρ² fit
would turn into a far too long comet."""


@lru_cache(maxsize=32)
def traced_coma(lens_name: str, focus_distance_m: float, f_number: float) -> tuple[np.ndarray, np.ndarray]:
    """(image_height_mm, C_mm) of a traced lens from its meridional fans."""
    from . import get_lens, lens_curves
    from .curves import _Field

    lens = get_lens(lens_name)
    curves = lens_curves(lens_name, focus_distance_m, f_number)
    focus_mm = focus_distance_m * 1000.0
    pres = lens.focused(focus_mm, f_number)
    field = _Field(lens, pres, focus_mm, lens.stop_radius_mm(f_number))
    r_e = curves.entrance_pupil_radius_mm
    th = np.radians(np.asarray(curves.field_angle_deg, np.float64))
    aim = field.chief_aim(th)
    rho = np.linspace(0.07, RHO_FIT, 10)
    fan = np.concatenate([-rho[::-1], [0.0], rho])
    t = np.repeat(th, fan.size)
    ay = np.repeat(aim, fan.size) + np.tile(fan, th.size) * r_e / np.cos(t)
    res = field.trace(t, 0.0, ay, clip=False)
    y = res.pos[:, 1].reshape(th.size, fan.size)
    ok = (res.status == 0).reshape(th.size, fan.size)
    eps = y - y[:, rho.size][:, None]
    even = 0.5 * (eps[:, rho.size + 1:] + eps[:, :rho.size][:, ::-1])
    good = ok[:, rho.size + 1:] & ok[:, :rho.size][:, ::-1] & ok[:, rho.size][:, None]
    w = np.where(good, rho ** 3, 0.0)  # least squares of 3Cρ² with the pupil-area weight ρ dρ
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.where(w.sum(1) > 0, np.sum(w * np.where(good, even, 0.0), 1) / (3.0 * np.sum(w * rho ** 2, 1)), 0.0)
    c = np.nan_to_num(c)
    c[0] = 0.0  # on axis the fan is symmetric: no coma
    return np.asarray(curves.image_height_mm), c
