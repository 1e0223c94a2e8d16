r"""Lens ghosts: light reflected twice inside the lens (first-order model and full traces).

**Paths.** A ghost is light that reflects at surface j, travels back to an earlier surface i < j,
reflects again and then goes on to the film (the aperture stop, a plane in air, reflects
nothing). A lens of S reflecting surfaces has S(S−1)/2 two-reflection ghosts
(:func:`ghost_paths`).

**Coatings.** Every air–glass surface carries, unless the lens file says otherwise, a single
quarter-wave layer of MgF₂ (n = 1.38) designed for 550 nm; glass–glass (cemented) surfaces are
bare. A lens file overrides it per surface with ``coating = "none"`` (bare), ``"mgf2"`` or
``coating = {index = n, thickness_nm = d}`` (``lens_data/README.md``). Reflectance at normal
incidence of one layer (index n₁, thickness d) between media n₀ and n₂ (Hecht, *Optics*, 5th ed.,
§9.7.1; Macleod, *Thin-Film Optical Filters*, §2.2):

.. math::

    R = \frac{r_{01}^2 + r_{12}^2 + 2 r_{01} r_{12}\cos 2\delta}
             {1 + r_{01}^2 r_{12}^2 + 2 r_{01} r_{12}\cos 2\delta},\qquad
    r_{ab} = \frac{n_a - n_b}{n_a + n_b},\qquad \delta = \frac{2\pi n_1 d}{\lambda}

(a lossless stack reflects alike from both sides). At the design wavelength of a quarter-wave layer
:math:`R = \big((n_0 n_2 - n_1^2)/(n_0 n_2 + n_1^2)\big)^2`; with d = 0 it is the bare Fresnel
:math:`r_{02}^2`. Ghosts are evaluated at normal incidence (the paraxial limit).

**First order (Lee & Eisemann 2013, "Practical Real-Time Lens-Flare Rendering", EGSR).** A
ghost path is a product of 2 × 2 ray-transfer matrices acting on (height y, slope θ) measured
along the direction of travel: a gap d is :math:`y \mathrel{+}= d\,\theta`; refraction from n to
n' at a surface whose curvature seen along the travel is c (−c when travelling toward the
object) is :math:`\theta' = (n\theta - y\,c\,(n' - n))/n'` (Smith, *Modern Optical Engineering*,
§2.5); reflection is :math:`\theta' = \theta + 2 c\,y`. An incoming parallel beam at angle θ
meets the first vertex at heights y; the path reaches the film at
:math:`y_f = A y + B\theta` and crosses the stop at :math:`y_s = A_s y + B_s\theta`. The stop
admits :math:`y_s` in the aperture (radius r, the bladed shape), so the ghost on the film is the
aperture scaled by :math:`A/A_s` (negative: turned by 180°) and centred at
:math:`(B - A B_s/A_s)\,\theta`. The direct path (no reflection) gives the source's own image
centre :math:`c_0\theta`, so a source at image position p throws the ghost centred at
:math:`p\,(B - A B_s/A_s)/c_0` — on the line through the image centre — with radius
:math:`|A/A_s|\,r`. A path that crosses the stop three times (i < stop < j) is limited by the
crossing with the largest :math:`|A_s|` (the narrowest beam; the other two are ignored); the
beam is also limited to the first surface's clear semi-diameter. The share of the source's flux
in the ghost is

.. math::

    \rho = R_i R_j \left(\frac{\min(r/|A_s|,\ h_1)}{r/|A_{s,0}|}\right)^2

(the beam it takes over the direct path's entrance pupil, r/|A_{s,0}|). Element clear apertures
other than the first, and aberrations, are left out; the full traces (:func:`trace_ghost`)
measure what that costs (docs/flare.md).

**Full traces.** :func:`trace_path` is the sequential tracer of :mod:`clpost.optics.trace` (same
intersection and vector Snell formulas) for rays that may travel either way, with reflections;
on a path without reflections it equals :func:`clpost.optics.trace.trace` (tested to 1e-9 mm).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .prescription import Prescription
from .trace import CLIPPED, MISS, OK, STOP, TIR, film_z

MGF2_INDEX = 1.38
DESIGN_NM = 550.0
MGF2_QUARTER_WAVE = (MGF2_INDEX, DESIGN_NM / (4.0 * MGF2_INDEX))
"""(layer index, thickness nm) of the default coating: quarter-wave MgF₂ at 550 nm (99.6 nm)."""
BARE = (1.0, 0.0)
"""A layer of zero thickness: the bare Fresnel reflectance."""


def layer_reflectance(n0, n2, n1: float, thickness_nm: float, wavelength_nm) -> np.ndarray:
    """R of one thin layer (index n1, thickness) between n0 and n2 at normal incidence (module docstring)."""
    n0, n2, lam = (np.asarray(v, np.float64) for v in (n0, n2, wavelength_nm))
    r01, r12 = (n0 - n1) / (n0 + n1), (n1 - n2) / (n1 + n2)
    cos2d = np.cos(2.0 * (2.0 * math.pi * n1 * thickness_nm / lam))
    num = r01 ** 2 + r12 ** 2 + 2 * r01 * r12 * cos2d
    return num / (1.0 + r01 ** 2 * r12 ** 2 + 2 * r01 * r12 * cos2d)


def surface_coating(pres: Prescription, k: int) -> tuple[float, float]:
    """(layer index, thickness nm) of surface k: the lens file's, else MgF₂ on air–glass, bare on glass–glass."""
    own = getattr(pres.surfaces[k], "coating", None)
    if own is not None:
        return own
    n_before = 1.0 if k == 0 else pres.surfaces[k - 1].n_d
    air_glass = (n_before == 1.0) != (pres.surfaces[k].n_d == 1.0)
    return MGF2_QUARTER_WAVE if air_glass else BARE


def surface_reflectance(pres: Prescription, k: int, wavelength_nm: float) -> float:
    """Reflectance of surface k at ``wavelength_nm`` (its coating between the media either side)."""
    n = pres.indices(wavelength_nm)
    n_before = 1.0 if k == 0 else n[k - 1]
    layer = surface_coating(pres, k)
    return float(layer_reflectance(n_before, n[k], layer[0], layer[1], wavelength_nm))


def ghost_paths(pres: Prescription) -> list[tuple[int, int]]:
    """(i, j), i < j: reflect at j, then at i; every pair of surfaces but the stop."""
    refl = [k for k, s in enumerate(pres.surfaces) if not s.stop]
    return [(i, j) for a, i in enumerate(refl) for j in refl[a + 1:]]


def path_events(n_surfaces: int, ghost: tuple[int, int] | None) -> list[tuple[int, str, int]]:
    """The surfaces a path meets in order: (surface, "refract"|"reflect", direction +1/−1)."""
    if ghost is None:
        return [(k, "refract", 1) for k in range(n_surfaces)]
    i, j = ghost
    return ([(k, "refract", 1) for k in range(j)] + [(j, "reflect", 1)]
            + [(k, "refract", -1) for k in range(j - 1, i, -1)] + [(i, "reflect", -1)]
            + [(k, "refract", 1) for k in range(i + 1, n_surfaces)])


def _media(n: np.ndarray, k: int, direction: int) -> tuple[float, float]:
    """(index before, index after) surface k for light travelling ``direction``."""
    left = 1.0 if k == 0 else float(n[k - 1])
    right = float(n[k])
    return (left, right) if direction > 0 else (right, left)


def paraxial_path(pres: Prescription, ghost, wavelength_nm: float, z_film: float | None = None):
    """First-order matrices of a path: ((A, B) at the film, [(A_s, B_s) at each stop crossing])."""
    n = pres.indices(wavelength_nm)
    zs = pres.vertex_z
    zf = film_z(pres) if z_film is None else z_film
    stop = pres.stop_index
    rays = np.array([[1.0, 0.0], [0.0, 1.0]])  # (y, θ) of the two basis rays, rows
    z_prev = 0.0
    crossings = []
    for k, kind, direction in path_events(len(pres.surfaces), ghost):
        rays[:, 0] += abs(zs[k] - z_prev) * rays[:, 1]
        z_prev = zs[k]
        c = pres.surfaces[k].curvature * direction
        n1, n2 = _media(n, k, direction)
        y, th = rays[:, 0], rays[:, 1]
        if kind == "reflect":
            rays[:, 1] = th + 2.0 * c * y
        else:
            rays[:, 1] = (n1 * th - y * c * (n2 - n1)) / n2
        if k == stop:
            crossings.append((rays[0, 0], rays[1, 0]))
    rays[:, 0] += (zf - z_prev) * rays[:, 1]
    return (rays[0, 0], rays[1, 0]), crossings


@dataclass(frozen=True)
class Ghost:
    """One ghost at one wavelength (first order; lengths in mm on the film)."""

    path: tuple[int, int]
    centre_factor: float
    """Ghost centre / source image position (signed; on the line through the image centre)."""
    scale: float
    """Film size of the aperture image per mm of stop radius (signed: negative is turned 180°)."""
    radius_mm: float
    share: float
    """ρ: the share of the source's flux in this ghost."""


def ghosts(pres: Prescription, stop_radius_mm: float, wavelength_nm: float,
           z_film: float | None = None) -> list[Ghost]:
    """Every two-reflection ghost of ``pres`` (focused: its last thickness is the film distance)."""
    (a0, b0), cr0 = paraxial_path(pres, None, wavelength_nm, z_film)
    as0, bs0 = cr0[0]
    c0 = b0 - a0 * bs0 / as0
    y0 = stop_radius_mm / abs(as0)
    h1 = pres.surfaces[0].semi_diameter_mm
    out = []
    for path in ghost_paths(pres):
        (a, b), cr = paraxial_path(pres, path, wavelength_nm, z_film)
        as_, bs = max(cr, key=lambda ab: abs(ab[0]))
        if as_ == 0.0:
            continue
        refl = surface_reflectance(pres, path[0], wavelength_nm) * surface_reflectance(pres, path[1], wavelength_nm)
        y_g = min(stop_radius_mm / abs(as_), h1)
        scale = a / as_
        out.append(Ghost(path, (b - a * bs / as_) / c0, scale, abs(scale) * stop_radius_mm,
                         refl * (y_g / y0) ** 2))
    return out


# -- full traces ------------------------------------------------------------------------------

def trace_path(pres: Prescription, ghost, origins, directions, wavelength_nm: float,
               stop_radius_mm: float | None = None, clip: bool = True, z_film: float | None = None,
               aperture: tuple[int, float, float] | None = None):
    """Real rays along a path (module docstring): (positions at the film (N, 3), status (N,)).
    ``aperture``: (blades, rotation °, roundness) of a bladed stop (the DoF stage's shape, angle
    atan2(y, x) of the stop plane's coordinates); None: a round stop."""
    n = pres.indices(wavelength_nm)
    zs = pres.vertex_z
    zf = film_z(pres) if z_film is None else z_film
    o = np.array(origins, np.float64).reshape(-1, 3).copy()
    d = np.array(directions, np.float64).reshape(-1, 3).copy()
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    status = np.zeros(len(o), np.int8)
    with np.errstate(invalid="ignore", divide="ignore"):
        for k, kind, direction in path_events(len(pres.surfaces), ghost):
            s = pres.surfaces[k]
            c = s.curvature
            alive = status == OK
            p = o - np.array([0.0, 0.0, zs[k]])
            bq = c * np.einsum("ij,ij->i", p, d) - d[:, 2]
            cc = c * np.einsum("ij,ij->i", p, p) - 2.0 * p[:, 2]
            disc = bq * bq - c * cc
            sq = np.sqrt(np.maximum(disc, 0.0))
            # the vertex-side root in the form without cancellation (trace.py's, and its mirror
            # image z → −z for rays travelling toward the object)
            if direction > 0:
                t = np.where(-bq > 0, cc / (-bq + sq), (-bq - sq) / c)
            else:
                t = np.where(bq > 0, cc / (-bq - sq), (-bq + sq) / c)
            miss = alive & ((disc < 0) | ~np.isfinite(t) | (t < -1e-9))
            status[miss] = MISS
            alive &= ~miss
            q = p + t[:, None] * d
            sd = stop_radius_mm if (s.stop and stop_radius_mm is not None) else s.semi_diameter_mm
            if clip or s.stop:
                if s.stop and aperture is not None:
                    from ..stages.dof import aperture_radius

                    sd = sd * aperture_radius(np.arctan2(q[:, 1], q[:, 0]), *aperture)
                out = alive & (q[:, 0] ** 2 + q[:, 1] ** 2 > sd * sd)
                status[out] = STOP if s.stop else CLIPPED
                alive &= ~out
            nrm = np.stack([c * q[:, 0], c * q[:, 1], c * q[:, 2] - 1.0], axis=1)
            nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
            nrm = np.where((np.einsum("ij,ij->i", d, nrm) > 0)[:, None], -nrm, nrm)
            cosi = -np.einsum("ij,ij->i", d, nrm)
            if kind == "reflect":
                new_d = d + 2.0 * cosi[:, None] * nrm
            else:
                n1, n2 = _media(n, k, direction)
                mu = n1 / n2
                kk = 1.0 - mu * mu * (1.0 - cosi * cosi)
                tir = alive & (kk < 0)
                status[tir] = TIR
                alive &= ~tir
                new_d = mu * d + (mu * cosi - np.sqrt(np.maximum(kk, 0.0)))[:, None] * nrm
            o[alive] = (q + np.array([0.0, 0.0, zs[k]]))[alive]
            d[alive] = new_d[alive]
        alive = status == OK
        back = alive & ~(d[:, 2] > 0)
        status[back] = MISS
        alive &= ~back
        t = (zf - o[:, 2]) / d[:, 2]
        o[alive] = o[alive] + t[alive, None] * d[alive]
    return o, status


def parallel_beam(theta_rad: float, radius_mm: float, n: int, z0: float = -5.0):
    """A square grid of n × n parallel rays at field angle θ (in the x–z plane) filling a disc of
    ``radius_mm`` at the first vertex (z = 0): (origins, directions)."""
    u = np.linspace(-radius_mm, radius_mm, n)
    x, y = np.meshgrid(u, u)
    keep = x ** 2 + y ** 2 <= radius_mm ** 2
    x, y = x[keep], y[keep]
    dvec = np.array([math.sin(theta_rad), 0.0, math.cos(theta_rad)])
    o = np.stack([x + z0 * dvec[0] / dvec[2], y, np.full_like(x, z0)], 1)  # meets z = 0 at (x, y)
    return o, np.broadcast_to(dvec, o.shape).copy()


def traced_ghost(pres: Prescription, ghost, theta_rad: float, stop_radius_mm: float, wavelength_nm: float,
                 n: int = 161, clip: bool = False, z_film: float | None = None) -> dict:
    """A ghost (or the direct image, ``ghost=None``) by full traces of a parallel beam at θ:
    centroid x (mm), radius (√2 × the RMS distance from the centroid: a uniform disc's radius, mm)
    and the share of the beam's rays that arrive."""
    o, d = parallel_beam(theta_rad, pres.surfaces[0].semi_diameter_mm, n)
    pos, status = trace_path(pres, ghost, o, d, wavelength_nm, stop_radius_mm, clip, z_film)
    ok = status == OK
    if not ok.any():
        return dict(x=float("nan"), radius=float("nan"), fraction=0.0, n=0)
    p = pos[ok, :2]
    cx = float(p[:, 0].mean())
    rms = float(np.sqrt(np.mean((p[:, 0] - cx) ** 2 + (p[:, 1] - p[:, 1].mean()) ** 2)))
    return dict(x=cx, radius=math.sqrt(2.0) * rms, fraction=float(ok.mean()), n=int(ok.sum()))


# -- traced fit -------------------------------------------------------------------------------

FIT_FIELD_DEG = (0.5, 1.5, 2.5, 4.0, 6.0, 9.0, 13.0, 18.0, 24.0)
"""Field angles (degrees) at which :func:`fit_ghosts` traces every ghost (beyond the ends: held);
dense near the axis, where stopped-down ghosts are cut off by element apertures within a few degrees."""
FIT_RAYS = 27
"""Rays across each of the two grids of one ghost and field angle (~570 in each disc)."""
AIM_MARGIN = 1.5
"""The aimed grid's radius over the first-order beam's r/|A_s|."""


def _beams(pres: Prescription, ghost, thetas, stop_radius_mm: float, wavelength_nm: float,
           z_film: float | None, n: int):
    """Parallel beams at each field angle: a fine n × n grid aimed (first order) at the rays that
    pass the stop on ``ghost``'s path — a disc of AIM_MARGIN · r/|A_s| around the height
    −B_s tan θ/A_s at the first vertex — and a coarse n × n grid over the rest of the first
    surface (real bundles of caustic ghosts pass the stop far from the paraxial aim). Returns
    (origins, directions, angle index, ray weight mm²: its grid cell)."""
    _, cr = paraxial_path(pres, ghost, wavelength_nm, z_film)
    as_, bs = max(cr, key=lambda ab: abs(ab[0]))
    h1 = pres.surfaces[0].semi_diameter_mm
    rad = min(AIM_MARGIN * stop_radius_mm / abs(as_), h1)
    u = np.linspace(-rad, rad, n)
    fx, fy = (v.ravel() for v in np.meshgrid(u, u))
    fine = fx ** 2 + fy ** 2 <= rad * rad
    fx, fy = fx[fine], fy[fine]
    v = np.linspace(-h1, h1, n)
    cx_, cy_ = (w.ravel() for w in np.meshgrid(v, v))
    coarse = cx_ ** 2 + cy_ ** 2 <= h1 * h1
    cx_, cy_ = cx_[coarse], cy_[coarse]
    cells = ((u[1] - u[0]) ** 2, (v[1] - v[0]) ** 2)
    os_, ds, idx, wts = [], [], [], []
    z0 = -5.0
    for k, th in enumerate(thetas):
        yc = float(np.clip(-bs * math.tan(th) / as_, -h1, h1))
        outside = (cx_ - yc) ** 2 + cy_ ** 2 > rad * rad
        x = np.concatenate([fx + yc, cx_[outside]])
        y = np.concatenate([fy, cy_[outside]])
        dvec = np.array([math.sin(th), 0.0, math.cos(th)])
        os_.append(np.stack([x + z0 * dvec[0] / dvec[2], y, np.full_like(x, z0)], 1))
        ds.append(np.broadcast_to(dvec, (len(x), 3)))
        idx.append(np.full(len(x), k))
        wts.append(np.concatenate([np.full(len(fx), cells[0]), np.full(int(outside.sum()), cells[1])]))
    return np.concatenate(os_), np.concatenate(ds), np.concatenate(idx), np.concatenate(wts)


def fit_ghosts(pres: Prescription, stop_radius_mm: float, wavelength_nm: float,
               thetas_deg=FIT_FIELD_DEG, z_film: float | None = None,
               aperture: tuple[int, float, float] | None = None, n: int = FIT_RAYS) -> dict:
    r"""Every two-reflection ghost fitted from real traces (element apertures clip, aberrations
    move and spread the bundle) at the field angles ``thetas_deg``: for each path and angle the
    centroid on the film over the direct image's centroid (the centre factor), √2 × the RMS
    distance from the centroid (a uniform disc's radius, mm) and the share

    .. math:: \rho = R_i R_j\,\frac{A_\text{ghost}}{A_\text{direct}}

    (A: the beam cross-section, summed over rays (each its grid cell), that reaches the film
    along the path; the beams of :func:`_beams`; centroid and RMS weighted by cell). Returns dict of arrays:
    ``paths`` (G, 2), ``centre`` / ``radius_mm`` / ``share`` (G, T) (share 0, centre and radius
    NaN where no ray arrives), ``direct_mm`` (T,) the direct image's centroid, ``thetas_deg``."""
    thetas = [math.radians(t) for t in thetas_deg]
    nt = len(thetas)

    def run(ghost):
        o, d, idx, wt = _beams(pres, ghost, thetas, stop_radius_mm, wavelength_nm, z_film, n)
        pos, status = trace_path(pres, ghost, o, d, wavelength_nm, stop_radius_mm, True, z_film, aperture)
        ok = status == OK
        i, w = idx[ok], wt[ok]
        area = np.bincount(i, w, nt)
        with np.errstate(invalid="ignore", divide="ignore"):
            cx = np.bincount(i, w * pos[ok, 0], nt) / area
            cy = np.bincount(i, w * pos[ok, 1], nt) / area
            r2 = np.bincount(i, w * ((pos[ok, 0] - cx[i]) ** 2 + (pos[ok, 1] - cy[i]) ** 2), nt) / area
        return cx, np.sqrt(2.0 * r2), area

    dx, _, da = run(None)
    paths = ghost_paths(pres)
    out = dict(paths=np.array(paths), centre=np.full((len(paths), nt), np.nan),
               radius_mm=np.full((len(paths), nt), np.nan), share=np.zeros((len(paths), nt)),
               direct_mm=dx, thetas_deg=np.array(thetas_deg, np.float64))
    for g, path in enumerate(paths):
        gx, gr, ga = run(path)
        refl = surface_reflectance(pres, path[0], wavelength_nm) * surface_reflectance(pres, path[1], wavelength_nm)
        arrived = ga > 0
        out["centre"][g, arrived] = gx[arrived] / dx[arrived]
        out["radius_mm"][g, arrived] = gr[arrived]
        out["share"][g] = np.where(arrived, refl * ga / da, 0.0)
    return out


def fit_weights(direct_mm: np.ndarray, height_mm: float) -> tuple[int, int, float]:
    """(i0, i1, f): a source at image height ``height_mm`` takes (1 − f) of the fit at angle i0 and
    f of i1 (linear in the direct image's height; held beyond the grid's ends)."""
    t = float(np.interp(height_mm, direct_mm, np.arange(len(direct_mm))))
    i0 = min(int(t), len(direct_mm) - 1)
    return i0, min(i0 + 1, len(direct_mm) - 1), t - i0


def check_rows(name="zeiss-planar-50-f1.4", n=8.0, field_deg=2.0, count=8, wavelength_nm=550.0) -> list[dict]:
    """The ``count`` brightest first-order ghosts of lens ``name`` at f/``n``, ``field_deg`` off
    axis: each one's share, centre factor and radius as first order gives them, as the stage's fit
    gives them (:func:`fit_ghosts` interpolated by :func:`fit_weights`) and as a dense clipped
    trace gives them (:func:`traced_ghost`) — the check of docs/flare.md (tools/ghost_check.py
    prints it)."""
    from . import get_lens

    lens = get_lens(name)
    pres = lens.focused(3000.0, n)
    r = lens.stop_radius_mm(n)
    theta = math.radians(field_deg)
    direct = traced_ghost(pres, None, theta, r, wavelength_nm, clip=True)
    fit = fit_ghosts(pres, r, wavelength_nm)
    i0, i1, f = fit_weights(fit["direct_mm"], direct["x"])
    index = {tuple(p): k for k, p in enumerate(fit["paths"])}
    gs = sorted(ghosts(pres, r, wavelength_nm), key=lambda g: -g.share / g.radius_mm ** 2)[:count]
    out = []
    for g in gs:
        t = traced_ghost(pres, g.path, theta, r, wavelength_nm, clip=True)
        refl = surface_reflectance(pres, g.path[0], wavelength_nm) * surface_reflectance(pres, g.path[1], wavelength_nm)
        k = index[g.path]

        def at(a):
            v0, v1 = a[k, i0], a[k, i1]
            v0, v1 = (v1 if np.isnan(v0) else v0), (v0 if np.isnan(v1) else v1)
            return (1 - f) * v0 + f * v1

        out.append(dict(path=g.path, share=g.share, share_fit=at(fit["share"]),
                        share_traced=refl * t["fraction"] / direct["fraction"],
                        centre=g.centre_factor, centre_fit=at(fit["centre"]), centre_traced=t["x"] / direct["x"],
                        radius=g.radius_mm, radius_fit=at(fit["radius_mm"]), radius_traced=t["radius"]))
    return out
