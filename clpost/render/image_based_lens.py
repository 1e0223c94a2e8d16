r"""The image-based lens model of Heidrich, Slusallek & Seidel ("An Image-Based Model for
Realistic Lens Systems in Interactive Computer Graphics", Graphics Interface 1997): its
preprocessing — the set of perspective projections that replaces a real lens for one point of
its exit pupil — built from the real ray tracer (:mod:`clpost.optics.trace`).

Frames. The lens frame is the prescription's (mm, z from the first vertex, light toward +z, film
at :math:`z_f`). Rays are traced **backwards**, film → object, through the mirrored prescription
(:math:`z' = z_f - z`, curvatures negated, each surface's indices swapped), so the forward tracer
is reused unchanged. A camera-space direction (X right, Y down, Z forward) is the lens-frame
direction (x, −y, −z); the camera origin is the film centre (focus distances of real lenses are
measured from the film, ``shared/CONVENTIONS.md``).

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
from ..optics.trace import OK, surface_table, trace_table

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
        """e in camera space (metres), camera origin at the film centre (see the module)."""
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

    @property
    def max_angle_deg(self) -> float:
        return max((p.max_angle_deg for p in self.projections), default=0.0)

    def projections_per_sample(self) -> np.ndarray:
        return np.bincount([p.pupil_index for p in self.projections], minlength=len(self.pupil_samples_mm))


# ---------------------------------------------------------------------------------------------
# Backward tracing through the mirrored prescription
# ---------------------------------------------------------------------------------------------


def mirrored_table(pres, stop_radius_mm: float) -> tuple[np.ndarray, float]:
    """The :func:`surface_table` of the prescription seen from the film: z' = z_f − z, c' = −c,
    index after each surface = the forward index before it. Returns (table, z_f)."""
    fwd = surface_table(pres, stop_radius_mm=stop_radius_mm)
    zf = float(pres.vertex_z[-1] + pres.surfaces[-1].thickness_mm)
    rows = []
    for k in range(len(fwd) - 1, -1, -1):
        zk, c, sd, _, is_stop = fwd[k]
        n_before = fwd[k - 1, 3] if k > 0 else 1.0
        rows.append((zf - zk, -c, sd, n_before, is_stop))
    return np.array(rows), zf


def trace_back(table: np.ndarray, zf: float, film_xy: np.ndarray, p: np.ndarray):
    """Rays from film points (N×2, mm) through the exit-side point p (lens frame) to the object
    side: (q, d, ok) in the lens frame — q on the plane 1 mm before the first vertex, d unit and
    pointing to the object (d_z < 0)."""
    film_xy = np.asarray(film_xy, np.float64).reshape(-1, 2)
    o = np.concatenate([film_xy, np.zeros((len(film_xy), 1))], 1)
    pm = np.array([p[0], p[1], zf - p[2]])
    r = trace_table(table, o, pm[None, :] - o, zf + 1.0)
    q = r.pos.copy()
    d = r.dir.copy()
    q[:, 2] = zf - q[:, 2]
    d[:, 2] = -d[:, 2]
    return q, d, r.status == OK


# ---------------------------------------------------------------------------------------------
# Pupil sampling, the COP fit and vignetting
# ---------------------------------------------------------------------------------------------


def _concentric(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shirley–Chiu concentric map of [−1, 1]² onto the unit disc (area preserving)."""
    a, b = u, v
    big = np.abs(a) > np.abs(b)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(big, a, b)
        phi = np.where(big, (math.pi / 4) * b / a, math.pi / 2 - (math.pi / 4) * a / b)
    phi = np.where((a == 0) & (b == 0), 0.0, phi)
    return r * np.cos(phi), r * np.sin(phi)


def pupil_samples(pres, table, zf, z_exit_mm: float, n: int, pattern: str = "grid") -> np.ndarray:
    r"""n² stratified points on the exit-pupil plane z = ``z_exit_mm``, inside the radius R
    through which the axial film point's rays pass the stopped-down iris (bisection).

    ``pattern``: ``"grid"`` — the n×n cell centres mapped by the concentric map (rows and
    columns: a defocused highlight shows as an n×n array of copies); ``"spiral"`` — the Vogel
    (golden-angle) spiral :math:`r_k = R\sqrt{(k + ½)/n^2},\ \varphi_k = k \cdot 137.5°`,
    equally stratified in area but with no rows, so the copies of a defocused point fill its
    blur disc evenly instead of lining up (the same count, the same cost)."""
    lo, hi = 0.0, 4.0 * float(pres.surfaces[-1].semi_diameter_mm)
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        if trace_back(table, zf, np.zeros((1, 2)), np.array([mid, 0.0, z_exit_mm]))[2][0]:
            lo = mid
        else:
            hi = mid
    if pattern == "spiral":
        k = np.arange(n * n)
        rad, phi = np.sqrt((k + 0.5) / (n * n)), k * math.pi * (3.0 - math.sqrt(5.0))
        x, y = rad * np.cos(phi), rad * np.sin(phi)
        return np.stack([lo * 0.999 * x, lo * 0.999 * y, np.full(x.shape, z_exit_mm)], -1)
    g = (np.arange(n) + 0.5) / n * 2 - 1
    u, v = np.meshgrid(g, g)
    x, y = _concentric(u.ravel(), v.ravel())
    return np.stack([lo * 0.999 * x, lo * 0.999 * y, np.full(x.shape, z_exit_mm)], -1)


def fit_cop(q: np.ndarray, d: np.ndarray, e0: np.ndarray, iters: int = 60, max_step_mm: float = 5.0) -> np.ndarray:
    r"""Newton maximisation of :math:`F(e) = \sum \langle d|q-e\rangle^2/\lVert q-e\rVert^2`
    (module docstring) from ``e0``; d unit. Steps that do not increase F are halved."""
    def f_and_grad(e):
        r = q - e
        s = np.einsum("ij,ij->i", d, r)
        n2 = np.einsum("ij,ij->i", r, r)
        f = np.sum(s * s / n2)
        # dF/de = −Σ (2 s d / n2 − 2 s² r / n2²)
        g = -np.sum(2 * (s / n2)[:, None] * d - 2 * (s * s / (n2 * n2))[:, None] * r, axis=0)
        return f, g

    def behind(e):  # e on the lens side of every ray point (cos² alone also rewards the antipode)
        return bool(np.all(np.einsum("ij,ij->i", d, q - e) > 0))

    # also try the least-squares point nearest to all rays (closed form); keep the better start
    proj = np.eye(3)[None] - d[:, :, None] * d[:, None, :]
    try:
        e_ls = np.linalg.solve(proj.sum(0), np.einsum("kij,kj->i", proj, q))
    except np.linalg.LinAlgError:
        e_ls = None
    e = np.asarray(e0, np.float64).copy()
    f, g = f_and_grad(e)
    if e_ls is not None and np.all(np.isfinite(e_ls)) and behind(e_ls) and f_and_grad(e_ls)[0] > f:
        e = e_ls
        f, g = f_and_grad(e)
    for _ in range(iters):
        h = 1e-4 * max(1.0, float(np.abs(e).max()))
        hess = np.empty((3, 3))
        for k in range(3):
            dk = np.zeros(3)
            dk[k] = h
            hess[:, k] = (f_and_grad(e + dk)[1] - f_and_grad(e - dk)[1]) / (2 * h)
        try:
            step = -np.linalg.solve(hess, g)
        except np.linalg.LinAlgError:
            step = g * 1e-3
        norm = np.linalg.norm(step)
        if norm > max_step_mm:  # trust region: F is bounded and flat far away (e → ∞ along the rays)
            step *= max_step_mm / norm
        if np.dot(step, g) <= 0:  # not an ascent direction (Hessian not negative definite): gradient
            step = g / max(np.linalg.norm(g), 1e-300) * min(1.0, np.linalg.norm(step))
        t = 1.0
        while t > 1e-8:
            f_new, g_new = f_and_grad(e + t * step)
            if f_new >= f and behind(e + t * step):
                break
            t *= 0.5
        if t <= 1e-8:
            break
        e, f_prev, f, g = e + t * step, f, f_new, g_new
        if abs(f - f_prev) <= 1e-15 * max(f, 1.0) and np.linalg.norm(t * step) < 1e-10:
            break
    return e


def angle_errors_deg(q: np.ndarray, d: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Angle between each ray direction d and the approximating ray q − e (degrees)."""
    r = q - e
    c = np.einsum("ij,ij->i", d, r) / np.linalg.norm(r, axis=1)
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def image_plane_tex(q: np.ndarray, d: np.ndarray, e: np.ndarray, z_plane_mm: float) -> np.ndarray:
    r"""Texture coordinates of rays (q, d) in a projection with centre e (sec. 3.3): camera-space
    :math:`(X/Z, Y/Z)` of :math:`x_f - e`, where :math:`x_f = q + t d` is the ray's intersection
    with the **image plane** — the plane of sharp focus, lens-frame z = ``z_plane_mm``
    (:math:`-\infty` for focus at infinity: the direction d itself).

    Why the focus plane and not a point near the lens: two projections sharing a film edge have
    different COPs, and each maps a ray to the scene point seen from its own e. Anchored at the
    focus plane, both map the edge's ray to the *same* in-focus scene point — the seam vanishes
    where the image is sharp and grows only with defocus, :math:`\approx \alpha\,|D - D_f|`
    for a fit error α, where the image is blurred anyway. Anchored 1 mm before the lens (the
    first version) the mismatch was :math:`\approx \alpha D` at every depth: visible seams."""
    q = np.asarray(q, np.float64)
    d = np.asarray(d, np.float64)
    if math.isfinite(z_plane_mm):
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (z_plane_mm - q[:, 2]) / d[:, 2]
        r = q + t[:, None] * d - e
    else:
        r = d
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.stack([r[:, 0], -r[:, 1]], -1) / (-r[:, 2:3])


def focus_plane_z_mm(focus_distance_m: float, z_film_mm: float) -> float:
    """Lens-frame z of the plane of sharp focus (focus distances are measured from the film)."""
    return z_film_mm - focus_distance_m * 1000.0 if math.isfinite(focus_distance_m) else -math.inf


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


# ---------------------------------------------------------------------------------------------
# Building the model
# ---------------------------------------------------------------------------------------------


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
          threshold_deg: float = THRESHOLD_DEG, max_depth: int = 4, pupil_pattern: str = "grid") -> ImageBasedLens:
    """The image-based model of ``lens`` (a ``lens_data`` name) focused at ``focus_distance_m``
    (from the film) at ``f_number``; cached per arguments (module docstring)."""
    if lens not in available_lenses():
        raise InputError(f"lens {lens!r} is not in lens_data/; choose one of {', '.join(available_lenses())}")
    if int(grid) != grid or grid < 2:
        raise InputError(f"grid={grid!r} must be an integer >= 2 (rays per cell side; the paper uses 10)")
    if int(pupil_n) != pupil_n or pupil_n < 1:
        raise InputError(f"pupil_n={pupil_n!r} must be an integer >= 1 (pupil samples per side)")
    if pupil_pattern not in ("grid", "spiral"):
        raise InputError(f"pupil_pattern={pupil_pattern!r} must be 'grid' or 'spiral' (pupil_samples)")
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
    samples = pupil_samples(pres, table, zf, L.paraxial.z_exit_pupil_mm, int(pupil_n), pupil_pattern)
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


# ---------------------------------------------------------------------------------------------
# Rendering (sec. 3.5): one pinhole render per projection, warped onto the film and accumulated
# ---------------------------------------------------------------------------------------------
#
# Film ↔ pixels. The lens inverts the image; the output is shown upright, as a camera shows it:
# the centre of pixel (i, j) is the film point (lens frame, mm)
#     x' = −(i − c_x) p,   y' = (j − c_y) p,   c = ((W−1)/2, (H−1)/2),  p = sensor width / W
# (a scene point to the right, camera X > 0, images at lens-frame x' < 0 and shows at i > c_x).
# Camera space (X right, Y down, Z forward, metres) has its origin at the lens's entrance pupil
# on the axis — the perspective centre of the chief rays, and of the pinhole render the
# post-process pipeline starts from — so the depth buffers of both paths agree.


def pixel_to_film(i, j, size: tuple[int, int], sensor_w_mm: float):
    """Film point (lens frame, mm) of pixel coordinates (i, j) (see the comment above)."""
    w, h = size
    p = sensor_w_mm / w
    return -(np.asarray(i, np.float64) - (w - 1) / 2.0) * p, (np.asarray(j, np.float64) - (h - 1) / 2.0) * p


def lens_to_camera_m(points_mm: np.ndarray, z_origin_mm: float) -> np.ndarray:
    """Lens-frame points (mm) → camera space (m) with the origin on the axis at ``z_origin_mm``."""
    pts = np.asarray(points_mm, np.float64)
    return np.stack([pts[..., 0], -pts[..., 1], -(pts[..., 2] - z_origin_mm)], -1) / 1000.0


@dataclass(frozen=True)
class WarpCell:
    """What the warp kernel needs for one projection at one output size: the projection's render
    (size, focal length, principal point, camera-space COP) and the film node grid."""

    pupil_index: int
    box: tuple[int, int, int, int]  # output pixels i0, i1, j0, j1 (half-open) owned by the cell
    nodes: np.ndarray  # (gy, gx, 4) float64: u, v (render px), W (1/mm²), 0
    node_origin: tuple[float, float]  # output pixel coordinates of node (0, 0)
    node_step: tuple[float, float]  # output pixels between nodes
    render_size: tuple[int, int]
    render_f_px: float
    render_c: tuple[float, float]
    cop_camera_m: np.ndarray


def _owned(coord: np.ndarray, lo: float, hi: float, last: bool) -> tuple[int, int]:
    """Half-open range of indices whose coordinate lies in [lo, hi) ([lo, hi] for the last cell),
    so cells that share an edge never both own a pixel."""
    m = (coord >= lo) & ((coord <= hi) if last else (coord < hi))
    idx = np.flatnonzero(m)
    return (int(idx[0]), int(idx[-1]) + 1) if idx.size else (0, 0)


def warp_cells(model: ImageBasedLens, size: tuple[int, int], node_spacing_px: float = 16.0,
               supersample: float = 1.0, margin_px: int = 2) -> tuple[list[WarpCell], float]:
    r"""The warp data of every projection for an output of ``size`` pixels, and the
    normalisation :math:`\sum_i W_i(0)` (the axial film point's weight over all pupil samples).

    Nodes: a regular grid over the cell's film rectangle (at least the model's ``grid`` per side,
    at most ``node_spacing_px`` apart so the vignetting border and the distortion are resolved
    at the output's resolution), each traced back through its pupil sample exactly as in
    preprocessing: u, v = the render pixel where the projection's image plane meets the ray's
    approximation q − e, W as in the module docstring. Vignetted nodes get W = 0 and the
    affine extrapolation of the passing nodes' (u, v), so interpolation across the border stays
    smooth. Render: focal length ``supersample`` × the film's (v / p), the frustum = the
    bounding box of the passing nodes' texture coordinates plus ``margin_px``."""
    w, h = (int(v) for v in size)
    if w < 2 or h < 2 or (w, h) != tuple(size):
        raise InputError(f"image-based lens: size={size!r} must be (width, height) in whole pixels >= 2")
    if not (math.isfinite(node_spacing_px) and node_spacing_px >= 1):
        raise InputError(f"node_spacing_px={node_spacing_px!r} must be >= 1 output pixel, e.g. 16")
    if not (math.isfinite(supersample) and 0.25 <= supersample <= 8):
        raise InputError(f"supersample={supersample!r} must be in [0.25, 8] (render px per film px)")
    L = get_lens(model.lens)
    dist_mm = model.focus_distance_m * 1000.0 if math.isfinite(model.focus_distance_m) else math.inf
    pres = L.focused(dist_mm, model.f_number)
    table, zf = mirrored_table(pres, L.stop_radius_mm(model.f_number))
    z_e = L.paraxial.z_entrance_pupil_mm
    z_plane = focus_plane_z_mm(model.focus_distance_m, zf)
    pitch = model.sensor_mm[0] / w
    f_px = supersample * L.focus(dist_mm, model.f_number).image_distance_mm / pitch
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    xs, ys = pixel_to_film(np.arange(w), np.arange(h), (w, h), model.sensor_mm[0])
    hw, hh = 0.5 * model.sensor_mm[0], 0.5 * model.sensor_mm[1]
    cells = []
    for proj in model.projections:
        x0, x1, y0, y1 = proj.cell_mm
        p = model.pupil_samples_mm[proj.pupil_index]
        # film x is mirrored: the cell [x0, x1) is the pixel interval (c_x − x1/p, c_x − x0/p]
        i0, i1 = _owned(-xs, -x1, -x0, last=x0 <= -hw + 1e-9)
        j0, j1 = _owned(ys, y0, y1, last=y1 >= hh - 1e-9)
        if i1 <= i0 or j1 <= j0:
            continue
        a_x, b_x = cx - x1 / pitch, cx - x0 / pitch
        a_y, b_y = cy + y0 / pitch, cy + y1 / pitch
        gx = max(int(model_grid(proj)), int(math.ceil((b_x - a_x) / node_spacing_px)) + 1)
        gy = max(int(model_grid(proj)), int(math.ceil((b_y - a_y) / node_spacing_px)) + 1)
        nx, ny = np.meshgrid(np.linspace(a_x, b_x, gx), np.linspace(a_y, b_y, gy))
        fx, fy = pixel_to_film(nx, ny, (w, h), model.sensor_mm[0])
        film = np.stack([fx.ravel(), fy.ravel()], -1)
        q, d, ok = trace_back(table, zf, film, p)
        if ok.sum() < 3:
            continue
        tex = image_plane_tex(q, d, proj.cop_mm, z_plane)
        ok &= np.all(np.isfinite(tex), axis=1)
        if ok.sum() < 3:
            continue
        # vignetted nodes: affine extrapolation of the passing nodes' texture coordinates
        design = np.concatenate([film, np.ones((len(film), 1))], 1)
        coef = np.linalg.lstsq(design[ok], tex[ok], rcond=None)[0]
        tex = np.where(ok[:, None], tex, design @ coef)
        ray = np.concatenate([p[None, :2] - film, np.full((len(film), 1), p[2] - zf)], 1)
        dist2 = np.einsum("ij,ij->i", ray, ray)
        cos = np.abs(ray[:, 2]) / np.sqrt(dist2)
        wgt = np.where(ok, cos * cos / dist2, 0.0)
        t_ok = tex[ok]
        lo, hi = t_ok.min(0), t_ok.max(0)
        rw = int(math.ceil((hi[0] - lo[0]) * f_px)) + 2 * margin_px + 1
        rh = int(math.ceil((hi[1] - lo[1]) * f_px)) + 2 * margin_px + 1
        rc = (margin_px - lo[0] * f_px, margin_px - lo[1] * f_px)
        uv = tex * f_px + np.array(rc)
        nodes = np.zeros((gy, gx, 4))
        nodes[..., 0] = uv[:, 0].reshape(gy, gx)
        nodes[..., 1] = uv[:, 1].reshape(gy, gx)
        nodes[..., 2] = wgt.reshape(gy, gx)
        step = ((b_x - a_x) / (gx - 1), (b_y - a_y) / (gy - 1))
        cells.append(WarpCell(proj.pupil_index, (i0, i1, j0, j1), nodes, (a_x, a_y), step, (rw, rh), f_px, rc,
                              lens_to_camera_m(proj.cop_mm, z_e)))
    # normalisation: the axial film point's irradiance for unit radiance (all samples pass there)
    axial = 0.0
    for p in model.pupil_samples_mm:
        dz = p[2] - zf
        d2 = p[0] ** 2 + p[1] ** 2 + dz * dz
        axial += dz * dz / d2 / d2
    return cells, axial


def model_grid(proj: Projection) -> int:
    """Rays per cell side the projection was fitted with."""
    return int(proj.film_mm.shape[0])


def warp_reference(acc: np.ndarray, src: np.ndarray, cell: WarpCell) -> None:
    """float64 numpy reference of ``kernels/ibl_warp.cl``: adds the cell's weighted, warped
    render ``src`` (h×w×3) into ``acc`` (H×W×3) in place."""
    i0, i1, j0, j1 = cell.box
    gy_n, gx_n = cell.nodes.shape[:2]
    xx, yy = np.meshgrid(np.arange(i0, i1, dtype=np.float64), np.arange(j0, j1, dtype=np.float64))
    gx = np.clip((xx - cell.node_origin[0]) / cell.node_step[0], 0, gx_n - 1)
    gy = np.clip((yy - cell.node_origin[1]) / cell.node_step[1], 0, gy_n - 1)
    ix = np.minimum(gx.astype(int), gx_n - 2)
    iy = np.minimum(gy.astype(int), gy_n - 2)
    fx, fy = (gx - ix)[..., None], (gy - iy)[..., None]
    nd = cell.nodes
    n = ((nd[iy, ix] * (1 - fx) + nd[iy, ix + 1] * fx) * (1 - fy)
         + (nd[iy + 1, ix] * (1 - fx) + nd[iy + 1, ix + 1] * fx) * fy)
    sh, sw = src.shape[:2]
    u = np.clip(n[..., 0], 0, sw - 1)
    v = np.clip(n[..., 1], 0, sh - 1)
    iu = np.minimum(u.astype(int), sw - 2)
    iv = np.minimum(v.astype(int), sh - 2)
    fu, fv = (u - iu)[..., None], (v - iv)[..., None]
    s = src.astype(np.float64)
    val = ((s[iv, iu] * (1 - fu) + s[iv, iu + 1] * fu) * (1 - fv)
           + (s[iv + 1, iu] * (1 - fu) + s[iv + 1, iu + 1] * fu) * fv)
    wgt = np.where(n[..., 2] > 0, n[..., 2], 0.0)[..., None]
    acc[j0:j1, i0:i1] += wgt * val


class Warper:
    """The OpenCL side: a planar accumulator of the output size and :meth:`add` per projection."""

    def __init__(self, size: tuple[int, int], device: str | None = None) -> None:
        import pyopencl as cl

        from ..runtime import get_runtime, kernel_source

        self.cl = cl
        self.rt = get_runtime(device)
        self.size = (int(size[0]), int(size[1]))
        w, h = self.size
        self.kernel = cl.Kernel(self.rt.program(kernel_source("ibl_warp"), "ibl_warp"), "ibl_warp")
        self.acc = cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE, size=3 * w * h * 4)
        cl.enqueue_fill_buffer(self.rt.queue, self.acc, np.float32(0), 0, 3 * w * h * 4)
        self.events = []

    def add(self, src: np.ndarray, cell: WarpCell) -> None:
        cl = self.cl
        i0, i1, j0, j1 = cell.box
        if i1 <= i0 or j1 <= j0:
            return
        planar = np.ascontiguousarray(np.moveaxis(np.asarray(src, np.float32), -1, 0))
        sh, sw = src.shape[:2]
        if sw < 2 or sh < 2:
            raise InputError(f"image-based lens: a projection's render of {sw}x{sh} px is too small to sample")
        mf = cl.mem_flags
        src_buf = cl.Buffer(self.rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=planar)
        nodes = np.ascontiguousarray(cell.nodes, np.float32)
        node_buf = cl.Buffer(self.rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=nodes)
        gy, gx = nodes.shape[:2]
        w, h = self.size
        ev = self.kernel(self.rt.queue, (i1 - i0, j1 - j0), None, src_buf, np.int32(sw), np.int32(sh),
                         node_buf, np.int32(gx), np.int32(gy), np.float32(cell.node_origin[0]),
                         np.float32(cell.node_origin[1]), np.float32(1.0 / cell.node_step[0]),
                         np.float32(1.0 / cell.node_step[1]), self.acc, np.int32(w), np.int32(h),
                         np.int32(i0), np.int32(j0))
        self.events.append(ev)

    def result(self) -> np.ndarray:
        w, h = self.size
        out = np.empty((3, h, w), np.float32)
        self.cl.enqueue_copy(self.rt.queue, out, self.acc)
        self.rt.queue.finish()
        return np.ascontiguousarray(np.moveaxis(out, 0, -1))

    def device_ms(self) -> float:
        from ..runtime import event_ms

        self.rt.queue.finish()
        return float(sum(event_ms(e) for e in self.events))


def render_image_based(model: ImageBasedLens, size: tuple[int, int], render_fn, *, node_spacing_px: float = 16.0,
                       supersample: float = 1.0, device: str | None = None) -> tuple[np.ndarray, dict]:
    r"""The image of ``model`` at ``size`` (sec. 3.5): every projection rendered by
    ``render_fn(cop_camera_m, f_px, c, (w, h)) -> h×w×3 radiance`` (a pinhole at the COP with an
    off-axis frustum), warped onto its film cell by the ``ibl_warp`` kernel with weight W and
    summed over pupil samples, then normalised by the axial point's weight,

    .. math:: I(x') = \frac{\sum_i W_i(x')\,L_i(x')}{\sum_i W_i(0)},

    so a uniform scene of radiance L gives L × the lens's relative illumination RI(x'), 1 on
    the axis. Photometry: this is scene radiance times RI — what the exposure stage expects as
    input, with the lens's fall-off (natural and optical vignetting) already applied; the
    ``vignetting`` stage must then not run (nor ``dof`` and ``distortion``, which the model
    also contains). Returns (H×W×3 float32, stats: projections, render_s, warp_device_ms)."""
    cells, axial = warp_cells(model, size, node_spacing_px, supersample)
    warper = Warper(size, device)
    t_render = 0.0
    for cell in cells:
        t0 = time.perf_counter()
        src = np.asarray(render_fn(cell.cop_camera_m, cell.render_f_px, cell.render_c, cell.render_size))
        t_render += time.perf_counter() - t0
        if src.shape != (cell.render_size[1], cell.render_size[0], 3):
            raise InputError(f"image-based lens: render_fn returned shape {src.shape}, expected "
                             f"{(cell.render_size[1], cell.render_size[0], 3)} (h, w, 3)")
        warper.add(src, cell)
    out = warper.result() / np.float32(axial)
    return out.astype(np.float32), {"projections": len(cells), "render_s": t_render,
                                     "warp_device_ms": warper.device_ms()}


def pyvista_render_fn(renderer, frame_index: int = 0):
    """``render_fn`` for :func:`render_image_based` from a :class:`PyVistaRenderer`: the scene
    camera moved to the COP (camera axes unchanged) with the projection's off-axis frustum."""
    from .pyvista_renderer import shade

    def fn(cop_m, f_px, c, size):
        gbuf, cam_pose, poses = renderer.gbuffer(tuple(size), f_px, frame_index, tuple(c), tuple(cop_m))
        return shade(renderer.scene, gbuf, f_px, tuple(c), cam_pose, poses)

    return fn


def model_for_camera(camera, *, pupil_n: int = 3, threshold_deg: float = THRESHOLD_DEG, max_depth: int = 4,
                     grid: int = 10, pupil_pattern: str = "grid") -> ImageBasedLens:
    """The cached model of a :class:`~clpost.camera.Camera` with a ``lens_data`` lens (auto
    f-number: the lens wide open)."""
    if camera.optics is None:
        raise InputError(f"the image-based lens model needs a real lens from lens_data (--lens "
                         f"{', '.join(available_lenses())}); {camera.lens!r} is a thin lens")
    return build(camera.lens, float(camera.focus_distance_m), camera.f_number, tuple(camera.sensor_mm),
                 grid=grid, pupil_n=pupil_n, threshold_deg=threshold_deg, max_depth=max_depth,
                 pupil_pattern=pupil_pattern)


def render_image_based_sequence(camera, size: tuple[int, int], n_frames: int = 1, camera_motion: bool = False,
                                 scene=None, *, pupil_n: int = 3, threshold_deg: float = THRESHOLD_DEG,
                                 max_depth: int = 4, device: str | None = None, log=None,
                                 pupil_pattern: str = "grid") -> list:
    """Frames 0 … n_frames−1 through the image-based model of ``camera``'s lens: colour from
    :func:`render_image_based`, depth and velocity from the pinhole at the entrance pupil
    (the centre of the chief rays; what the post-process path renders). Metadata records the
    projections per frame and the timings."""
    from .demo_scene import DemoScene
    from .pyvista_renderer import PyVistaRenderer

    if int(n_frames) != n_frames or n_frames < 1:
        raise InputError(f"n_frames={n_frames!r} must be an integer >= 1")
    model = model_for_camera(camera, pupil_n=pupil_n, threshold_deg=threshold_deg, max_depth=max_depth,
                             pupil_pattern=pupil_pattern)
    renderer = PyVistaRenderer(scene if scene is not None else DemoScene.default(camera_motion=camera_motion))
    try:
        frames = []
        for i in range(int(n_frames)):
            t0 = time.perf_counter()
            color, stats = render_image_based(model, size, pyvista_render_fn(renderer, i), device=device)
            stats["frame_s"] = time.perf_counter() - t0
            pin = renderer.render(camera, size, i)
            meta = dict(pin.metadata)
            meta["image_based_lens"] = dict(stats, max_angle_deg=model.max_angle_deg,
                                            pupil_samples=len(model.pupil_samples_mm))
            frames.append(pin.replace(color=color, metadata=meta))
            if log is not None:
                log(f"image-based lens frame {i}: {stats['projections']} projections, "
                    f"{stats['frame_s']:.2f} s ({stats['render_s']:.2f} s rendering, warp "
                    f"{stats['warp_device_ms']:.1f} ms device)")
        return frames
    finally:
        renderer.close()
