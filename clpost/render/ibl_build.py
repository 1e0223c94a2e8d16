r"""The image-based lens model of Heidrich, Slusallek & Seidel ("An Image-Based Model for
Realistic Lens Systems in Interactive Computer Graphics", Graphics Interface 1997): its
preprocessing — the set of perspective projections that replaces a real lens for one point of
its exit pupil — built from the real ray tracer (:mod:`clpost.optics.trace`). Frames and the ray functions used
below (backward tracing, pupil sampling, the COP fit): :mod:`clpost.render.ibl_rays`.

For every pupil sample :math:`p_i` (stratified: an n×n grid of cell centres mapped to the disc
by Shirley's concentric map, on the paraxial exit-pupil plane — the lens_data achromat and
singlet have their stop at the front face, so points on the last surface would be vignetted for
most of the film — inside the radius the axial film point sees through the stopped-down iris):

1. **Grid rays** (sec. 3.2): a regular grid on a film cell (10×10 by default), each ray from
   its film point x' through :math:`p_i`, traced back to the object side: points q and unit
   directions d.
2. **Vignetting** (sec. 3.4): border grid points whose ray does not pass are moved toward the
   cell centre by bisection (40 steps) until they pass; the inner points are then placed evenly
   inside by the Coons patch of the moved border.
3. **Virtual centre of projection** (sec. 3.3): the e that maximises

   .. math:: F(e) = \sum_k \frac{\langle d_k \mid q_k - e\rangle^2}{\lVert q_k - e\rVert^2},

   i.e. minimises the angles between each ray and the line from e through its point, by Newton
   iteration (analytic gradient, central-difference Hessian, halving steps that do not increase
   F, and refusing points in front of a ray's point: cos² also rewards the antipode), started
   from the lens centre (the entrance pupil on the axis) or from the parent cell's e — or from
   the least-squares point nearest to all rays where that has the larger F (nearly parallel
   bundles of small cells put e far away, where Newton from the centre is slow).
   The ray-angle error is :math:`\max_k \angle(d_k, q_k - e)`.
4. **Subdivision** (sec. 3.2): where that error exceeds the threshold (0.05° as in the paper),
   the cell is split as a quad-tree and each quadrant gets its own grid and fit.

Each leaf is a :class:`Projection`: e, the film grid, the texture coordinates of the grid rays
in the projection's image plane (camera-space :math:`(X/Z, Y/Z)` of the ray's point on the plane of focus, seen from e, whose
bounding box is the off-axis frustum) and the weights of sec. 3.5,

.. math:: W(x') = \frac{\cos\theta'\cos\theta''}{\lVert x'' - x'\rVert^2},

θ' between the ray and the film normal, θ'' between the ray and the exit-pupil plane's normal
at :math:`x'' = p_i` (both the optical axis). :func:`build` caches the result per (lens, focus, aperture, sampling).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from ..errors import InputError
from ..optics import get_lens
from ..optics.prescription import available_lenses
from .ibl_rays import (angle_errors_deg, fit_cop, focus_plane_z_mm, image_plane_tex, mirrored_table, pupil_samples,
                       trace_back)

THRESHOLD_DEG = 0.05
"""The paper's ray-angle error threshold."""


@dataclass(frozen=True)
class Projection:
    pupil_index: int
    depth: int
    cell_mm: tuple[float, float, float, float]  # film x0, x1, y0, y1 (lens frame, mm)
    cop_mm: np.ndarray  # virtual centre of projection e (lens frame, mm)
    film_mm: np.ndarray  # (n, n, 2) grid points on the film after vignetting
    tex: np.ndarray  # (n, n, 2) camera-space (X/Z, Y/Z) of the ray at the focus plane − e (image_plane_tex)
    weight: np.ndarray  # (n, n) W(x') of sec. 3.5 (1/mm²), 0 where the ray does not pass
    max_angle_deg: float
    frustum: tuple[float, float, float, float]  # bounding box of tex: x0, x1, y0, y1

    @property
    def cop_camera_m(self) -> np.ndarray:
        """e in camera space (metres), camera origin at the film centre (:mod:`clpost.render.ibl_rays`)."""
        return np.array([self.cop_mm[0], -self.cop_mm[1], -(self.cop_mm[2] - self._z_film)]) / 1000.0

    _z_film: float = 0.0


@dataclass
class ImageBasedLens:
    lens: str
    focus_distance_m: float
    f_number: float
    sensor_mm: tuple[float, float]
    pupil_samples_mm: np.ndarray  # (k, 3)
    projections: list[Projection] = field(default_factory=list)
    threshold_deg: float = THRESHOLD_DEG
    preprocess_s: float = 0.0
    dropped_cells: int = 0
    # warp data per output size (clpost.render.ibl_warp.warp_cells): the model is fixed once built
    warp_cache: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def max_angle_deg(self) -> float:
        return max((p.max_angle_deg for p in self.projections), default=0.0)

    def projections_per_sample(self) -> np.ndarray:
        return np.bincount([p.pupil_index for p in self.projections], minlength=len(self.pupil_samples_mm))


def _coons(border: dict, n: int) -> np.ndarray:
    """Grid (n×n×2) from four border curves (bottom j=0, top j=n−1 along i; left i=0, right
    i=n−1 along j) by the bilinearly blended Coons patch."""
    s = np.linspace(0, 1, n)
    bot, top, left, right = border["b"], border["t"], border["l"], border["r"]
    u, v = s[None, :, None], s[:, None, None]  # grid[j, i]
    ruled_v = (1 - v) * bot[None, :, :] + v * top[None, :, :]
    ruled_u = (1 - u) * left[:, None, :] + u * right[:, None, :]
    corners = ((1 - u) * (1 - v) * bot[0] + u * (1 - v) * bot[-1] + (1 - u) * v * top[0] + u * v * top[-1])
    return ruled_v + ruled_u - corners


def _vignetting_grid(table, zf, p, cell, n):
    """The film grid of a cell after sec. 3.4 (None when the cell centre is vignetted)."""
    x0, x1, y0, y1 = cell
    gx, gy = np.meshgrid(np.linspace(x0, x1, n), np.linspace(y0, y1, n))
    grid = np.stack([gx, gy], -1)
    _, _, ok = trace_back(table, zf, grid.reshape(-1, 2), p)
    if ok.all():
        return grid
    centre = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1)])
    if not trace_back(table, zf, centre[None], p)[2][0]:
        return None
    border = {"b": grid[0].copy(), "t": grid[-1].copy(), "l": grid[:, 0].copy(), "r": grid[:, -1].copy()}
    for key, pts in border.items():
        _, _, pass_ = trace_back(table, zf, pts, p)
        lo, hi = np.zeros(len(pts)), np.ones(len(pts))
        lo[pass_] = 1.0
        for _ in range(24):
            mid = 0.5 * (lo + hi)
            _, _, okm = trace_back(table, zf, centre + mid[:, None] * (pts - centre), p)
            lo = np.where(okm & ~pass_, mid, lo)
            hi = np.where(~okm & ~pass_, mid, hi)
        border[key] = centre + lo[:, None] * (pts - centre)
    # corners are shared by two border curves: use the one pulled in further
    for (a, ia), (b, ib) in ((("b", 0), ("l", 0)), (("b", -1), ("r", 0)), (("t", 0), ("l", -1)), (("t", -1), ("r", -1))):
        pa, pb = border[a][ia], border[b][ib]
        pick = pa if np.linalg.norm(pa - centre) < np.linalg.norm(pb - centre) else pb
        border[a][ia] = border[b][ib] = pick
    return _coons(border, n)


def _projection(pres, table, zf, p, index, cell, grid, e, depth, z_plane_mm):
    n = grid.shape[0]
    q, d, ok = trace_back(table, zf, grid.reshape(-1, 2), p)
    err = angle_errors_deg(q[ok], d[ok], e)
    tex = image_plane_tex(q, d, e, z_plane_mm)
    x1 = np.concatenate([grid.reshape(-1, 2), np.full((n * n, 1), zf)], 1)
    ray = p[None, :] - x1
    dist = np.linalg.norm(ray, axis=1)
    cos1 = np.abs(ray[:, 2]) / dist
    cos2 = cos1  # the exit-pupil plane is parallel to the film
    w = np.where(ok, cos1 * cos2 / (dist * dist), 0.0)
    t_ok = tex[ok]
    fr = (float(t_ok[:, 0].min()), float(t_ok[:, 0].max()), float(t_ok[:, 1].min()), float(t_ok[:, 1].max()))
    proj = Projection(index, depth, cell, e, grid, tex.reshape(n, n, 2), w.reshape(n, n),
                      float(err.max(initial=0.0)), fr)
    object.__setattr__(proj, "_z_film", zf)
    return proj, float(err.max(initial=0.0))


@lru_cache(maxsize=16)
def build(lens: str, focus_distance_m: float = math.inf, f_number: float | None = None,
          sensor_mm: tuple[float, float] = (36.0, 24.0), grid: int = 10, pupil_n: int = 3,
          threshold_deg: float = THRESHOLD_DEG, max_depth: int = 4, pupil_pattern: str = "grid",
          pupil_count: int | None = None) -> ImageBasedLens:
    """The image-based model of ``lens`` (a ``lens_data`` name) focused at ``focus_distance_m``
    (lens-scale: from the film, :meth:`clpost.optics.Lens.focus`; a Camera's is its
    ``focus_from_film_m``) at ``f_number``; cached per arguments (module docstring).
    ``pupil_count``: that many spiral pupil samples instead of ``pupil_n``² (e.g. the paper's 10)."""
    if lens not in available_lenses():
        raise InputError(f"lens {lens!r} is not in lens_data/; choose one of {', '.join(available_lenses())}")
    if int(grid) != grid or grid < 2:
        raise InputError(f"grid={grid!r} must be an integer >= 2 (rays per cell side; the paper uses 10)")
    if int(pupil_n) != pupil_n or pupil_n < 1:
        raise InputError(f"pupil_n={pupil_n!r} must be an integer >= 1 (pupil samples per side)")
    if pupil_pattern not in ("grid", "spiral"):
        raise InputError(f"pupil_pattern={pupil_pattern!r} must be 'grid' or 'spiral' (pupil_samples)")
    if pupil_count is not None and (pupil_pattern != "spiral" or int(pupil_count) != pupil_count or pupil_count < 1):
        raise InputError(f"pupil_count={pupil_count!r} needs pupil_pattern='spiral' and an integer >= 1 "
                         "(the grid pattern has pupil_n² samples)")
    if not (math.isfinite(threshold_deg) and threshold_deg > 0):
        raise InputError(f"threshold_deg={threshold_deg!r} must be > 0 degrees (the paper uses 0.05)")
    if len(sensor_mm) != 2 or not all(math.isfinite(s) and s > 0 for s in sensor_mm):
        raise InputError(f"sensor_mm={sensor_mm!r} must be (width, height) in mm > 0")
    t0 = time.perf_counter()
    L = get_lens(lens)
    n_num = L.clamp_f_number(f_number if f_number is not None else L.max_aperture)
    dist_mm = focus_distance_m * 1000.0 if math.isfinite(focus_distance_m) else math.inf
    pres = L.focused(dist_mm, n_num)
    table, zf = mirrored_table(pres, L.stop_radius_mm(n_num))
    samples = pupil_samples(pres, table, zf, L.paraxial.z_exit_pupil_mm, int(pupil_n), pupil_pattern,
                            pupil_count)
    e_root = np.array([0.0, 0.0, L.paraxial.z_entrance_pupil_mm])
    model = ImageBasedLens(lens, float(focus_distance_m), float(n_num), tuple(sensor_mm), samples,
                           threshold_deg=float(threshold_deg))
    hw, hh = 0.5 * sensor_mm[0], 0.5 * sensor_mm[1]
    z_plane = focus_plane_z_mm(float(focus_distance_m), zf)

    def recurse(index, p, cell, e0, depth):
        g = _vignetting_grid(table, zf, p, cell, int(grid))
        if g is None:
            if depth < max_depth:
                x0, x1, y0, y1 = cell
                xm, ym = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
                for c in ((x0, xm, y0, ym), (xm, x1, y0, ym), (x0, xm, ym, y1), (xm, x1, ym, y1)):
                    recurse(index, p, c, e0, depth + 1)
            else:
                model.dropped_cells += 1
            return
        q, d, ok = trace_back(table, zf, g.reshape(-1, 2), p)
        if ok.sum() < 4:
            model.dropped_cells += 1
            return
        e = fit_cop(q[ok], d[ok], e0)
        proj, err = _projection(pres, table, zf, p, index, cell, g, e, depth, z_plane)
        if err > threshold_deg and depth < max_depth:
            x0, x1, y0, y1 = cell
            xm, ym = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
            for c in ((x0, xm, y0, ym), (xm, x1, y0, ym), (x0, xm, ym, y1), (xm, x1, ym, y1)):
                recurse(index, p, c, e, depth + 1)
            return
        model.projections.append(proj)

    for i, p in enumerate(samples):
        recurse(i, p, (-hw, hw, -hh, hh), e_root, 0)
    model.preprocess_s = time.perf_counter() - t0
    return model


def model_for_camera(camera, *, pupil_n: int = 3, threshold_deg: float = THRESHOLD_DEG, max_depth: int = 4,
                     grid: int = 10, pupil_pattern: str = "grid") -> ImageBasedLens:
    """The cached model of a :class:`~clpost.camera.Camera` with a ``lens_data`` lens (auto
    f-number: the lens wide open)."""
    if camera.optics is None:
        raise InputError(f"the image-based lens model needs a real lens from lens_data (--lens "
                         f"{', '.join(available_lenses())}); {camera.lens!r} is a thin lens")
    return build(camera.lens, float(camera.focus_from_film_m), camera.f_number, tuple(camera.sensor_mm),
                 grid=grid, pupil_n=pupil_n, threshold_deg=threshold_deg, max_depth=max_depth,
                 pupil_pattern=pupil_pattern)
