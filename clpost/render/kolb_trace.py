r"""Brute-force reference for the image-based lens model: a distribution ray tracer through the
lens prescription (Kolb, Mitchell & Hanrahan, "A Realistic Camera Model for Computer Graphics",
SIGGRAPH 1995), and the three-way comparison of docs/image_based_lens.md.

For every film pixel, ``rays`` rays from random points of the pixel to uniform random points of
a disc on the exit-pupil plane (1.3× the radius the axial point sees through, so no passing ray
is missed) are traced through the lens (:func:`clpost.render.image_based_lens.trace_back`, the
forward tracer on the mirrored prescription) and intersected with an analytic scene of textured
planes. The film irradiance is the estimator of

.. math:: E(x') = \int_{A} L(x', x'')\,\frac{\cos\theta'\cos\theta''}{\lVert x''-x'\rVert^2}\,dA(x''),

divided by the same integral for the axial point with L = 1 — the normalisation of
:func:`clpost.render.image_based_lens.render_image_based`, so the three images share one exposure:
radiance × relative illumination.

Scene: fronto-parallel checker planes at known depths (1.5 m, 3 m = focus, 7 m) in front of a
backdrop at 25 m, lit only by the ambient term (no sun, no emitters) so the radiance is
albedo × ambient × ½(1 + n_z) = albedo exactly — the same shading as the pyvista renderer's, so
the renderer's pinhole images and the tracer see the same radiance.

``tools/kolb_trace.py`` prints the comparison (RMS and 99th-percentile relative error against
the traced image, away from the frame border) and writes PNGs of the images and error maps::

    PYTHONPATH=. python tools/kolb_trace.py --lens thorlabs-lb1471 --size 192 128 --rays 256 --out /tmp/kolb
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..optics import get_lens
from ..optics.trace import OK, trace_table
from .demo_scene import DemoScene, Material, Plane, RigidMotion, SceneObject, rotation
from .image_based_lens import lens_to_camera_m, mirrored_table, pixel_to_film, trace_back
from .pyvista_renderer import _albedo, _sky


def planes_scene() -> DemoScene:
    """Checker planes facing the camera (level, at 1 m height, looking along +y)."""
    face = tuple(tuple(r) for r in rotation((1.0, 0.0, 0.0), math.pi / 2))  # local +z → world −y

    def plane(name, x, y, z, half, a1, a2, scale):
        return SceneObject(name, Plane(half), Material(albedo=a1, albedo2=a2, texture="checker", texture_scale_m=scale),
                           RigidMotion(position_m=(x, y, z), base_rotation=face), casts_shadow=False)

    objs = (
        plane("near_1.5m", -0.22, 1.5, 1.0, 0.12, (0.9, 0.8, 0.2), (0.1, 0.1, 0.4), 0.02),
        plane("focus_3m", 0.0, 3.0, 1.0, 0.5, (0.9, 0.9, 0.9), (0.05, 0.05, 0.05), 0.05),
        plane("far_7m", 0.9, 7.0, 1.0, 0.6, (0.2, 0.7, 0.3), (0.8, 0.2, 0.2), 0.15),
        plane("backdrop_25m", 0.0, 25.0, 1.0, 12.0, (0.6, 0.6, 0.7), (0.3, 0.3, 0.3), 0.8),
    )
    return DemoScene(objects=objs, camera_motion=RigidMotion.camera((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
                     sun_irradiance=0.0, ambient=2.0, emitter_lighting=False)


def radiance(scene: DemoScene, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Radiance (N×3) along world rays: the nearest plane's albedo under the ambient term, else
    the sky (exactly the renderer's shading for this scene; planes only)."""
    best = np.full(len(origin), np.inf)
    out = _sky(direction, scene)
    for k, obj in enumerate(scene.objects):
        if not isinstance(obj.shape, Plane):
            raise ValueError("kolb_trace shades planes only")
        pose = scene.object_pose(k, 0)
        rot, t = pose[:3, :3], pose[:3, 3]
        o = (origin - t) @ rot
        d = direction @ rot
        with np.errstate(divide="ignore", invalid="ignore"):
            s = -o[:, 2] / d[:, 2]
        hit_local = o + s[:, None] * d
        h = obj.shape.half_size_m
        hit = (s > 0) & (s < best) & (np.abs(hit_local[:, 0]) <= h) & (np.abs(hit_local[:, 1]) <= h)
        if not hit.any():
            continue
        best[hit] = s[hit]
        n_world = rot[:, 2]
        alb = _albedo(obj.material, hit_local[hit], np.zeros((int(hit.sum()), 3)))
        out[hit] = alb * scene.ambient * 0.5 * (1.0 + n_world[2])
    return out


def exit_pupil_disc_mm(table, zf: float, lens) -> float:
    """Radius (mm) of the exit-pupil-plane disc the estimator samples: 1.3× the radius the axial
    film point sees through (bisection), so no passing ray is missed."""
    z_x = lens.paraxial.z_exit_pupil_mm
    lo, hi = 0.0, 4.0 * float(lens.prescription.surfaces[-1].semi_diameter_mm)
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if trace_back(table, zf, np.zeros((1, 2)), np.array([mid, 0, z_x]))[2][0] else (lo, mid)
    return 1.3 * lo


def film_point_footprint(lens_name: str, f_number: float, focus_m: float, film_xy_mm, depth_m: float,
                         rays: int = 20000, seed: int = 0) -> np.ndarray:
    """Where the light reaching one film point comes from on the plane at planar depth ``depth_m``
    (camera space: origin at the entrance pupil, z toward the scene): hits (N×2, mm) of the
    estimator's rays — film point → uniform points of the exit-pupil disc → through the lens
    focused at ``focus_m`` from the film — with that plane. By reciprocity the footprint's size
    over the depth is the blur a point at that depth makes on the film (its minimum is where the
    lens is sharp); the reference of tests/test_focus.py."""
    lens = get_lens(lens_name)
    pres = lens.focused(focus_m * 1000.0, f_number)
    table, zf = mirrored_table(pres, lens.stop_radius_mm(f_number))
    radius = exit_pupil_disc_mm(table, zf, lens)
    z_x, z_e = lens.paraxial.z_exit_pupil_mm, lens.paraxial.z_entrance_pupil_mm
    rng = np.random.default_rng(seed)
    rr = radius * np.sqrt(rng.random(rays))
    ph = 2 * math.pi * rng.random(rays)
    fx, fy = (float(v) for v in film_xy_mm)
    o = np.tile([fx, fy, 0.0], (rays, 1))
    pm = np.stack([rr * np.cos(ph), rr * np.sin(ph), np.full(rays, zf - z_x)], -1)
    return _object_plane_hits(table, o, pm, zf, z_e, depth_m)[1]


def _object_plane_hits(table, o, pm, zf: float, z_e: float, depth_m: float):
    """Trace rays from film points ``o`` toward exit-pupil points ``pm`` through the mirrored
    ``table`` (:func:`mirrored_table`) and intersect the ones that leave the lens with the plane at
    planar depth ``depth_m`` (camera space, mm): (mask of the rays that pass, hits N×2)."""
    r = trace_table(table, o, pm - o, zf + 1.0)
    ok = r.status == OK
    q, d = r.pos[ok].copy(), r.dir[ok].copy()
    q[:, 2] = zf - q[:, 2]
    d[:, 2] = -d[:, 2]
    oc = lens_to_camera_m(q, z_e) * 1000.0
    dc = np.stack([d[:, 0], -d[:, 1], -d[:, 2]], -1)
    t = (depth_m * 1000.0 - oc[:, 2]) / dc[:, 2]
    return ok, oc[:, :2] + t[:, None] * dc[:, :2]


def axial_blur_px(camera, depth_m: float, width_px: int, rays: int = 20000, seed: int = 0) -> float:
    """Blur (px at ``width_px``) of an axial point at ``depth_m`` through ``camera``'s traced lens at
    its focus, by :func:`film_point_footprint`: the diameter of the uniform disc with the footprint's
    RMS radius (2√2 · RMS), mapped to the film at the focused camera's scale F/S."""
    hits = film_point_footprint(camera.lens, camera.f_number, camera.focus_from_film_m, (0.0, 0.0), depth_m,
                                rays=rays, seed=seed)
    c = hits - hits.mean(0)
    rms = math.sqrt(float((c ** 2).sum(1).mean()))
    return 2 * math.sqrt(2) * rms * camera.render_focal_length_mm / (depth_m * 1000.0) / camera.pixel_pitch_mm(width_px)


def point_source_profile(camera, depth_m: float, edges: np.ndarray, rho0_mm: float, wavelengths_nm,
                         source_t: float = 0.1, points_per_bin: int = 400, rays: int = 500,
                         seed: int = 0) -> np.ndarray:
    r"""Radial irradiance profile of a small disc source on the axis at planar depth ``depth_m``,
    by this module's estimator (film point → uniform points of the exit-pupil disc → back through
    the lens at ``camera``'s focus and f-number → the source plane), averaged over
    ``wavelengths_nm``: the independent reference of the DoF stage's traced bokeh texture
    (:mod:`clpost.optics.pencil`, which traces forward from the object point).

    The source's image has radius ``source_t`` · ρ₀ (its object radius from the paraxial scale
    F/S). Film points are stratified, ``points_per_bin`` uniform in area per bin of ``edges`` (in
    t = ρ/ρ₀), ``rays`` per point. Returns the profile normalised to ∫ P 2t dt = 1 over the bins
    (the pencil map's normalisation; a point source is this convolved with the source disc)."""
    from ..optics.trace import surface_table

    lens = camera.optics
    n = camera.f_number
    pres = lens.focused(camera.focus_from_film_m * 1000.0, n)
    z_x, z_e = lens.paraxial.z_exit_pupil_mm, lens.paraxial.z_entrance_pupil_mm
    table_d, zf = mirrored_table(pres, lens.stop_radius_mm(n))
    radius = exit_pupil_disc_mm(table_d, zf, lens)
    area = math.pi * radius * radius
    eps_mm = source_t * rho0_mm * depth_m * 1000.0 / camera.render_focal_length_mm
    rng = np.random.default_rng(seed)
    nb = len(edges) - 1
    e = np.zeros(nb)
    for lam in wavelengths_nm:
        fwd = surface_table(pres, lam, stop_radius_mm=lens.stop_radius_mm(n))
        table = np.array([(zf - fwd[k, 0], -fwd[k, 1], fwd[k, 2], fwd[k - 1, 3] if k > 0 else 1.0, fwd[k, 4])
                          for k in range(len(fwd) - 1, -1, -1)])
        for b in range(nb):
            m = points_per_bin * rays
            t = np.sqrt(edges[b] ** 2 + (edges[b + 1] ** 2 - edges[b] ** 2) * rng.random(m))
            ph = 2 * math.pi * rng.random(m)
            film = np.stack([rho0_mm * t * np.cos(ph), rho0_mm * t * np.sin(ph)], -1)
            rr = radius * np.sqrt(rng.random(m))
            pp = 2 * math.pi * rng.random(m)
            pupil = np.stack([rr * np.cos(pp), rr * np.sin(pp)], -1)
            ray = np.concatenate([pupil - film, np.full((m, 1), z_x - zf)], 1)
            d2 = np.einsum("ij,ij->i", ray, ray)
            wgt = ray[:, 2] ** 2 / (d2 * d2) * area
            o = np.concatenate([film, np.zeros((m, 1))], 1)
            pm = np.concatenate([pupil, np.full((m, 1), zf - z_x)], 1)
            ok, xy = _object_plane_hits(table, o, pm, zf, z_e, depth_m)
            hit = np.hypot(xy[:, 0], xy[:, 1]) <= eps_mm
            e[b] += float(np.sum(wgt[ok] * hit)) / m
    return e / np.sum(e * np.diff(edges ** 2))


def disc_blurred(profile: np.ndarray, edges: np.ndarray, source_t: float, step: float = 0.005) -> np.ndarray:
    """A radial profile (piecewise constant on ``edges``) convolved with a uniform disc of radius
    ``source_t`` and averaged again over the same bins: what :func:`point_source_profile` measures
    for a source whose point profile is ``profile``."""
    lim = edges[-1] + 2 * source_t
    x = np.arange(-lim, lim + step / 2, step)
    xx, yy = np.meshgrid(x, x)
    rr = np.hypot(xx, yy)
    idx = np.clip(np.searchsorted(edges, rr, side="right") - 1, 0, len(profile) - 1)
    img = np.where(rr < edges[-1], profile[idx], 0.0)
    k = (np.hypot(xx, yy) <= source_t).astype(np.float64)
    k /= k.sum()
    f = np.fft.irfft2(np.fft.rfft2(img) * np.fft.rfft2(np.fft.ifftshift(k)), s=img.shape)
    b = np.searchsorted(edges, rr, side="right") - 1
    ok = (b >= 0) & (b < len(profile))
    return np.bincount(b[ok], f[ok], len(profile)) / np.bincount(b[ok], minlength=len(profile))


def kolb_image(lens_name: str, f_number: float, focus_m: float, sensor_mm, size, scene: DemoScene,
               rays: int = 256, seed: int = 0, chunk: int = 200_000, axial_rays: int = 400_000) -> np.ndarray:
    """The traced image (H×W×3, radiance × relative illumination; module docstring) with the lens
    focused at ``focus_m`` from the film (lens scale; a Camera's ``focus_from_film_m``). The axial
    normalisation integral takes ``axial_rays`` rays (its Monte Carlo noise falls as 1/√axial_rays)."""
    lens = get_lens(lens_name)
    pres = lens.focused(focus_m * 1000.0, f_number)
    table, zf = mirrored_table(pres, lens.stop_radius_mm(f_number))
    z_x, z_e = lens.paraxial.z_exit_pupil_mm, lens.paraxial.z_entrance_pupil_mm
    radius = exit_pupil_disc_mm(table, zf, lens)
    area = math.pi * radius * radius
    rng = np.random.default_rng(seed)
    w, h = size
    pose = scene.camera_pose(0)

    def estimate(film_xy):
        n = len(film_xy)
        rr = radius * np.sqrt(rng.random(n))
        ph = 2 * math.pi * rng.random(n)
        pupil = np.stack([rr * np.cos(ph), rr * np.sin(ph), np.full(n, z_x)], -1)
        ray = np.concatenate([pupil[:, :2] - film_xy, np.full((n, 1), z_x - zf)], 1)
        d2 = np.einsum("ij,ij->i", ray, ray)
        wgt = ray[:, 2] ** 2 / (d2 * d2) * area
        out = np.zeros((n, 3))
        # trace_back takes one pupil point; here every ray has its own (same mirrored frame)
        o = np.concatenate([film_xy, np.zeros((n, 1))], 1)
        pm = np.stack([pupil[:, 0], pupil[:, 1], zf - pupil[:, 2]], -1)
        r = trace_table(table, o, pm - o, zf + 1.0)
        ok = r.status == OK
        q, d = r.pos[ok].copy(), r.dir[ok].copy()
        q[:, 2] = zf - q[:, 2]
        d[:, 2] = -d[:, 2]
        oc = lens_to_camera_m(q, z_e)
        dc = np.stack([d[:, 0], -d[:, 1], -d[:, 2]], -1)
        ow = oc @ pose[:3, :3].T + pose[:3, 3]
        dw = dc @ pose[:3, :3].T
        out[ok] = radiance(scene, ow, dw) * wgt[ok, None]
        return out

    # axial normalisation for L = 1: the same integral at x' = 0, with many rays
    n0 = int(axial_rays)
    rr = radius * np.sqrt(rng.random(n0))
    ph = 2 * math.pi * rng.random(n0)
    target = np.stack([rr * np.cos(ph), rr * np.sin(ph), np.full(n0, zf - z_x)], -1)
    r0 = trace_table(table, np.zeros((n0, 3)), target, zf + 1.0)
    dz = z_x - zf
    d2 = rr * rr + dz * dz
    e0 = float(np.mean(np.where(r0.status == OK, dz * dz / (d2 * d2) * area, 0.0)))
    jj, ii = np.mgrid[0:h, 0:w]
    img = np.zeros((h * w, 3))
    pix = np.stack([ii.ravel(), jj.ravel()], -1).astype(np.float64)
    per = max(1, chunk // rays)
    for s in range(0, len(pix), per):
        blk = np.repeat(pix[s:s + per], rays, axis=0) + rng.random((len(pix[s:s + per]) * rays, 2)) - 0.5
        fx, fy = pixel_to_film(blk[:, 0], blk[:, 1], size, sensor_mm[0])
        est = estimate(np.stack([fx, fy], -1))
        img[s:s + per] = est.reshape(-1, rays, 3).mean(1)
    return (img / e0).reshape(h, w, 3)


def fit_opencv(lens_name: str, f_number: float, focus_m: float, sensor_mm, size):
    """The post-process path's distortion: OpenCV k1, k2, k3 fitted (least squares) to the lens's
    traced distortion curve, in the pinhole render's normalised coordinates (r_n = r / v)."""
    from clpost.calibration import OpenCVModel
    from clpost.camera import Camera

    cam = Camera(lens=lens_name, f_number=f_number, focus_scale_m=focus_m, sensor_mm=tuple(sensor_mm))
    v = cam.image_distance_mm
    curves = cam.lens_curves()
    r = np.linspace(0.0, 0.5 * math.hypot(*sensor_mm), 64)
    dist = curves.at("distortion_pct", r) / 100.0
    rn = r / v
    a = np.stack([rn ** 2, rn ** 4, rn ** 6], -1)
    k = np.linalg.lstsq(a, dist, rcond=None)[0]
    fx, fy, cx, cy = cam.intrinsics(*size)
    return OpenCVModel(size[0], size[1], fx, fy, cx, cy, k1=k[0], k2=k[1], k3=k[2], source=f"{lens_name} traced curve")


def post_image(lens_name, f_number, focus_m, sensor_mm, size, scene, device=None):
    """The post-process path on the renderer's pinhole image (camera centre = entrance pupil):
    stages dof + vignetting ('lens') + distortion (fitted), no exposure — radiance × RI."""
    from clpost.camera import Camera
    from clpost.pipeline import Pipeline
    from clpost.render.pyvista_renderer import PyVistaRenderer

    cam = Camera(lens=lens_name, f_number=f_number, focus_scale_m=focus_m, sensor_mm=tuple(sensor_mm),
                 shutter_s=1 / 100, depth_of_field=True, vignetting="lens",
                 distortion=fit_opencv(lens_name, f_number, focus_m, sensor_mm, size))
    r = PyVistaRenderer(scene, supersample=3)
    try:
        frame = r.render(cam, size, 0)
    finally:
        r.close()
    pipe = Pipeline(cam, stages=["dof", "vignetting", "distortion"], device=device)
    t0 = time.perf_counter()
    out = pipe.run(frame)
    return np.asarray(out.color[..., :3], np.float64), [e for e in pipe.explain(frame)], time.perf_counter() - t0, frame


def ibl_image(lens_name, f_number, focus_m, sensor_mm, size, scene, pupil_n=3, threshold_deg=0.05, max_depth=4,
              device=None, supersample=2.0, pupil_pattern="grid", rasterizer=False):
    """The image-based model's image; ``rasterizer``: its projections through the rasterizer path
    (baked textures, VTK float framebuffer) instead of per-projection numpy shading."""
    from clpost.render.image_based_lens import build, pyvista_render_fn, rasterizer_render_fn, render_image_based
    from clpost.render.pyvista_renderer import PyVistaRenderer

    model = build(lens_name, focus_m, f_number, tuple(sensor_mm), pupil_n=pupil_n, threshold_deg=threshold_deg,
                  max_depth=max_depth, pupil_pattern=pupil_pattern)
    if rasterizer:
        from clpost.render.ibl_raster import FloatRasterizer

        r = FloatRasterizer(scene)
        fn = rasterizer_render_fn(r, 0)
    else:
        r = PyVistaRenderer(scene)
        fn = pyvista_render_fn(r, 0)
    try:
        t0 = time.perf_counter()
        img, stats = render_image_based(model, size, fn, supersample=supersample, device=device)
        stats["frame_s"] = time.perf_counter() - t0
    finally:
        r.close()
    stats["max_angle_deg"] = model.max_angle_deg
    stats["pupil_samples"] = len(model.pupil_samples_mm)
    stats["preprocess_s"] = model.preprocess_s
    return np.asarray(img, np.float64), stats


def errors(img: np.ndarray, ref: np.ndarray, border: int) -> dict:
    """Relative error |img − ref| / mean(ref) per pixel (luminance-like mean over RGB), away from
    ``border`` pixels of the frame edge (the pinhole render has nothing outside the frame)."""
    sl = (slice(border, -border), slice(border, -border))
    e = np.abs(img[sl] - ref[sl]).mean(-1) / ref[sl].mean()
    where = np.unravel_index(int(e.argmax()), e.shape)
    return {"rms": float(np.sqrt(np.mean(e * e))), "p99": float(np.percentile(e, 99)), "max": float(e.max()),
            "max_at": (int(where[1]) + border, int(where[0]) + border)}
