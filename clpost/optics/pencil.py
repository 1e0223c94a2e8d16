r"""Pencil map: the intensity across a defocused point's blur disc, traced through the real lens
per colour channel, as a function of signed defocus (Kawase, "Bokeh and Pencil Maps", SIGGRAPH
2015 course "Advances in Real-Time Rendering": precompute the lens's ray bundle per defocus, look
the bokeh's texture up in the gather).

An axial object point at planar depth S in front of the entrance pupil (lens frame: z = z_E − S,
:mod:`clpost.optics.lens`) sends a meridional fan of real rays through the entrance pupil (heights
:math:`h_k`, uniform over [0, 1.1·R_EP]; the iris clips the fan where the real stop does) of the
lens focused for the camera (:meth:`Lens.focused`); ray k lands on the film at signed height
:math:`\rho_k`. The object is on the axis, so the bundle is rotationally symmetric: the pupil
annulus :math:`[h_k, h_k + dh]` carries energy :math:`\propto h_k\,dh` (uniform pupil
irradiance; the cos⁴ fall-off across an f/1.4 pupil is < 0.1 % at S ≥ 0.4 m) onto the film circle
of radius :math:`|\rho_k|`. Binning :math:`t = |\rho|/\rho_0` with weights :math:`h_k` gives the
profile, normalised so that

.. math::

    \int_0^{T} P_c(t)\,2t\,dt = 1 \qquad (\text{a uniform disc of radius 1 is } P = 1),

where :math:`\rho_0 = |c|/2` is the thin-lens disc radius the gather already uses
(:func:`clpost.optics.coc.coc_mm`, so t = 1 is the edge of the disc the DoF stage draws, and the
traced disc may be larger, smaller or shifted in colour) and T = :data:`T_MAX`. Energy that the
real lens sends beyond T (near focus, where the SA blur exceeds the thin-lens disc) is dropped and
the rest renormalised: the gather bounds a tap's reach at T·r. Where less than half of the light
lands inside T (|c| of a pixel or so) the row is the uniform disc.

Channels are band-integrated: each channel's profile is the equal-weight mean of three
wavelengths spread over its passband (:data:`BANDS`, nm; the sRGB/Rec. 709 camera bands at their
half-maxima, approximately), each traced with the glasses' dispersion
(:meth:`Prescription.indices`). ρ₀ is the same for the three channels, so axial colour shows as
discs of different size and texture per channel (the "purple/green fringes across focus").

Table layout (what the gather reads, :func:`clpost.stages.dof.profile_weight`): ``table[c, j, i]``,
c = R, G, B; j over :data:`N_DEFOCUS` signed CoC radii :math:`r_j = r_{max}(2j/(N_D-1) - 1)`
(working px, near < 0); i over :data:`N_RADIUS` bin centres :math:`t_i = (i + \tfrac12)T/N_R`.
Cost: ``3 × 3 × N_DEFOCUS`` fans of :data:`FAN_RAYS` rays (numpy, float64), measured in
docs/bokeh_profile.md.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .trace import OK, trace

T_MAX = 1.3
"""Largest normalised radius a traced bokeh reaches in the gather (units of the thin-lens disc)."""
N_DEFOCUS = 65
"""Signed defocus rows (odd: row (N_D−1)/2 is in focus)."""
N_RADIUS = 48
"""Radial bins over [0, T_MAX]."""
FAN_RAYS = 1024
"""Rays per meridional fan."""
BANDS = ((590.0, 620.0, 650.0), (500.0, 540.0, 580.0), (440.0, 465.0, 490.0))
"""Wavelengths (nm) averaged per channel R, G, B."""
MIN_CAPTURED = 0.5
"""A row whose traced light lands less than this inside T_MAX is the uniform disc."""


@dataclass(frozen=True)
class PencilMap:
    """Traced bokeh profiles of one (lens, focus, f-number, pixel scale)."""

    table: np.ndarray  # (3, N_DEFOCUS, N_RADIUS) float64, ∫ P 2t dt = 1 per row
    rmax_px: float  # |signed CoC radius| of the outermost rows (working px)
    captured: np.ndarray  # (3, N_DEFOCUS) fraction of the traced light inside T_MAX
    seconds: float  # build time


def radius_edges(n: int = N_RADIUS, t_max: float = T_MAX) -> np.ndarray:
    return np.linspace(0.0, t_max, n + 1)


def fan_landing(lens, pres, stop_r: float, depths_mm: np.ndarray, wavelength_nm: float, f_number: float,
                n_rays: int = FAN_RAYS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Entrance heights h (mm, (n_rays,)), film heights ρ (mm) and the pass mask ((D, n_rays)) of
    the meridional fans from axial points at ``depths_mm`` (inf: parallel rays) in front of the
    entrance pupil, traced in one call."""
    par = lens.paraxial
    h = (np.arange(n_rays) + 0.5) / n_rays * 1.1 * par.efl_mm / (2.0 * f_number)
    z_e = par.z_entrance_pupil_mm
    d_mm = np.asarray(depths_mm, np.float64)[:, None] * np.ones_like(h)
    hh = np.broadcast_to(h, d_mm.shape)
    inf = np.isinf(d_mm)
    o = np.stack([np.zeros_like(d_mm), np.where(inf, hh, 0.0), np.where(inf, -1.0, z_e - np.where(inf, 0.0, d_mm))], -1)
    d = np.stack([np.zeros_like(d_mm), np.where(inf, 0.0, hh), np.where(inf, 1.0, d_mm)], -1)
    r = trace(pres, o.reshape(-1, 3), d.reshape(-1, 3), wavelength_nm, stop_radius_mm=stop_r)
    return h, r.pos[:, 1].reshape(d_mm.shape), (r.status == OK).reshape(d_mm.shape)


def row_profile(h: np.ndarray, rho: np.ndarray, ok: np.ndarray, rho0: float, edges: np.ndarray):
    """Binned, normalised profile of one fan (module docstring) and the captured fraction."""
    w = np.where(ok, h, 0.0)
    total = w.sum()
    t = np.abs(rho) / max(rho0, 1e-12)
    e, _ = np.histogram(t, bins=edges, weights=w)
    cap = float(e.sum() / total) if total > 0 else 0.0
    if cap < MIN_CAPTURED:
        p = (edges[1:] <= 1.0).astype(np.float64)
        return p / np.sum(p * np.diff(edges ** 2)), cap
    return e / e.sum() / np.diff(edges ** 2), cap


def build_pencil_map(camera, pixel_mm: float, rmax_px: float, n_defocus: int = N_DEFOCUS,
                     n_radius: int = N_RADIUS, t_max: float = T_MAX, n_rays: int = FAN_RAYS) -> PencilMap:
    """The pencil map of ``camera``'s traced lens at its focus and f-number; ``pixel_mm``: the
    working pixel's size on the film (pixel pitch × working-resolution divisor); rows span signed
    CoC radii ±``rmax_px`` working px."""
    from .coc import coc_mm

    t0 = time.perf_counter()
    lens = camera.optics
    n = camera.f_number
    pres = lens.focused(camera.focus_from_film_m * 1000.0, n)
    stop_r = lens.stop_radius_mm(n)
    edges = radius_edges(n_radius, t_max)
    r_rows = rmax_px * (2.0 * np.arange(n_defocus) / (n_defocus - 1) - 1.0)
    c_rows = 2.0 * r_rows * pixel_mm  # signed CoC diameter on the film (mm)
    # depth of each row from c = K (1/u − 1/S), K = f F / N: 1/S = 1/u − c/K (mm); beyond the far
    # limit (1/S ≤ 0) no real object has this CoC: the row of S = ∞
    u = camera.focused_depth_m * 1000.0
    k = camera.focal_length_mm * camera.render_focal_length_mm / n
    inv_s = (0.0 if math.isinf(u) else 1.0 / u) - c_rows / k
    depths = np.where(inv_s <= 0, np.inf, 1.0 / np.where(inv_s <= 0, 1.0, inv_s))
    rho0 = np.abs(coc_mm(camera, depths / 1000.0)) / 2.0
    table = np.zeros((3, n_defocus, n_radius))
    captured = np.zeros((3, n_defocus))
    for ch, band in enumerate(BANDS):
        fans = [fan_landing(lens, pres, stop_r, depths, lam, n, n_rays) for lam in band]
        h = np.concatenate([f[0] for f in fans])
        for j in range(n_defocus):
            table[ch, j], captured[ch, j] = row_profile(h, np.concatenate([f[1][j] for f in fans]),
                                                        np.concatenate([f[2][j] for f in fans]), rho0[j], edges)
    return PencilMap(table, float(rmax_px), captured, time.perf_counter() - t0)


def depth_profile(camera, depth_m: float, edges: np.ndarray, bands=BANDS, n_rays: int = FAN_RAYS):
    """(3, len(edges) − 1) profiles of the axial point at planar depth ``depth_m`` (the rows of
    :func:`build_pencil_map` at an exact depth, bins ``edges`` in t = ρ/ρ₀) and ρ₀ (mm)."""
    from .coc import coc_mm

    lens = camera.optics
    n = camera.f_number
    pres = lens.focused(camera.focus_from_film_m * 1000.0, n)
    stop_r = lens.stop_radius_mm(n)
    rho0 = abs(float(coc_mm(camera, depth_m))) / 2.0
    out = []
    for band in bands:
        fans = [fan_landing(lens, pres, stop_r, np.array([depth_m * 1000.0]), lam, n, n_rays) for lam in band]
        out.append(row_profile(np.concatenate([f[0] for f in fans]), np.concatenate([f[1][0] for f in fans]),
                               np.concatenate([f[2][0] for f in fans]), rho0, edges)[0])
    return np.array(out), rho0


def profile_at(pm: PencilMap, r_px: np.ndarray, t: np.ndarray) -> np.ndarray:
    r"""(…, 3) profile values at signed CoC radius ``r_px`` (working px) and normalised radius
    ``t``: bilinear in (row, bin centre) with clamped ends — the lookup the gather does (float64
    here; the gather's coverage ends the disc at T_MAX)."""
    nd, nr = pm.table.shape[1:]
    r = np.asarray(r_px, np.float64)
    t = np.asarray(t, np.float64)
    fj = np.clip((r / pm.rmax_px + 1.0) * 0.5 * (nd - 1), 0.0, nd - 1.0)
    j0 = np.minimum(np.floor(fj).astype(int), nd - 2)
    aj = fj - j0
    fi = np.clip(t * (nr / T_MAX) - 0.5, 0.0, nr - 1.0)
    i0 = np.minimum(np.floor(fi).astype(int), nr - 2)
    ai = fi - i0
    tab = pm.table
    out = []
    for ch in range(3):
        a = tab[ch, j0, i0] * (1 - ai) + tab[ch, j0, i0 + 1] * ai
        b = tab[ch, j0 + 1, i0] * (1 - ai) + tab[ch, j0 + 1, i0 + 1] * ai
        out.append(a * (1 - aj) + b * aj)
    return np.stack(out, -1)
