r"""Manufacturer-style lens curves derived by tracing the real prescription.

Everything is a function of the image height r (mm on the film, 0 … ``image_height_max_mm``,
default the 36×24 half diagonal 21.63 mm, or less where the lens's image circle ends) for one
(lens, focus, f-number); :meth:`clpost.optics.Lens.curves` caches them on the lens object, since
they change only when those do (this module computes; it never looks a lens up by name).
Field points are parametrised by the angle θ of the chief ray in object space, measured at the
entrance pupil; for a finite focus the object point lies on the focused object plane.

* **distortion** (%): :math:`100\,(r_{real} - r_{par})/r_{par}` with r_real the real chief-ray
  height (the ray through the stop centre, found by Newton iteration on its aim point) and
  :math:`r_{par} = K\tan\theta` the paraxial chief-ray height at the same film plane; 0 on axis.
* **relative illumination**: irradiance at r over irradiance on axis, from ray bundles that
  fill a grid over the entrance pupil (projected perpendicular to the beam, so the cos θ of the
  foreshortened pupil is included); rays clipped by any semi-diameter or the iris are dropped
  (optical vignetting). Energy conservation gives, for an object at infinity,

  .. math::

      E(\theta) \propto \frac{A_\perp(\theta)\,\sin\theta}{r\,\mathrm{d}r/\mathrm{d}\theta}

  which is :math:`\cos^4\theta` for a distortion-free lens with a constant pupil (natural
  vignetting) and includes pupil aberrations and distortion exactly. For a finite object the
  passing rays are weighted by :math:`\cos^2\gamma/\rho^2` (projected solid angle from the
  object point) and the image-area Jacobian is :math:`r\,\mathrm{d}r/(Y\,\mathrm{d}Y)`.
  Fresnel and absorption losses are not modelled (they are the Camera's ``transmittance``).
* **sagittal / tangential focal offsets** (mm along z, + = behind the film): where rays offset by
  ±1 % of the pupil from the chief ray in x (sagittal) or y (tangential) cross it (Coddington's
  astigmatic foci by finite differences). Field curvature is their mean, astigmatism their difference.
* **longitudinal spherical aberration** (mm) vs normalised pupil height ρ ∈ (0, 1]: axial
  crossing of the axial ray at ρ minus that of the ρ → 0 ray (paraxial focus);
  ``sa_transverse_mm`` is the ray's height on the film (drives SA bokeh).
* **lateral colour** (mm): chief-ray height at F (486.1 nm) minus at C (656.3 nm); 0 for lenses
  without dispersion data.
* **pupil shape**: for a few field heights, the boolean mask of passing rays on the projected
  entrance-pupil grid (``pupil_grid`` in units of the axial entrance-pupil radius at this
  f-number; y is the radial direction, + away from the axis): the cat's eye of optical vignetting.

References: W. J. Smith, *Modern Optical Engineering*, 4th ed., §§3, 10 (aberration curves,
relative illumination); Kolb, Mitchell & Hanrahan, "A Realistic Camera Model for Computer
Graphics", SIGGRAPH 1995.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .paraxial import yu_trace
from .prescription import LAMBDA_C_NM, LAMBDA_D_NM, LAMBDA_F_NM
from .trace import trace

FULL_FRAME_HALF_DIAGONAL_MM = math.hypot(36.0, 24.0) / 2


@dataclass(frozen=True)
class LensCurves:
    """Curves of one lens at one focus and f-number. Arrays are read-only float64."""

    lens: str
    focus_distance_m: float
    f_number: float
    image_height_mm: np.ndarray
    field_angle_deg: np.ndarray
    distortion_pct: np.ndarray
    relative_illumination: np.ndarray
    sagittal_offset_mm: np.ndarray
    tangential_offset_mm: np.ndarray
    lateral_color_mm: np.ndarray
    pupil_rho: np.ndarray
    lsa_mm: np.ndarray
    sa_transverse_mm: np.ndarray
    pupil_field_mm: np.ndarray
    pupil_grid: np.ndarray
    pupil_masks: np.ndarray  # (len(pupil_field_mm), G, G) bool, [iy, ix]
    entrance_pupil_radius_mm: float

    @property
    def image_height_max_mm(self) -> float:
        return float(self.image_height_mm[-1])

    def at(self, name: str, r_mm) -> np.ndarray:
        """Curve ``name`` interpolated (linearly) at image heights ``r_mm`` (clamped to the range)."""
        y = getattr(self, name)
        return np.interp(np.abs(np.asarray(r_mm, np.float64)), self.image_height_mm, y)

    def pupil_area_fraction(self) -> np.ndarray:
        """Passing pupil area at each ``pupil_field_mm`` relative to the axial pupil."""
        cell = (self.pupil_grid[1] - self.pupil_grid[0]) ** 2
        return self.pupil_masks.sum(axis=(1, 2)) * cell / math.pi


def _start_z(pres) -> float:
    s = pres.surfaces[0]
    return min(0.0, s.sag(s.semi_diameter_mm)) - 1.0


class _Field:
    """Ray generation for field angle(s) θ and aim points on the entrance-pupil plane."""

    def __init__(self, lens, pres, focus_mm: float, stop_r: float):
        self.lens, self.pres, self.stop_r = lens, pres, stop_r
        self.z_e = lens.paraxial.z_entrance_pupil_mm
        self.z0 = _start_z(pres)
        zf = pres.vertex_z[-1] + pres.surfaces[-1].thickness_mm
        self.z_film = zf
        self.z_obj = None if math.isinf(focus_mm) else zf - focus_mm

    def rays(self, theta, ax, ay):
        theta, ax, ay = np.broadcast_arrays(*(np.asarray(v, np.float64) for v in (theta, ax, ay)))
        aim = np.stack([ax, ay, np.full_like(ax, self.z_e)], -1)
        if self.z_obj is None:
            d = np.stack([np.zeros_like(theta), np.sin(theta), np.cos(theta)], -1)
            o = aim - ((self.z_e - self.z0) / np.cos(theta))[..., None] * d
        else:
            yobj = -(self.z_e - self.z_obj) * np.tan(theta)
            o = np.stack([np.zeros_like(theta), yobj, np.full_like(theta, self.z_obj)], -1)
            d = aim - o
        return o.reshape(-1, 3), d.reshape(-1, 3)

    def trace(self, theta, ax, ay, clip=True, wavelength_nm=LAMBDA_D_NM):
        o, d = self.rays(theta, ax, ay)
        return trace(self.pres, o, d, wavelength_nm=wavelength_nm, clip=clip, stop_radius_mm=self.stop_r)

    def chief_aim(self, theta, wavelength_nm=LAMBDA_D_NM) -> np.ndarray:
        """Aim heights a(θ) on the entrance-pupil plane of the rays through the stop centre.

        A scan of candidate aims over ±2 front semi-diameters brackets the sign change of the
        stop height (wide-angle pupils move far from their paraxial place and rays aimed at the
        paraxial pupil may miss or reflect totally), then Newton polishes it.
        """
        theta = np.asarray(theta, np.float64)
        span = 2.0 * self.pres.surfaces[0].semi_diameter_mm
        cand = np.linspace(-span, span, 257)
        rs = self.trace(theta[:, None], 0.0, cand[None, :], clip=False, wavelength_nm=wavelength_nm)
        sy = rs.stop_xy[:, 1].reshape(theta.size, cand.size)
        okc = (rs.status == 0).reshape(sy.shape)
        flip = okc[:, :-1] & okc[:, 1:] & (np.sign(sy[:, :-1]) != np.sign(sy[:, 1:]))
        # The bracket nearest the paraxial aim (0) wins.
        dist = np.where(flip, np.abs(cand[:-1])[None, :], np.inf)
        j = np.argmin(dist, axis=1)
        has = np.isfinite(dist[np.arange(theta.size), j])
        s0, s1 = sy[np.arange(theta.size), j], sy[np.arange(theta.size), j + 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            a = np.where(has, cand[j] - s0 * (cand[j + 1] - cand[j]) / (s1 - s0), 0.0)
        eps = 1e-4 * max(self.lens.paraxial.entrance_pupil_radius_mm, 1e-3)
        for _ in range(12):
            r0 = self.trace(theta, 0.0, a, clip=False, wavelength_nm=wavelength_nm)
            r1 = self.trace(theta, 0.0, a + eps, clip=False, wavelength_nm=wavelength_nm)
            s0, s1 = r0.stop_xy[:, 1], r1.stop_xy[:, 1]
            slope = (s1 - s0) / eps
            ok = (r0.status == 0) & (r1.status == 0) & (np.abs(slope) > 1e-12)
            step = np.where(ok, s0 / np.where(ok, slope, 1.0), 0.0)
            step = np.clip(step, -eps * 1e3, eps * 1e3)
            a = a - step
            if np.all(np.abs(step) < 1e-13):
                break
        return a


def _paraxial_chief_gain(lens, pres, fld: _Field) -> float:
    """K of r_par = K tan θ: paraxial chief ray through the entrance-pupil centre to the film."""
    y, u = yu_trace(pres, -fld.z_e, 1.0)  # slope 1, crossing the axis at z_E
    return float(y[-1] + u[-1] * pres.surfaces[-1].thickness_mm)


def compute_curves(lens, focus_distance_m: float, f_number: float,
                   image_height_max_mm: float = FULL_FRAME_HALF_DIAGONAL_MM,
                   n_fields: int = 48, pupil_samples: int = 64) -> LensCurves:
    focus_mm = focus_distance_m * 1000.0
    pres = lens.focused(focus_mm, f_number)
    stop_r = lens.stop_radius_mm(f_number)
    fld = _Field(lens, pres, focus_mm, stop_r)
    # Axial beam radius at infinity for this f-number (real rays: EFL / 2N by construction).
    r_e = lens.efl_mm / (2.0 * f_number)
    k_par = _paraxial_chief_gain(lens, pres, fld)

    # Field angles: up to where the chief ray reaches r_max or stops being traceable/monotonic.
    th_lim = min(math.radians(88.0), 2.5 * math.atan(image_height_max_mm / abs(k_par)))
    th = np.linspace(0.0, th_lim, 400)
    a = fld.chief_aim(th)
    rr = fld.trace(th, 0.0, a, clip=False)
    r = rr.pos[:, 1]
    good = (rr.status == 0) & (np.abs(rr.stop_xy[:, 1]) < 1e-6 * max(stop_r, 1.0))
    stop_at = np.argmin(good) if not good.all() else len(th)
    mono = np.diff(r[:stop_at]) > 0
    end = (np.argmin(mono) + 1) if not mono.all() else stop_at
    r_end = min(image_height_max_mm, float(r[end - 1]))
    th_end = float(np.interp(r_end, r[:end], th[:end]))

    # Fine field grid in θ (uniform in r would be ideal; θ(r) is monotonic, interpolate).
    r_grid_f = np.linspace(0.0, r_end, n_fields)
    th_f = np.interp(r_grid_f, r[:end], th[:end])
    th_f[-1] = th_end
    a_f = fld.chief_aim(th_f)
    rc = fld.trace(th_f, 0.0, a_f, clip=False)
    r_real = rc.pos[:, 1]
    r_par = k_par * np.tan(th_f)
    with np.errstate(invalid="ignore", divide="ignore"):
        dist = np.where(th_f > 0, 100.0 * (r_real - r_par) / r_par, 0.0)

    # Relative illumination from pupil grids.
    g = (np.arange(pupil_samples) + 0.5) / pupil_samples * 3.2 - 1.6  # ±1.6 pupil radii
    gx, gy = np.meshgrid(g, g)
    cell = (g[1] - g[0]) ** 2

    def pupil(theta, aim):
        t = np.asarray(theta)[:, None, None]
        c = np.cos(t)
        rays = fld.trace(t, gx[None] * r_e, aim[:, None, None] + gy[None] * r_e / c)
        ok = rays.ok.reshape(len(theta), pupil_samples, pupil_samples)
        if fld.z_obj is None:
            w = np.broadcast_to(np.ones_like(c), ok.shape)
        else:
            o, d = fld.rays(t, gx[None] * r_e, aim[:, None, None] + gy[None] * r_e / c)
            d = d.reshape(ok.shape + (3,))
            rho2 = np.sum(d * d, -1)
            w = (d[..., 2] ** 2 / rho2) / rho2 / c * (fld.z_e - fld.z_obj) ** 2
        return ok, (ok * w).sum(axis=(1, 2)) * cell

    masks, power = pupil(th_f, a_f)
    if fld.z_obj is None:
        jac_x = np.sin(th_f)
        dx = np.cos(th_f)
    else:
        yobj = (fld.z_e - fld.z_obj) * np.tan(th_f)
        jac_x = yobj
        dx = (fld.z_e - fld.z_obj) / np.cos(th_f) ** 2
    drdth = np.gradient(r_real, th_f, edge_order=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        e = power * np.where(th_f > 0, jac_x / (r_real * drdth), dx / drdth ** 2)
    ri = np.clip(e / e[0], 0.0, 1.0) if e[0] > 0 else np.zeros_like(e)

    # Astigmatic foci (unclipped: the field curves of the lens design, as datasheets plot them).
    dlt = 0.01 * r_e
    t4 = np.repeat(th_f, 4)
    ax = np.tile([0.0, 0.0, dlt, -dlt], n_fields)
    ay = np.repeat(a_f, 4) + np.tile([dlt, -dlt, 0.0, 0.0], n_fields) / np.cos(t4)
    ra = fld.trace(t4, ax, ay, clip=False)
    p = ra.pos.reshape(n_fields, 4, 3)
    dd = ra.dir.reshape(n_fields, 4, 3)
    m = dd[..., :2] / dd[..., 2:3]
    with np.errstate(invalid="ignore", divide="ignore"):
        tan_off = -(p[:, 0, 1] - p[:, 1, 1]) / (m[:, 0, 1] - m[:, 1, 1])
        sag_off = -0.5 * (p[:, 2, 0] / m[:, 2, 0] + p[:, 3, 0] / m[:, 3, 0])
    tan_off = np.nan_to_num(tan_off)
    sag_off = np.nan_to_num(sag_off)

    # Lateral colour.
    if pres.has_dispersion:
        hf = fld.trace(th_f, 0.0, fld.chief_aim(th_f, LAMBDA_F_NM), clip=False, wavelength_nm=LAMBDA_F_NM).pos[:, 1]
        hc = fld.trace(th_f, 0.0, fld.chief_aim(th_f, LAMBDA_C_NM), clip=False, wavelength_nm=LAMBDA_C_NM).pos[:, 1]
        lat = hf - hc
    else:
        lat = np.zeros(n_fields)

    # Longitudinal spherical aberration on axis.
    rho = np.linspace(0.0, 1.0, 33)
    rho[0] = 1e-4
    z0 = np.zeros_like(rho)
    hs = rho * r_e
    ro = fld.trace(z0, 0.0, hs, clip=False)
    my = ro.dir[:, 1] / ro.dir[:, 2]
    z_cross = fld.z_film - ro.pos[:, 1] / my
    lsa = z_cross - z_cross[0]
    lsa[0] = 0.0
    sa_tr = ro.pos[:, 1]
    rho[0] = 0.0
    sa_tr[0] = 0.0

    # Pupil shape at a few field heights.
    pf = np.linspace(0.0, r_end, 7)
    th_p = np.interp(pf, r_real, th_f)
    pm, _ = pupil(th_p, fld.chief_aim(th_p))

    def ro_(x):
        x = np.ascontiguousarray(x)
        x.setflags(write=False)
        return x

    return LensCurves(
        lens=lens.name, focus_distance_m=float(focus_distance_m), f_number=float(f_number),
        image_height_mm=ro_(r_grid_f), field_angle_deg=ro_(np.degrees(th_f)),
        distortion_pct=ro_(dist), relative_illumination=ro_(ri),
        sagittal_offset_mm=ro_(sag_off), tangential_offset_mm=ro_(tan_off),
        lateral_color_mm=ro_(lat), pupil_rho=ro_(rho), lsa_mm=ro_(lsa), sa_transverse_mm=ro_(sa_tr),
        pupil_field_mm=ro_(pf), pupil_grid=ro_(g), pupil_masks=ro_(pm), entrance_pupil_radius_mm=r_e)
