r"""A real lens: prescription + paraxial data + iris + unit focusing, solved with real rays.

**Iris and f-number.** The f-number N sets the iris so that the real axial beam from infinity
has diameter EFL/N: a ray parallel to the axis at height h = EFL/(2N) is traced to the stop,
and its height there is the iris radius (exact for real rays, not only paraxially). The lens's
maximum aperture N_max is the N whose beam just fills the stop of the file, found by bisection
on h; smaller f-numbers are clamped to N_max with a warning.

**Unit focusing.** The whole lens moves; the film stays. :meth:`Lens.focus` takes the
lens-scale distance D **from the film plane** to the object (as engraved on a focus ring);
:meth:`Lens.focus_depth` takes the object's planar **depth in front of the entrance pupil** — the
depth a pinhole render measures, its pinhole standing for the entrance pupil (the centre of
projection of the chief rays) — and returns the same :class:`FocusState`. Unit focusing moves the
pupil with the lens, so an object at depth d sits at the fixed lens-frame position z_E − d and its
best image z* does not depend on the lens position: b = z* − z_L, D = z* − (z_E − d). For a lens
position (last vertex → film = b) the best image of an axial object point is the plane of least
RMS spot radius of a real meridional fan filling the iris (weights ∝ pupil radius, i.e. equal
pupil area): for rays y_i + m_i (z − z_L)

.. math::

    z^* = z_L - \frac{\sum_i w_i y_i m_i}{\sum_i w_i m_i^2}

and b is the root of z*(b) − (z_L + b) = 0 (secant from the thin-lens guess). So the lens is
focused at the taking aperture (focus shift of spherical aberration included).

**Thin-lens equivalent** (what a CoC formula uses): f = EFL, v = f + extension (the real lens
travel from its infinity position), u_thin = 1/(1/f − 1/v). It differs from the real object
distance measured from the front principal plane H by
:attr:`FocusState.thin_lens_error_mm` (pupil aberrations, spherical aberration, H–H' gap).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import InputError
from .curves import FULL_FRAME_HALF_DIAGONAL_MM, LensCurves, compute_curves
from .paraxial import Paraxial, paraxial, yu_trace
from .prescription import LAMBDA_D_NM, Prescription, load_prescription
from .trace import OK, trace


class FNumberClampedWarning(UserWarning):
    """An f-number below the lens's maximum aperture was clamped to it."""


@dataclass(frozen=True)
class FocusState:
    """Where the lens sits for an object at ``distance_mm`` from the film (mm, z from the
    first vertex in the lens's own frame)."""

    distance_mm: float  # film → object (inf for infinity)
    back_distance_mm: float  # last vertex → film
    extension_mm: float  # lens travel from infinity focus (>= 0)
    image_distance_mm: float  # v of the thin-lens equivalent: EFL + extension
    object_distance_from_h_mm: float  # front principal plane H → object
    thin_lens_object_distance_mm: float  # 1/(1/f - 1/v)
    magnification: float  # paraxial lateral magnification (negative: inverted; 0 at infinity)
    depth_mm: float = math.inf  # entrance pupil → object, planar (what a depth pass measures)
    render_focal_mm: float = math.nan  # K: film height of the paraxial chief ray per tan θ (object side)
    """The focal length of the pinhole camera (at the entrance pupil) that images like the lens at
    this focus: a point at angle θ from the axis seen from the entrance pupil lands at K tan θ on the
    film (paraxially; distortion is the real chief ray's departure from it). K/EFL is focus breathing."""

    @property
    def thin_lens_error_mm(self) -> float:
        """Thin-lens object distance minus the real one (both from H); 0 at infinity."""
        if math.isinf(self.distance_mm):
            return 0.0
        return self.thin_lens_object_distance_mm - self.object_distance_from_h_mm


class Lens:
    """A real lens from ``lens_data/``. Cheap queries (EFL, pupils) are attributes; focusing
    and curves are cached per (focus, f-number)."""

    def __init__(self, pres: Prescription):
        self.prescription = pres
        self.name = pres.name
        self.paraxial: Paraxial = paraxial(pres)
        self.efl_mm = self.paraxial.efl_mm
        self.stop_radius_max_mm = pres.surfaces[pres.stop_index].semi_diameter_mm
        self._h_max = self._max_axial_height()
        self.max_aperture = self.efl_mm / (2 * self._h_max)
        """Smallest f-number the real stop allows (wide open)."""
        self.min_aperture = max(pres.f_number_min_aperture, self.max_aperture)
        self.min_focus_m = pres.min_focus_m
        self._focus_cache: dict = {}
        self._curves_cache: dict = {}

    # -- aperture -------------------------------------------------------------------------------
    def _axial_rays(self, h: np.ndarray, z0: float = -1.0, **kw):
        h = np.atleast_1d(np.asarray(h, np.float64))
        o = np.stack([np.zeros_like(h), h, np.full_like(h, z0)], axis=1)
        d = np.tile([0.0, 0.0, 1.0], (h.size, 1))
        return trace(self.prescription, o, d, **kw)

    def _max_axial_height(self) -> float:
        """Largest entrance height of an axial parallel ray that passes every surface."""
        lo, hi = 0.0, self.paraxial.entrance_pupil_radius_mm * 2.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if self._axial_rays(mid).status[0] == OK:
                lo = mid
            else:
                hi = mid
        return lo

    def clamp_f_number(self, f_number: float, warn: bool = True) -> float:
        """``f_number`` limited to [max aperture, min aperture]; warns when clamping."""
        n = float(f_number)
        if n < self.max_aperture * (1 - 1e-9):
            if warn:
                warnings.warn(f"lens {self.name}: f/{n:g} is beyond its maximum aperture; using "
                              f"f/{self.max_aperture:.3g}", FNumberClampedWarning, stacklevel=3)
            return self.max_aperture
        if n > self.min_aperture * (1 + 1e-9):
            if warn:
                warnings.warn(f"lens {self.name}: f/{n:g} is beyond its smallest aperture; using "
                              f"f/{self.min_aperture:.3g}", FNumberClampedWarning, stacklevel=3)
            return self.min_aperture
        return n

    def stop_radius_mm(self, f_number: float) -> float:
        """Iris radius (mm) for f-number N: stop height of the real axial ray at EFL/(2N)."""
        n = self.clamp_f_number(f_number, warn=False)
        h = self.efl_mm / (2 * n)
        if h >= self._h_max:
            return self.stop_radius_max_mm
        r = self._axial_rays(h, clip=False)
        return float(min(abs(r.stop_xy[0, 1]), self.stop_radius_max_mm))

    # -- focusing -------------------------------------------------------------------------------
    def _best_focus_z(self, b: float, distance_mm: float, stop_r: float, wavelength_nm=LAMBDA_D_NM):
        """z* (least RMS meridional spot) for an axial object, lens with back distance b."""
        pres = self.prescription.with_back_distance(b)
        zl = pres.total_track_mm
        rho = (np.arange(1, 65) - 0.5) / 64.0
        # Aim at the entrance pupil plane; oversize and let the iris select the rays.
        aim = rho * self.paraxial.entrance_pupil_radius_mm * 1.6
        if math.isinf(distance_mm):
            o = np.stack([np.zeros_like(aim), aim, np.full_like(aim, -1.0)], axis=1)
            d = np.tile([0.0, 0.0, 1.0], (aim.size, 1))
        else:
            z_obj = zl + b - distance_mm
            o = np.tile([0.0, 0.0, z_obj], (aim.size, 1))
            d = np.stack([np.zeros_like(aim), aim, np.full_like(aim, self.paraxial.z_entrance_pupil_mm - z_obj)], 1)
        r = trace(pres, o, d, wavelength_nm=wavelength_nm, stop_radius_mm=stop_r)
        ok = r.ok
        if ok.sum() < 2:
            raise InputError(f"lens {self.name}: no axial rays pass at this focus/aperture")
        y = r.pos[ok, 1] - r.dir[ok, 1] / r.dir[ok, 2] * (r.pos[ok, 2] - zl)  # height at z_L
        m = r.dir[ok, 1] / r.dir[ok, 2]
        w = np.abs(y) + 1e-300  # area weight ∝ pupil radius
        return zl - np.sum(w * y * m) / np.sum(w * m * m)

    def focus(self, distance_mm: float, f_number: float | None = None) -> FocusState:
        """Solve unit focusing for an object ``distance_mm`` from the film (``inf`` allowed)."""
        n = self.max_aperture if f_number is None else self.clamp_f_number(f_number, warn=False)
        key = (float(distance_mm), round(n, 12))
        hit = self._focus_cache.get(key)
        if hit is not None:
            return hit
        stop_r = self.stop_radius_mm(n)
        zl = self.prescription.total_track_mm
        b_par = self.paraxial.bfl_mm
        b_inf = self._b_inf(n)
        f = self.efl_mm
        if math.isinf(distance_mm):
            b = b_inf
        else:
            # thin-lens guess from the paraxial principal planes, then secant on the real focus.
            hh = self.paraxial.z_principal_rear_mm - self.paraxial.z_principal_front_mm
            span = distance_mm - hh
            if span <= 4 * f:
                raise InputError(f"lens {self.name}: focus distance {distance_mm / 1000:g} m from the film is "
                                 f"closer than any real image allows (> {(4 * f + hh) / 1000:.3g} m)")
            v = 0.5 * span * (1 - math.sqrt(1 - 4 * f / span))
            b0 = b_inf + (v - f)

            def g(bb):
                return self._best_focus_z(bb, distance_mm, stop_r) - (zl + bb)

            b1 = b0 + 1e-3
            g0, g1 = g(b0), g(b1)
            for _ in range(30):
                if g1 == g0:
                    break
                b2 = b1 - g1 * (b1 - b0) / (g1 - g0)
                b0, g0 = b1, g1
                b1, g1 = b2, g(b2)
                if abs(g1) < 1e-10:
                    break
            b = b1
        st = self._state(float(distance_mm), float(b), float(b_inf))
        self._focus_cache[key] = st
        return st

    def _b_inf(self, n: float) -> float:
        """Last vertex → film at infinity focus (the real best focus at f-number ``n``)."""
        key = ("b_inf", round(n, 12))
        if key not in self._focus_cache:
            zl = self.prescription.total_track_mm
            self._focus_cache[key] = self._best_focus_z(self.paraxial.bfl_mm, math.inf, self.stop_radius_mm(n)) - zl
        return self._focus_cache[key]

    def _state(self, distance_mm: float, b: float, b_inf: float) -> FocusState:
        """The :class:`FocusState` of the lens at back distance ``b`` focused on ``distance_mm``."""
        f, zl = self.efl_mm, self.prescription.total_track_mm
        # v of the thin-lens equivalent: f plus the real extension, so v = f exactly at infinity
        # (the film sits at the real best focus, which spherical aberration moves off the
        # paraxial focus; measuring v from H' would count that shift as focusing).
        v = f + (b - b_inf)
        u_thin = math.inf if v <= f else 1.0 / (1.0 / f - 1.0 / v)
        z_e = self.paraxial.z_entrance_pupil_mm
        if math.isinf(distance_mm):
            u_h = depth = math.inf
            mag = 0.0
        else:
            z_obj = zl + b - distance_mm
            u_h = self.paraxial.z_principal_front_mm - z_obj
            depth = z_e - z_obj
            mag = -v / u_h
        y, u = yu_trace(self.prescription.with_back_distance(b), -z_e, 1.0)  # paraxial chief ray, slope 1
        k = float(y[-1] + u[-1] * b)
        return FocusState(distance_mm, b, b - b_inf, v, u_h, u_thin, mag, depth, k)

    def focus_depth(self, depth_mm: float, f_number: float | None = None) -> FocusState:
        """Solve unit focusing for an object at planar depth ``depth_mm`` in front of the entrance
        pupil (``inf`` allowed): the same :class:`FocusState` as :meth:`focus` at the film distance
        it returns (module docstring)."""
        n = self.max_aperture if f_number is None else self.clamp_f_number(f_number, warn=False)
        if math.isinf(depth_mm):
            return self.focus(math.inf, n)
        key = ("depth", float(depth_mm), round(n, 12))
        hit = self._focus_cache.get(key)
        if hit is not None:
            return hit
        zl, b_par = self.prescription.total_track_mm, self.paraxial.bfl_mm
        z_obj = self.paraxial.z_entrance_pupil_mm - float(depth_mm)
        front = min(0.0, self.prescription.surfaces[0].sag(self.prescription.surfaces[0].semi_diameter_mm))
        if not (depth_mm > 0 and z_obj < front):
            raise InputError(f"lens {self.name}: depth {depth_mm / 1000:g} m puts the object inside the lens "
                             f"(its front vertex is {(self.paraxial.z_entrance_pupil_mm - front) / 1000:.3g} m "
                             "in front of the entrance pupil)")
        z_star = self._best_focus_z(b_par, zl + b_par - z_obj, self.stop_radius_mm(n))
        if not (z_star - zl > 0 and z_star > z_obj):
            raise InputError(f"lens {self.name}: depth {depth_mm / 1000:g} m is closer than any real image allows "
                             "(the object is inside the front focal length)")
        st = self._state(z_star - z_obj, z_star - zl, self._b_inf(n))
        self._focus_cache[key] = st
        return st

    def focused(self, distance_mm: float, f_number: float | None = None) -> Prescription:
        """The prescription with its last thickness set for this focus."""
        return self.prescription.with_back_distance(self.focus(distance_mm, f_number).back_distance_mm)

    def curves(self, focus_distance_m: float = math.inf, f_number: float | None = None,
               image_height_max_mm: float = FULL_FRAME_HALF_DIAGONAL_MM) -> LensCurves:
        """Derived curves (:class:`clpost.optics.curves.LensCurves`) at this focus (m, from the
        film) and f-number (clamped to the lens's range; None: wide open), cached on the lens."""
        n = self.max_aperture if f_number is None else self.clamp_f_number(f_number, warn=False)
        return self._curves(float(focus_distance_m), round(n, 9), float(image_height_max_mm))

    _CURVES_KEPT = 64
    """Curves kept per lens (an animated focus asks for new ones every frame; oldest go first)."""

    def _curves(self, focus_distance_m: float, f_number: float, image_height_max_mm: float) -> LensCurves:
        key = (focus_distance_m, f_number, image_height_max_mm)
        hit = self._curves_cache.get(key)
        if hit is None:
            hit = compute_curves(self, focus_distance_m, f_number, image_height_max_mm)
            if len(self._curves_cache) >= self._CURVES_KEPT:
                self._curves_cache.pop(next(iter(self._curves_cache)))
            self._curves_cache[key] = hit
        return hit

    def __repr__(self) -> str:
        return f"Lens({self.name!r}, EFL {self.efl_mm:.4g} mm, f/{self.max_aperture:.3g})"


@lru_cache(maxsize=None)
def get_lens(name: str) -> Lens:
    """The :class:`Lens` for a ``lens_data`` name (built once per process)."""
    return Lens(load_prescription(name))


def lens_curves(name: str, focus_distance_m: float, f_number: float,
                image_height_max_mm: float = FULL_FRAME_HALF_DIAGONAL_MM) -> LensCurves:
    """The curves of the ``lens_data`` lens ``name`` at exactly this f-number (not clamped),
    cached on its :class:`Lens`."""
    return get_lens(name)._curves(float(focus_distance_m), float(f_number), float(image_height_max_mm))
