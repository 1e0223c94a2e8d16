"""Run every clpost OpenCL kernel once per case on small and odd sizes, for Oclgrind.

Meant to run on Oclgrind's simulated device (``tests/test_oclgrind.py`` starts it in a
subprocess with an ICD file for ``liboclgrind-rt-icd.so`` and ``CLPOST_DEVICE=oclgrind``);
Oclgrind writes its reports (invalid reads/writes, data races, uninitialised values) to stderr.
Before each case this prints ``=== <case>`` to stderr, so a report names the case that made it.

    python tools/oclgrind_sweep.py [--list] [--only SUBSTRING ...]

Cases cover every stage at every quality it distinguishes (``dof`` with blades and cat's eye,
``distortion`` bilinear, B-spline and fold-over, grain's Boolean model at ``final``, sensor, film,
print), the layout conversions of a plan, ``clpost.expose``'s accumulator, the image-based
lens warp and the OpenCL lens trace. Sizes are tiny because Oclgrind interprets every work-item.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace

import numpy as np

SIZES = ((1, 1), (3, 2), (17, 5), (37, 23))
"""Odd sizes; 37×23 is not a multiple of the 16-pixel tiles and vectors in either direction."""


def _frame(w: int, h: int, seed: int = 0, *, depth=True, velocity=0.0, scale=4.0, intrinsics=None, labels=0,
           moving=None, lights=False, light_depth=None, front=False):
    from clpost import Frame
    from clpost.frame import front_layer

    rng = np.random.default_rng(seed + 7919 * w + h)
    color = (rng.random((h, w, 3)) * scale).astype(np.float32)
    if lights:  # small bright lights (dof's narrow-source layer): 2x2 at 100x, every 9 px, one at each edge
        for y in list(range(4, h - 1, 9)) + [0, h - 2]:
            for x in list(range(5, w - 1, 9)) + [0, w - 2]:
                color[max(y, 0):y + 2, max(x, 0):x + 2] = 100.0 * scale
    if depth is True:
        d = rng.uniform(0.3, 30.0, (h, w)).astype(np.float32)
    else:  # False: none; a number: that depth everywhere
        d = None if depth is False else np.full((h, w), float(depth), np.float32)
    if lights and light_depth is not None:  # the lights at their own depth (e.g. in focus over a far background)
        d[np.asarray(color)[..., 0] == 100.0 * scale] = light_depth
    v = (rng.standard_normal((h, w, 2)) * velocity).astype(np.float32) if velocity else None
    if v is not None and moving is not None:  # (y0, y1, x0, x1): only these pixels move
        y0, y1, x0, x1 = moving
        keep = np.zeros((h, w), bool)
        keep[y0:y1, x0:x1] = True
        v[~keep] = 0.0
    meta = {"frame_index": 3}
    if intrinsics is not None:
        meta["intrinsics"] = intrinsics
    lab = {f"id{i}": rng.integers(0, 2**32, (h, w), dtype=np.uint64).astype(np.uint32) for i in range(labels)}
    fr = None
    if front:  # a front layer: soft coverage (0 in a third of the pixels) touching every edge, near depths
        a = np.clip(rng.uniform(-0.5, 1.2, (h, w)), 0.0, 1.0).astype(np.float32)
        fr = front_layer(rng.random((h, w, 3)) * scale * a[..., None], a,
                         np.where(a > 0, rng.uniform(0.2, 1.0, (h, w)), np.inf))
    return Frame(color, depth=d, velocity=v, metadata=meta, labels=lab, front=fr)


def _run(camera, stages, quality, w, h, *, narrow=False, wide=False, **frame_kw):
    """``narrow``: the forms a GPU runs (one pixel per work-item, :attr:`Runtime.wide` False);
    ``wide``: the CPUs' forms (Oclgrind's device reports every device type, GPU included, so
    without either it runs the GPU forms)."""
    from clpost import Pipeline
    from clpost.runtime import Runtime

    if narrow or wide:
        with Runtime.forced_width(wide):
            return _run(camera, stages, quality, w, h, **frame_kw)
    if callable(camera):  # a camera that depends on the size
        camera = camera(w, h)
    pipe = Pipeline(camera, quality=quality, stages=list(stages), device="oclgrind")
    frame = _frame(w, h, **frame_kw)
    planned = pipe.plan(frame)
    missing = [s for s in stages if s not in planned]
    if missing:  # a case that plans nothing would check nothing: fail loudly
        raise SystemExit(f"oclgrind_sweep: stage(s) {missing} not planned for {w}x{h} {quality} "
                         f"(planned: {planned})")
    out = pipe.run(frame)
    if not np.all(np.isfinite(out.color)):
        raise SystemExit(f"oclgrind_sweep: non-finite output for {stages} {w}x{h} {quality}")


def _distortion_model(cam, w, h, **k):
    from clpost.calibration import OpenCVModel

    return replace(cam, distortion=OpenCVModel.from_camera(cam, (w, h), **k))


def cases():
    """(name, callable) for every case."""
    from clpost import Camera

    base = Camera(f_number=2.0, shutter_s=1 / 50, luminance_scale=1.0)  # exposure planned (passthrough by default)
    out = []

    def add(name, fn):
        out.append((name, fn))

    qualities = ("draft", "preview", "final")
    small = ((1, 1), (3, 2), (37, 23))

    # dof: round, bladed with rounding and spherical aberration, cat's eye; a defocused scene
    dof_cams = {
        "round": replace(base, depth_of_field=True, f_number=1.4, focus_distance_m=0.5),
        "blades": replace(base, depth_of_field=True, f_number=1.4, focus_distance_m=0.5, blades=6,
                          blade_rotation_deg=10.0, aperture_roundness=0.3, spherical_aberration=0.5),
        "catseye": replace(base, depth_of_field=True, f_number=1.4, focus_distance_m=0.5,
                           optical_vignetting=0.8),
    }
    def dof_sized(cam):  # 0.4 mm pixels: circles of confusion of a few pixels, whatever the size
        return lambda w, h: replace(cam, sensor_mm=(0.4 * w, 0.4 * h))

    for label, cam in dof_cams.items():
        cam = dof_sized(cam)
        for q in qualities:
            sizes = SIZES if (label == "round" and q == "final") else ((3, 2), (37, 23))
            for w, h in sizes:
                add(f"dof-{label} {q} {w}x{h}", lambda cam=cam, q=q, w=w, h=h: _run(cam, ["dof"], q, w, h))
    # the narrow-source layer (draft, preview): lights on a defocused scene, the cells' borders crossed;
    # "wide": 0.15 mm pixels, CoCs of ~13 px (sources above NARROW_SUM_PX, whole groups inside a disc);
    # final: the full-resolution gather's lights (dof.LIGHT_RAMP_PX; the small ones' 3x3,
    # dof.LIGHT_SMALL_PX; textured light sums on "blades"; "blades" at draft/preview: the texture's
    # level plane, dof_texture_plane)
    for q in ("draft", "preview", "final"):
        for w, h in ((37, 23), (141, 75)):
            add(f"dof-lights {q} {w}x{h}", lambda q=q, w=w, h=h: _run(
                dof_sized(dof_cams["blades"]), ["dof"], q, w, h, lights=True, scale=0.5))
        add(f"dof-lights-wide {q} 141x75", lambda q=q: _run(
            replace(dof_cams["round"], sensor_mm=(0.15 * 141, 0.15 * 75)), ["dof"], q, 141, 75, lights=True,
            scale=0.5))
        # in-focus lights over a far background (their excess leaves the working image, unlisted)
        add(f"dof-lights-focus {q} 141x75", lambda q=q: _run(
            replace(dof_cams["round"], sensor_mm=(0.15 * 141, 0.15 * 75)), ["dof"], q, 141, 75, lights=True,
            scale=0.5, depth=30.0, light_depth=0.5))
        # lights of CoC ~1.2 px over it: in focus for the half-resolution path, their 3x3 share added
        # back by the layer (dof.small_layer)
        add(f"dof-lights-small {q} 141x75", lambda q=q: _run(
            replace(dof_cams["round"], sensor_mm=(0.15 * 141, 0.15 * 75)), ["dof"], q, 141, 75, lights=True,
            scale=0.5, depth=30.0, light_depth=0.55))
        # near lights (CoC -3 px) over a wall sharper than 2 px (1.5 px): split, and the composite's
        # 3x3 share of their excess taken off by the layer (dof_narrow16's kw)
        if q != "final":
            add(f"dof-lights-wall {q} 141x75", lambda q=q: _run(
                replace(dof_cams["round"], sensor_mm=(0.15 * 141, 0.15 * 75)), ["dof"], q, 141, 75, lights=True,
                scale=0.5, depth=0.564, light_depth=0.4076))

    aberr = replace(base, f_number=2.0, field_curvature_mm=-0.14, astigmatism_mm=0.11, coma_mm=0.087,
                    lateral_color_mm=0.007)
    for st in ("astigmatism", "coma", "lateral_color"):
        for q in qualities:
            for w, h in small:
                add(f"{st} {q} {w}x{h}", lambda st=st, q=q, w=w, h=h: _run(aberr, [st], q, w, h))

    # the same aberrations on small pixels (pitch 20 and 6 µm): blurs of tens of pixels, so the
    # tiles fall into the larger tap/stencil classes and the whole-tile fast paths
    for pitch in (0.02, 0.006):
        for st in ("astigmatism", "coma", "lateral_color"):
            w, h = 61, 35
            cam = replace(aberr, sensor_mm=(w * pitch, h * pitch))
            add(f"{st}-strong{pitch * 1000:g}um final {w}x{h}", lambda st=st, cam=cam, w=w, h=h: _run(cam, [st], "final", w, h))

    # the one-pixel forms a GPU runs (astigmatism's gather and copy, fused pointwise kernels)
    for w, h in ((1, 1), (37, 23)):
        for st, cam in (("astigmatism", aberr), ("vignetting", replace(base, vignetting="natural"))):
            add(f"{st} narrow final {w}x{h}", lambda st=st, cam=cam, w=w, h=h: _run(cam, [st], "final", w, h, narrow=True))
    add("astigmatism-strong20um narrow final 61x35",
        lambda: _run(replace(aberr, sensor_mm=(61 * 0.02, 35 * 0.02)), ["astigmatism"], "final", 61, 35, narrow=True))
    # grain's Gaussian path one pixel per work-item (correlated and white noise), with the fused
    # film and print around it
    for w, h in ((1, 1), (37, 23)):
        for label, g in (("-white", {}), ("-correlated", dict(sensor_mm=(0.013, 0.008)))):  # r ≈ 0.3 px at 37 wide
            add(f"film+grain{label}+print narrow draft {w}x{h}",
                lambda g=g, w=w, h=h: _run(replace(base, film="kodak-ektar-100", **g), ["exposure", "film", "grain", "print"],
                                           "draft", w, h, narrow=True))
    # and its 32-pixel lane form with correlated noise (two blocks and a remainder; r ≈ 0.3 px)
    for w, h in ((1, 1), (70, 23)):
        add(f"film+grain-correlated+print wide draft {w}x{h}",
            lambda w=w, h=h: _run(replace(base, film="kodak-ektar-100", sensor_mm=(0.025 * w / 70, 0.008 * h / 23)),
                                  ["exposure", "film", "grain", "print"], "draft", w, h, wide=True))
    # white noise: one fused pointwise kernel, 32 pixels per work-item as two 16-lane calls sharing
    # the Box-Muller draws (one work-item and a tail; three and a tail; exactly two; one, a row's
    # last whole vector with its own state, and a tail)
    for w, h in ((37, 23), (100, 5), (64, 3), (53, 3)):
        add(f"film+grain-white+print wide draft {w}x{h}",
            lambda w=w, h=h: _run(replace(base, film="kodak-ektar-100"), ["exposure", "film", "grain", "print"], "draft",
                                  w, h, wide=True))

    # and the 16-lane forms a CPU runs (Oclgrind reports a GPU type too, so the cases above without
    # narrow/wide run the one-pixel forms as well)
    for w, h in ((1, 1), (37, 23)):
        add(f"astigmatism wide final {w}x{h}", lambda w=w, h=h: _run(aberr, ["astigmatism"], "final", w, h, wide=True))
    add("astigmatism-strong20um wide final 61x35",
        lambda: _run(replace(aberr, sensor_mm=(61 * 0.02, 35 * 0.02)), ["astigmatism"], "final", 61, 35, wide=True))
    # both point classes (tiles of semi-axes >= 4 and >= 8 px far enough from the centre for the
    # tile model: a flat field at one depth), their box plane and the other classes, both forms
    point = replace(base, f_number=2.0, focus_distance_m=3.0, field_curvature_mm=-0.2, astigmatism_mm=0.0,
                    sensor_mm=(401 * 0.006, 9 * 0.006))
    for form, q in (("wide", "final"), ("narrow", "final"), ("wide", "draft")):
        add(f"astigmatism-point {form} {q} 401x9",
            lambda form=form, q=q: _run(point, ["astigmatism"], q, 401, 9, depth=3.0, **{form: True}))
    for w, h in ((1, 1), (37, 23)):
        add(f"vignetting wide final {w}x{h}",
            lambda w=w, h=h: _run(replace(base, vignetting="natural"), ["vignetting"], "final", w, h, wide=True))

    mb = replace(base, frame_rate_fps=24.0, shutter_s=1 / 48, readout_time_s=0.01)
    for q in qualities:
        for w, h in small:
            add(f"motion_blur {q} {w}x{h}",
                lambda q=q, w=w, h=h: _run(mb, ["motion_blur"], q, w, h, velocity=6.0))
    # motion_blur's one-pixel prep and gather (a GPU's form); 45x23: partial 32x4 groups and tiles
    for q in ("draft", "final"):
        for w, h in ((1, 1), (45, 23)):
            add(f"motion_blur narrow {q} {w}x{h}",
                lambda q=q, w=w, h=h: _run(mb, ["motion_blur"], q, w, h, velocity=6.0, narrow=True))
    # and its 16-lane form (a CPU's): a partial 16-pixel run at the right edge
    for q in ("draft", "final"):
        for w, h in ((1, 1), (37, 23)):
            add(f"motion_blur wide {q} {w}x{h}",
                lambda q=q, w=w, h=h: _run(mb, ["motion_blur"], q, w, h, velocity=6.0, wide=True))
    # a mover in one corner tile of 6x4: the frame's cap rises to S_max (draft 19 taps; 16-pixel runs
    # straddling tiles whose lanes take different S), both forms
    for form in ("wide", "narrow"):
        add(f"motion_blur sparse {form} draft 101x61",
            lambda form=form: _run(mb, ["motion_blur"], "draft", 101, 61, velocity=40.0, moving=(2, 14, 3, 17),
                                   **{form: True}))

    # distortion: barrel (bench scenes), strong pincushion + tangential (fold-over, pixels
    # without data), at both filters; sizes include a partial tile in x and in y
    dist = {"barrel": dict(k1=-0.12, k2=0.03, p1=1e-4),
            "foldover": dict(k1=0.6, k2=-0.9, p1=0.01, p2=-0.01)}
    # (final: the GPU's one-pixel kernels, Oclgrind's default form, and the CPUs' 16-lane ones: "wide")
    for label, k in dist.items():
        for q, form in (("draft", None), ("final", None), ("final", "wide")):
            for w, h in ((3, 2), (17, 5), (37, 23), (61, 35)):
                add(f"distortion-{label} {q}{' wide' if form else ''} {w}x{h}",
                    lambda k=k, q=q, w=w, h=h, form=form: _run(_distortion_model(base, w, h, **k), ["distortion"],
                                                               q, w, h, **({form: True} if form else {})))

    # label planes (distortion_labels): fold-over leaves pixels without a preimage (index -1)
    for w, h in ((3, 2), (37, 23)):
        add(f"distortion-labels draft {w}x{h}",
            lambda w=w, h=h: _run(_distortion_model(base, w, h, **dist["foldover"]), ["distortion"], "draft", w, h,
                                  labels=2))

    # the render shifted by 12.6 px against the calibration (frame.metadata["intrinsics"]): the
    # edge of the data crosses the 16-pixel tiles far from the render's edge, so a tile's lanes
    # without data sit up to 16 px from those with data (the B-spline tiles' windows then reached
    # past the coefficient planes: before the buffer for +, past its end for -)
    from clpost.calibration import OpenCVModel

    model = OpenCVModel.from_camera(base, (48, 48))
    edge = replace(base, distortion=model)
    for sign, label in ((1, "+"), (-1, "-")):
        for q, form in (("draft", None), ("final", None), ("final", "wide")):
            k = (model.fx, model.fy, model.cx - sign * 12.6, model.cy - sign * 12.6)
            add(f"distortion-shift{label} {q}{' wide' if form else ''} 48x48",
                lambda k=k, q=q, form=form: _run(edge, ["distortion"], q, 48, 48, intrinsics=k,
                                                 **({form: True} if form else {})))

    vig = replace(base, vignetting="natural")
    film = replace(base, film="kodak-ektar-100")
    sensor = replace(base, sensor_preset="smartphone", iso=800.0)
    for q in qualities:
        for w, h in SIZES:
            add(f"vignetting+exposure {q} {w}x{h}",
                lambda q=q, w=w, h=h: _run(vig, ["vignetting", "exposure"], q, w, h))
            add(f"film+grain+print {q} {w}x{h}",
                lambda q=q, w=w, h=h: _run(film, ["exposure", "film", "grain", "print"], q, w, h))
            add(f"sensor {q} {w}x{h}", lambda q=q, w=w, h=h: _run(sensor, ["exposure", "sensor"], q, w, h))
    # the raw sensor (fused with exposure) and its ISP (5x5 mirrored neighbourhood: 3x3 is the
    # smallest frame it takes, where the mirror reaches the opposite edge)
    raw = replace(base, raw_calibration="a7s2-like", iso=800.0, isp=True, cfa_pattern="GBRG")
    for w, h in ((3, 3), (4, 5), (37, 23)):
        add(f"raw+isp final {w}x{h}", lambda w=w, h=h: _run(raw, ["exposure", "raw", "isp"], "final", w, h))
    # the CPUs' 16-lane forms of the shot noise (kernels/random.cl rnd_poisson: exact Poisson
    # search and normal approximation lanes mixed in a float16; the frame's means 0 to ~60 e⁻)
    add("sensor wide draft 37x23", lambda: _run(sensor, ["exposure", "sensor"], "draft", 37, 23, wide=True))
    add("raw+isp wide final 37x23", lambda: _run(raw, ["exposure", "raw", "isp"], "final", 37, 23, wide=True))
    # halation (film base halo, its own gather before film) and ghosts (traced lens): both planned
    # only when the frame holds light far above saturation, so these frames are bright
    halo = replace(film, halation=True)
    for w, h in ((1, 1), (3, 2), (37, 23)):
        add(f"halation+film final {w}x{h}",
            lambda w=w, h=h: _run(halo, ["exposure", "halation", "film"], "final", w, h, scale=5e4))
    ghost = replace(base, lens="zeiss-planar-50-f1.4", f_number=8.0, ghosts=True, ghost_sources=2)
    for q in ("draft", "final"):
        for w, h in ((3, 2), (37, 23)):
            add(f"ghosts {q} {w}x{h}", lambda q=q, w=w, h=h: _run(ghost, ["ghosts"], q, w, h, scale=5e4))
    # glare: the starburst and veiling glare of the highlights (split, FFT convolution, add)
    glare = replace(base, blades=6, diffraction=True, veiling_glare=0.02)
    for w, h in ((3, 2), (37, 23)):
        add(f"glare final {w}x{h}", lambda w=w, h=h: _run(glare, ["glare"], "final", w, h, scale=5e4))
    # grain's Boolean model needs resolved grains (r >= 1/8 px): a fast stock, coarse grain and a
    # tiny width make pixels large on the film
    boolean = replace(base, film="fuji-superia-400", grain_size=4.0, sensor_mm=(0.05, 0.03))
    for w, h in ((3, 2), (17, 5)):
        add(f"grain-boolean final {w}x{h}",
            lambda w=w, h=h: _run(boolean, ["exposure", "film", "grain"], "final", w, h))
    # front_layer: a foreground layer over dof's background (its tile reach, the clamped taps)
    # and "levels": 0.05 mm pixels, front radii of 4-40 px, spread at levels 0-4 (draft) / 0-3 (final)
    front_cam = dof_sized(dof_cams["blades"])
    front_wide = lambda w, h: replace(dof_cams["blades"], sensor_mm=(0.05 * w, 0.05 * h))  # noqa: E731
    for q in ("draft", "final"):
        for w, h in small:
            add(f"front_layer {q} {w}x{h}",
                lambda q=q, w=w, h=h: _run(front_cam, ["dof", "front_layer"], q, w, h, front=True))
        add(f"front_layer levels {q} 45x29",
            lambda q=q: _run(front_wide, ["dof", "front_layer"], q, 45, 29, front=True))
        # the CPUs' 16-pixel spreads (front_layer_gather16, front_layer_add): rows not a multiple of 16
        add(f"front_layer levels wide {q} 45x29",
            lambda q=q: _run(front_wide, ["dof", "front_layer"], q, 45, 29, front=True, wide=True))
        add(f"front_layer wide {q} 3x2",
            lambda q=q: _run(front_cam, ["dof", "front_layer"], q, 3, 2, front=True, wide=True))
    # a gather between pointwise stages: both layout conversions around it
    for w, h in ((3, 2), (37, 23)):
        add(f"layouts vignetting|astigmatism|exposure final {w}x{h}",
            lambda w=w, h=h: _run(replace(aberr, vignetting="natural"), ["vignetting", "astigmatism", "exposure"],
                                  "final", w, h))

    def expose_case(w, h):
        from clpost.expose import ExposureAccumulator

        acc = ExposureAccumulator((w, h), 24, device="oclgrind")
        for i in range(2):
            acc.add(_frame(w, h, i, depth=False).color, "1/48")
        acc.partial()

    for w, h in ((1, 1), (17, 5)):
        add(f"expose {w}x{h}", lambda w=w, h=h: expose_case(w, h))

    def ibl_case(w, h):
        from clpost.render.image_based_lens import WarpCell, Warper

        rng = np.random.default_rng(5)
        warper = Warper((w, h), device="oclgrind")
        g, (sw, sh) = (4, 3), (9, 7)
        cells, srcs = [], []
        # two pupil samples: a left/right split and the whole frame (overlapping cells)
        for box in ((0, w // 2, 0, h), (w // 2, w, 0, h), (0, w, 0, h)):
            i0, i1, j0, j1 = box
            nodes = np.zeros((g[1], g[0], 4))
            # texture coordinates overshooting the render (the kernel clamps), some zero weights
            nodes[..., 0] = rng.uniform(-3, sw + 2, (g[1], g[0]))
            nodes[..., 1] = rng.uniform(-3, sh + 2, (g[1], g[0]))
            nodes[..., 2] = np.where(rng.random((g[1], g[0])) < 0.25, 0.0, rng.uniform(0, 5, (g[1], g[0])))
            step = (max(i1 - i0, 1) / (g[0] - 1) * 1.03, (j1 - j0) / (g[1] - 1) * 1.03)
            cell = WarpCell(0, box, nodes, (i0 - 0.4, j0 - 0.3), step, (sw, sh), 1.0, (0.0, 0.0), np.zeros(3))
            cells.append(cell)
            srcs.append(rng.uniform(0, 10, (sh, sw, 3)).astype(np.float32))
            warper.add(srcs[-1], cell)
        warper.result()
        batched = Warper((w, h), device="oclgrind")  # ibl_warp_cells: all cells in one launch
        batched.add_cells(srcs, cells)
        batched.result()
        # the rasterizer path's form: renders as tiles of a page (a row stride per cell), alpha-0
        # texels filled with the sky by the kernel
        from clpost.render.ibl_warp import sky_table

        tiled = Warper((w, h), device="oclgrind")
        layout, pages = tiled.map_pages(cells)
        for page in pages:
            page[:] = 0.0
        for src, (p, x, y) in zip(srcs, layout.tiles):
            pages[p][y:y + sh, x:x + sw, :3] = src[::-1]
            pages[p][y:y + sh, x:x + sw, 3] = rng.random((sh, sw)) < 0.7  # 30 % sky
        tiled.launch_cells(sky=(sky_table(np.eye(3), cells), (0.9, 1.0, 1.0), (0.3, 0.5, 1.0)))
        tiled.result()

    add("ibl_warp 17x5", lambda: ibl_case(17, 5))

    def trace_case():
        from clpost.optics import load_prescription
        from clpost.optics.cltrace import trace_cl

        rng = np.random.default_rng(1)
        n = 37  # not a multiple of any work-group size
        o = np.c_[rng.uniform(-20, 20, (n, 2)), np.full(n, -3.0)]
        d = np.c_[rng.normal(0, 0.4, (n, 2)), np.ones(n)]
        trace_cl(load_prescription("zeiss-planar-50-f1.4"), o, d, device="oclgrind")

    add("lens_trace 37 rays", trace_case)

    def aovs_case(w, h, names):
        from clpost import Camera, aovs
        from clpost.runtime import get_runtime

        cam = Camera(f_number=2.0, focus_distance_m=3.0, frame_rate_fps=24.0, shutter_s=1 / 48)
        aovs.compute(get_runtime("oclgrind"), cam, _frame(w, h, velocity=3.0), names)

    for w, h in ((1, 1), (37, 23)):
        add(f"aovs coc,focus,blur {w}x{h}", lambda w=w, h=h: aovs_case(w, h, ("coc", "focus", "blur")))
    add("aovs blur 17x5", lambda: aovs_case(17, 5, ("blur",)))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--list", action="store_true", help="print the case names and exit")
    ap.add_argument("--only", nargs="*", default=[], help="run the cases whose name contains one of these")
    args = ap.parse_args(argv)
    todo = [(n, f) for n, f in cases() if not args.only or any(s in n for s in args.only)]
    if args.list:
        print("\n".join(n for n, _ in todo))
        return 0
    ran = _record_kernels()
    for name, fn in todo:
        print(f"=== {name}", file=sys.stderr, flush=True)
        fn()
    print(f"oclgrind_sweep: kernels run: {' '.join(sorted(ran))}", file=sys.stderr)
    print(f"oclgrind_sweep: {len(todo)} case(s) done", file=sys.stderr, flush=True)
    return 0


def _record_kernels() -> set:
    """The names of the kernels enqueued from now on (both ways clpost enqueues them)."""
    import pyopencl as cl

    ran = set()
    enqueue, call = cl.enqueue_nd_range_kernel, cl.Kernel.__call__

    def enqueue_nd_range_kernel(queue, kernel, *args, **kw):
        ran.add(kernel.function_name)
        return enqueue(queue, kernel, *args, **kw)

    def kernel_call(self, *args, **kw):
        ran.add(self.function_name)
        return call(self, *args, **kw)

    cl.enqueue_nd_range_kernel = enqueue_nd_range_kernel
    cl.Kernel.__call__ = kernel_call
    return ran


if __name__ == "__main__":
    sys.exit(main())
