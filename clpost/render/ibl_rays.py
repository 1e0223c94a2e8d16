r"""Rays of the image-based lens model (Heidrich, Slusallek & Seidel, Graphics Interface 1997):
backward tracing through the real prescription, exit-pupil sampling, the virtual centre of
projection fitted to a ray bundle, and a ray's texture coordinates in a projection. The model
built from them is :mod:`clpost.render.ibl_build`; the warp of its renders onto the film is
:mod:`clpost.render.ibl_warp`.

Frames. The lens frame is the prescription's (mm, z from the first vertex, light toward +z, film
at :math:`z_f`). Rays are traced **backwards**, film → object, through the mirrored prescription
(:math:`z' = z_f - z`, curvatures negated, each surface's indices swapped), so the forward tracer
is reused unchanged. A camera-space direction (X right, Y down, Z forward) is the lens-frame
direction (x, −y, −z); the camera origin is the film centre (focus distances of real lenses are
measured from the film, ``shared/CONVENTIONS.md``).
"""
from __future__ import annotations

import math

import numpy as np

from ..optics.trace import OK, surface_table, trace_table


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


def _concentric(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shirley–Chiu concentric map of [−1, 1]² onto the unit disc (area preserving)."""
    a, b = u, v
    big = np.abs(a) > np.abs(b)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(big, a, b)
        phi = np.where(big, (math.pi / 4) * b / a, math.pi / 2 - (math.pi / 4) * a / b)
    phi = np.where((a == 0) & (b == 0), 0.0, phi)
    return r * np.cos(phi), r * np.sin(phi)


def pupil_samples(pres, table, zf, z_exit_mm: float, n: int, pattern: str = "grid",
                  count: int | None = None) -> np.ndarray:
    r"""n² (spiral: ``count``, if given) stratified points on the exit-pupil plane z = ``z_exit_mm``,
    inside the radius R through which the axial film point's rays pass the stopped-down iris
    (bisection).

    ``pattern``: ``"grid"`` — the n×n cell centres mapped by the concentric map (rows and
    columns: a defocused highlight shows as an n×n array of copies); ``"spiral"`` — the Vogel
    (golden-angle) spiral :math:`r_k = R\sqrt{(k + ½)/K},\ \varphi_k = k \cdot 137.5°` for K = n² or ``count``
    samples (any number, e.g. the paper's 10),
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
        total = n * n if count is None else int(count)
        k = np.arange(total)
        rad, phi = np.sqrt((k + 0.5) / total), k * math.pi * (3.0 - math.sqrt(5.0))
        x, y = rad * np.cos(phi), rad * np.sin(phi)
        return np.stack([lo * 0.999 * x, lo * 0.999 * y, np.full(x.shape, z_exit_mm)], -1)
    g = (np.arange(n) + 0.5) / n * 2 - 1
    u, v = np.meshgrid(g, g)
    x, y = _concentric(u.ravel(), v.ravel())
    return np.stack([lo * 0.999 * x, lo * 0.999 * y, np.full(x.shape, z_exit_mm)], -1)


def fit_cop(q: np.ndarray, d: np.ndarray, e0: np.ndarray, iters: int = 60, max_step_mm: float = 5.0) -> np.ndarray:
    r"""Newton maximisation of :math:`F(e) = \sum \langle d|q-e\rangle^2/\lVert q-e\rVert^2`
    (:mod:`clpost.render.ibl_build`, step 3) from ``e0``; d unit. Steps that do not increase F are halved."""
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
