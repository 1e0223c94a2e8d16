r"""Paraxial (first-order) optics by the y–nu trace (Smith, *Modern Optical Engineering*, §2.5).

Per surface with curvature c, index n before and n' after, and thickness t to the next surface:

.. math::

    n'u' = nu - y\,c\,(n' - n), \qquad y_{k+1} = y_k + t_k u'_k

Two rays — (y, u) = (1, 0) and (0, 1) at the first vertex — give the system matrix
:math:`\begin{pmatrix}A & B\\ C & D\end{pmatrix}` from the first to the last vertex (object and
image space are air). Then EFL = −1/C, back focal distance BFL = −A/C (from the last vertex),
front focal distance −D/C (before the first vertex, as a negative z), principal planes at
z_H = z_F + EFL and z_H' = z_F' − EFL. The entrance pupil is the stop imaged backwards through
the front group: with (A_s, B_s) the heights at the stop of the two rays, the ray through the
stop centre crosses the axis at z_E = B_s/A_s and the pupil radius is r_stop/|A_s|. The exit
pupil is found the same way from the chief ray after the last surface. All lengths in mm;
z from the first vertex, +z toward the film.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .prescription import LAMBDA_D_NM, Prescription


def yu_trace(pres: Prescription, y0: float, u0: float, wavelength_nm: float = LAMBDA_D_NM,
             upto: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Heights y_k at each surface and slopes u'_k after it, for surfaces ``[0, upto)``."""
    n = pres.indices(wavelength_nm)
    surfs = pres.surfaces if upto is None else pres.surfaces[:upto]
    ys, us = [], []
    y, u, n_prev = float(y0), float(u0), 1.0
    for k, s in enumerate(surfs):
        if k > 0:
            y = y + pres.surfaces[k - 1].thickness_mm * u
        u = (n_prev * u - y * s.curvature * (n[k] - n_prev)) / n[k]
        ys.append(y)
        us.append(u)
        n_prev = n[k]
    return np.array(ys), np.array(us)


@dataclass(frozen=True)
class Paraxial:
    """First-order data of a prescription at one wavelength (mm, z from the first vertex)."""

    efl_mm: float
    bfl_mm: float
    """Last vertex → paraxial focus (infinity object)."""
    ffl_mm: float
    """Front focal point z (negative: before the first vertex)."""
    z_principal_front_mm: float
    z_principal_rear_mm: float
    z_entrance_pupil_mm: float
    entrance_pupil_radius_mm: float
    z_exit_pupil_mm: float
    exit_pupil_radius_mm: float
    z_last_vertex_mm: float

    @property
    def f_number(self) -> float:
        """Paraxial f-number EFL / entrance-pupil diameter (stop fully open)."""
        return self.efl_mm / (2 * self.entrance_pupil_radius_mm)

    @property
    def pupil_magnification(self) -> float:
        return self.exit_pupil_radius_mm / self.entrance_pupil_radius_mm

    def field_of_view_deg(self, extent_mm: float) -> float:
        """Paraxial angle of view 2·atan(K / 2·EFL) for a sensor extent K (mm)."""
        return float(np.degrees(2 * np.arctan(extent_mm / (2 * self.efl_mm))))


def paraxial(pres: Prescription, wavelength_nm: float = LAMBDA_D_NM) -> Paraxial:
    ya, ua = yu_trace(pres, 1.0, 0.0, wavelength_nm)
    yb, ub = yu_trace(pres, 0.0, 1.0, wavelength_nm)
    a, c = ya[-1], ua[-1]
    b, d = yb[-1], ub[-1]
    efl = -1.0 / c
    bfl = -a / c
    ffl = d / c  # u' = C y1 + D u1 = 0 with y1 = -z_F u1
    zl = pres.total_track_mm
    z_h = ffl + efl
    z_hp = zl + bfl - efl
    s = pres.stop_index
    # Heights at the stop plane of the two basis rays (no refraction at a plane stop in air).
    a_s = ya[s]
    b_s = yb[s]
    r_stop = pres.surfaces[s].semi_diameter_mm
    z_e = b_s / a_s
    r_e = r_stop / abs(a_s)
    # Chief ray: through the stop centre -> y1 = -B_s/A_s * u1 (u1 = 1).
    y_ch, u_ch = yu_trace(pres, -b_s / a_s, 1.0, wavelength_nm)
    z_x = zl - y_ch[-1] / u_ch[-1]
    y_m, u_m = yu_trace(pres, r_e, 0.0, wavelength_nm)
    r_x = abs(y_m[-1] + u_m[-1] * (z_x - zl))
    return Paraxial(efl, bfl, ffl, z_h, z_hp, z_e, r_e, z_x, r_x, zl)
