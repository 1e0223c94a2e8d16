"""OpenCL side of the dof stage: programs, per-resolution scratch buffers, kernel launches.

Kept apart from :mod:`clpost.stages.dof` (formulas + float64 reference) so the oracle reads
without OpenCL plumbing. Launch sequence: ``dof_coc`` (full res) → ``dof_prepare`` (padded working
buffers = level 0) → ``dof_levels`` per prefiltered level → ``dof_tile_max`` →
``dof_tile_dilate`` → ``dof`` (the gather) → (half res) ``dof_upsample``.

Vectorisation (issue 10, measured with ``POCL_VECTORIZER_REMARKS=1``): PoCL vectorised none of
these kernels across work-items — the gather's tap loop has a per-tile trip count ("loop control
flow is not understood"), the others clamp/branch per pixel. So every full-image kernel does 16
pixels of a row per work-item in explicit ``float16`` (the gather: :func:`gather_vector_width`,
8 or 16), loads whole rows with ``vload16`` where the group of pixels lies inside the image and
falls back to the per-pixel formula only for the groups at an edge; the gather reads 1/max(|CoC|,
1/2) from a fifth plane of each level instead of dividing per tap. Same formulas, same float
operations in the same order where it mattered: the output is within 5e-7 (relative) of the
scalar kernels'.
"""
from __future__ import annotations

import math

import numpy as np

from . import dof as D


def _kernels(rt, defines):
    import pyopencl as cl

    from ..runtime import kernel_source

    out = {}
    for src in ("dof_coc", "dof_levels", "dof_tiles", "dof"):
        head = kernel_source("common") + kernel_source("dof_common")  # DOF_PW: the padded extent
        prog = rt.program(head + kernel_source(src), src, defines)
        for k in prog.all_kernels():
            out[k.function_name] = cl.Kernel(prog, k.function_name)
    return out


def _launch(q, kernel, size, local):
    """Global size rounded up to whole work-groups (kernels guard their bounds): left to itself
    PoCL picks tiny work-groups for sizes like 706×426 and runs 10–50× slower (measured)."""
    import pyopencl as cl

    glob = tuple(-(-s // local) * local for s in size)
    return cl.enqueue_nd_range_kernel(q, kernel, glob, (local, local))


def _launch_rows(q, kernel, size, per_item=16, local=(8, 1)):
    """Kernels that do ``per_item`` pixels of a row per work-item (explicit float16): the x size
    divided by ``per_item``, then rounded up to whole work-groups like :func:`_launch`. Groups of
    8×1 work-items: the float16 bodies ran 3–10× slower in 8×8 groups (measured)."""
    import pyopencl as cl

    glob = (-(-size[0] // per_item), size[1])
    glob = tuple(-(-g // l) * l for g, l in zip(glob, local))
    return cl.enqueue_nd_range_kernel(q, kernel, glob, local)


def gather_vector_width(rt) -> int:
    """Pixels per work-item of the gather: 16 where the device's native float vector is 16 wide
    (AVX-512: measured 1.26–1.36× faster than 8 at final; presumably its 32 registers hold the 8
    accumulators and the pixel's constants without spilling), else 8. ``CLPOST_DOF_VEC`` (8 or 16)
    overrides it, for measuring and for the tests of both widths."""
    import os

    env = os.environ.get("CLPOST_DOF_VEC")
    if env in ("8", "16"):
        return int(env)
    return 16 if getattr(rt.device, "native_vector_width_float", 8) >= 16 else 8


def enqueue_dof(stage, rt, camera, frame, src, dst, aux):
    import pyopencl as cl

    q = rt.queue
    scale, rmax, budget = D.QUALITY[stage.quality]
    nlev = D.levels_for(rmax, budget)
    T = D.TILE
    w, h = frame.width, frame.height
    ww, hw = -(-w // scale), -(-h // scale)
    pad = D.gather_pad(rmax, budget)
    tw, th = -(-ww // T), -(-hw // T)
    pw, ph = tw * T + 2 * pad, th * T + 2 * pad  # DOF_PW in dof_common.cl: whole tiles + border
    vec = gather_vector_width(rt)
    defines = {**stage.defines(camera), "DOF_VEC": vec}
    key = (id(rt), tuple(sorted(defines.items())), w, h, camera.blades, camera.blade_rotation_deg,
           camera.aperture_roundness)
    cache = getattr(stage, "_cl_cache", None)
    if cache is None or cache["key"] != key:
        dx, dy, dist, rf, rn, ntaps = D.tap_table(budget, camera.blades, camera.blade_rotation_deg,
                                                  camera.aperture_roundness)
        mf = cl.mem_flags

        def const(a):
            return cl.Buffer(rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a))

        cache = {
            "key": key, "k": _kernels(rt, defines),
            "taps": [const(dx), const(dy), const(dist.astype(np.float32)), const(rf.astype(np.float32)),
                     const(rn.astype(np.float32)), const((1.0 / rf).astype(np.float32)),
                     const((1.0 / rn).astype(np.float32))],
            "ntaps": const(ntaps),
            "coc": rt.empty((h, w)), "lv": rt.empty((nlev + 1, 5, ph, pw)),
            "pv": rt.empty((ph, pw) if camera.optical_vignetting > 0 else (1,)),
            "tmax": rt.empty((th, tw)), "tn": rt.empty((th, tw), np.int32),
            "alpha": rt.empty((hw, ww)),
            "blur": rt.empty((3, hw, ww)) if scale > 1 else None,
            "inv_area": np.float32(1.0 / D.aperture_area(camera.blades, camera.blade_rotation_deg,
                                                         camera.aperture_roundness)),
        }
        stage._cl_cache = cache
    k = cache["k"]
    kc, inv_u = D.coc_coefficients(camera, w)
    i32, f32 = np.int32, np.float32
    evs = []
    k["dof_coc"].set_args(src, aux["depth"], cache["coc"], i32(w), i32(h), f32(kc), f32(inv_u),
                          f32(scale * rmax))
    evs.append(_launch_rows(q, k["dof_coc"], (w, h)))
    half = math.hypot(ww / 2.0, hw / 2.0)
    field = (f32(camera.optical_vignetting), f32((ww - 1) / 2.0), f32((hw - 1) / 2.0), f32(1.0 / half))
    k["dof_prepare"].set_args(src, cache["coc"], cache["lv"], cache["pv"], i32(w), i32(h),
                              i32(ww), i32(hw), i32(pad), *field)
    evs.append(_launch_rows(q, k["dof_prepare"], (pw, ph)))
    for lvl in range(nlev):
        k["dof_levels"].set_args(cache["lv"], i32(pw), i32(ph), i32(2 ** lvl), i32(lvl))
        evs.append(_launch_rows(q, k["dof_levels"], (pw, ph)))
    k["dof_tile_max"].set_args(cache["lv"], cache["tmax"], i32(ww), i32(hw), i32(pad), i32(tw), i32(th))
    evs.append(_launch(q, k["dof_tile_max"], (tw, th), 4))
    k["dof_tile_dilate"].set_args(cache["tmax"], cache["tn"], cache["ntaps"], i32(tw), i32(th))
    evs.append(_launch(q, k["dof_tile_dilate"], (tw, th), 4))
    target = dst if scale == 1 else cache["blur"]
    k["dof"].set_args(cache["lv"], cache["pv"], cache["tn"], *cache["taps"], target, cache["alpha"],
                             i32(ww), i32(hw), i32(pad), i32(tw), cache["inv_area"],
                             f32(camera.spherical_aberration), *field)
    # one work-group per tile, DOF_VEC pixels of a row per work-item (dof.cl)
    evs.append(cl.enqueue_nd_range_kernel(q, k["dof"], (tw * T // vec, th * T), (T // vec, T)))
    if scale > 1:
        k["dof_upsample"].set_args(src, cache["coc"], cache["blur"], cache["alpha"], cache["lv"], dst,
                                   i32(w), i32(h), i32(ww), i32(hw), i32(pad))
        evs.append(_launch_rows(q, k["dof_upsample"], (w, h)))
    return evs
