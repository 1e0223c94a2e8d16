"""OpenCL side of the dof stage: programs, per-resolution scratch buffers, kernel launches.

Kept apart from :mod:`clpost.stages.dof` (formulas + float64 reference) so the oracle reads
without OpenCL plumbing. Launch sequence: ``dof_despeckle``, ``dof_coc`` and ``dof_coc_tail`` (full res) → ``dof_prepare`` (padded working
buffers = level 0) → ``dof_levels`` per prefiltered level → ``dof_tile_max`` →
``dof_tile_dilate`` → ``dof`` (the gather) → (half res) ``dof_upsample``. Final (mixed
resolution, :data:`dof.MIXED`): the same up to the tile plan at full resolution (one level
pass), the same again at half resolution, ``dof_tile_mix`` (big tiles), the full-resolution
gather (big tiles skipped), the half-resolution gather (big tiles and their neighbours only) and
``dof_upsample`` writing only the big tiles' pixels.

Vectorisation (found with ``POCL_VECTORIZER_REMARKS=1``): PoCL vectorises none of these kernels'
scalar forms across work-items — the gather's tap loop has a per-tile trip count ("loop control
flow is not understood"), the others clamp/branch per pixel. So every full-image kernel does 16
pixels of a row per work-item in explicit ``float16`` (the gather: :func:`gather_vector_width`,
8 or 16 on a CPU, one pixel on a GPU), loads whole rows with ``vload16`` where the group of pixels lies inside the image and
falls back to the per-pixel formula only for the groups at an edge; the gather reads 1/max(|CoC|,
1/2) from a fifth plane of each level instead of dividing per tap. Same formulas, same float
operations in the same order where it mattered: the output is within 5e-7 (relative) of the
scalar kernels'.
"""
from __future__ import annotations

import math

import numpy as np

from . import _field as fld
from . import dof as D


TAIL_ROWS = 16
"""Rows of one ``dof_coc_tail`` work-item (its ``DOF_TAIL_ROWS``): 16 × 16 pixels read 54 group flags."""


def _kernels(rt, defines):
    from ..runtime import kernel_source

    out = {}
    for src in ("dof_coc", "dof_levels", "dof_tiles", "dof"):
        head = kernel_source("common") + kernel_source("dof_common")  # DOF_PW: the padded extent
        if src == "dof":  # the narrow-source layer's kernels and the upsampling's part of it
            head += kernel_source("dof_narrow")
        out.update(rt.kernels(head + kernel_source(src), src, defines))
    return out


def _launch(rt, kernel, size, local):
    """Square ``local`` × ``local`` work-groups over ``size`` (rounded up by :meth:`Runtime.launch`:
    PoCL's own choice of tiny work-groups for sizes like 706×426 runs many times slower;
    docs/measurements.md#kernel-forms-on-pocl)."""
    return rt.launch(kernel, size, (local, local))


def _launch_rows(rt, kernel, size, per_item=16, local=(8, 1)):
    """Kernels that do ``per_item`` pixels of a row per work-item (explicit float16): the x size
    divided by ``per_item``, then rounded up to whole work-groups like :func:`_launch`. Groups of
    8×1 work-items: the float16 bodies run several times slower in 8×8 groups
    (docs/measurements.md#kernel-forms-on-pocl)."""
    return rt.launch(kernel, (-(-size[0] // per_item), size[1]), local)


def gather_vector_width(rt) -> int:
    """Pixels per work-item of the gather: one on a GPU (:attr:`clpost.runtime.Runtime.wide`
    false: the H200 ran worst final's gather in 1.23 ms against 1.49 ms in the 8-wide form,
    docs/benchmarks.md "The H200 again (2026-11-27)"); on a CPU 16 where the device's native float
    vector is 16 wide (AVX-512, where it is faster than 8: docs/measurements.md#kernel-forms-on-pocl;
    presumably its 32 registers hold the 8 accumulators and the pixel's constants without
    spilling), else 8. ``CLPOST_DOF_VEC`` (1, 8 or 16) overrides it, for measuring and for the
    tests of every width."""
    import os

    env = os.environ.get("CLPOST_DOF_VEC")
    if env in ("1", "8", "16"):
        return int(env)
    if not rt.wide:
        return 1
    return 16 if getattr(rt.device, "native_vector_width_float", 8) >= 16 else 8


def _edge_normals(blades: int, rotation_deg: float) -> np.ndarray:
    """float2 per blade: the aperture polygon's unit edge normals, at φ0 + (i + ½)·2π/N with
    φ0 = −π/2 − rotation (:func:`dof.aperture_radius`'s corners; the narrow-source layer's ρ,
    dof_narrow.cl); one dummy entry for a round aperture."""
    if blades == 0:
        return np.zeros((1, 2), np.float32)
    psi = -math.pi / 2 - math.radians(rotation_deg) + (np.arange(blades) + 0.5) * (2 * math.pi / blades)
    return np.stack([np.cos(psi), np.sin(psi)], 1).astype(np.float32)


def _config(rt, owner, tag, defines, camera, w, h, scale, rmax, budget, built=None):
    """Kernels and scratch buffers of one gather configuration (working resolution w/scale ×
    h/scale, max CoC ``rmax`` working px, lattice budget ``budget``). ``built``: levels to build
    when fewer than the plan's (final's full resolution in mixed mode, where dof_tile_mix sends
    every tile that would need a coarser level to the half-resolution gather). Scratch buffers
    are ``owner``'s, named with ``tag`` (one set per configuration)."""

    rmax = D.reach_rmax(rmax, float(defines["DOF_REACH"].rstrip("f")))  # a traced bokeh reaches T_MAX r
    nlev = D.levels_for(rmax, budget)
    T = D.TILE
    ww, hw = -(-w // scale), -(-h // scale)
    plan_levels, nlev = nlev, (nlev if built is None else built)
    if plan_levels > 7:  # dof_tile_dilate packs taps | level << 24 | routing level << 28 in an int
        raise RuntimeError(f"dof: {plan_levels} lattice levels do not fit the tile plan's packing (at most 7)")
    pad = 2 ** nlev * (budget + 1) + 1  # gather_pad for the levels built
    tw, th = -(-ww // T), -(-hw // T)
    pw, ph = tw * T + 2 * pad, th * T + 2 * pad  # DOF_PW in dof_common.cl: whole tiles + border
    # the lights' ¼-px ramp is the full-resolution gather's only (dof.gather_reference's `lights`)
    defines = {**defines, "DOF_SCALE": scale, "DOF_RMAX": rmax, "DOF_BUDGET": budget,
               "DOF_LEVELS": plan_levels, "DOF_LIGHTS": defines["DOF_LIGHTS"] if scale == 1 else 0}
    shape = (budget, camera.blades, camera.blade_rotation_deg, camera.aperture_roundness)
    tex_plane = bool(defines["DOF_TEXTURE"]) and scale > 1
    dx, dy, dist, rf, rn, ntaps = D.tap_table(*shape)
    sums = D.light_sums if scale == 1 else D.texture_sums

    def const(name, a):
        return rt.constant(a, ("dof_taps", name, shape))

    def scratch(name, shp, dtype=np.float32):
        return rt.scratch(owner, f"{tag}.{name}", shp, dtype)

    half = math.hypot(ww / 2.0, hw / 2.0)
    narrow = {}
    if defines.get("DOF_NARROW"):
        ncx, ncy = -(-w // D.NARROW_CELL), -(-h // D.NARROW_CELL)
        narrow = {"ncx": ncx, "ncy": ncy, "flag": scratch("nflag", (hw, ww), np.int32),
                  "gflag": scratch("ngflag", (hw, -(-ww // 16)), np.int32),
                  "ncount": scratch("ncount", (ncy, ncx), np.int32),
                  "ntx": -(-w // 16), "nty": -(-h // 16),
                  "ntile": scratch("ntile", (-(-h // 16), -(-w // 16)), np.int32),
                  "nrec": scratch("nrec", (ncy * ncx * D.NARROW_MAX, 8))}
    return {
        "narrow": narrow,
        "k": _kernels(rt, defines), "scale": scale, "nlev": nlev, "ww": ww, "hw": hw, "pad": pad,
        "tw": tw, "th": th, "pw": pw, "ph": ph,
        "taps": [const("dx", dx), const("dy", dy), const("dist", dist.astype(np.float32)),
                 const("rf", rf.astype(np.float32)), const("rn", rn.astype(np.float32)),
                 const("inv_rf", (1.0 / rf).astype(np.float32)), const("inv_rn", (1.0 / rn).astype(np.float32))],
        "ntaps": const("ntaps", ntaps),
        # a light tap's lattice sums N₁(r), N_¼(r), far and near (dof.light_sums), one row each; at
        # half resolution (no lights there) the texture's rescale in the same layout (dof.texture_sums)
        # (a callable: built only when its key is new, not on every re-plan — another frame size or
        # quality, another Pipeline — of the same aperture)
        "lsum": rt.constant(lambda: sums(*shape[1:], camera.spherical_aberration).astype(np.float32),
                            (f"dof_{sums.__name__}", shape[1:], camera.spherical_aberration)),
        # planes per level: R, G, B, CoC, 1/r, and the texture's rescale at half resolution
        # (dof_common.cl's DOF_PLANES, DOF_TEX_PLANE)
        "tex_plane": tex_plane,
        "lv": scratch("lv", (nlev + 1, 6 if tex_plane else 5, ph, pw)),
        "pv": scratch("pv", (ph, pw) if camera.optical_vignetting > 0 else (1,)),
        "tmax": scratch("tmax", (th, tw, 2)), "tn": scratch("tn", (th, tw), np.int32),
        "tlight": scratch("tlight", (th, tw), np.int32),
        "alpha": scratch("alpha", (hw, ww)),
        "blur": scratch("blur", (3, hw, ww)) if scale > 1 else None,
        "aperture": (const("normals", _edge_normals(camera.blades, camera.blade_rotation_deg)),
                     np.int32(camera.blades), np.float32(math.cos(math.pi / max(camera.blades, 1))),
                     np.float32(camera.aperture_roundness), np.float32(camera.spherical_aberration),
                     np.float32(1.0 / D.aperture_area(camera.blades, camera.blade_rotation_deg,
                                                      camera.aperture_roundness))),
        "field": (np.float32(camera.optical_vignetting), np.float32((ww - 1) / 2.0),
                  np.float32((hw - 1) / 2.0), np.float32(1.0 / half)),
    }


def _enqueue_plan(rt, c, src, coc, w, h):
    """Working buffers, prefiltered levels and the tile plan of configuration ``c``."""
    i32 = np.int32
    k, evs = c["k"], []
    k["dof_prepare"].set_args(src, coc, c["lv"], c["pv"], i32(w), i32(h), i32(c["ww"]), i32(c["hw"]),
                              i32(c["pad"]), *c["field"])
    evs.append(_launch_rows(rt, k["dof_prepare"], (c["pw"], c["ph"])))
    nw = c["narrow"]
    if nw:  # narrow sources: listed, and taken out of level 0 before the levels are built
        k["dof_narrow_flag"].set_args(c["lv"], nw["flag"], nw["gflag"], i32(c["ww"]), i32(c["hw"]), i32(c["pad"]))
        evs.append(_launch_rows(rt, k["dof_narrow_flag"], (c["ww"], c["hw"])))
        k["dof_narrow_list"].set_args(src, coc, c["lv"], nw["flag"], nw["gflag"], nw["ncount"], nw["nrec"],
                                      i32(w), i32(h), i32(c["ww"]), i32(c["hw"]), i32(c["pad"]), i32(nw["ncx"]),
                                      i32(nw["ncy"]), *c["aperture"])
        evs.append(_launch(rt, k["dof_narrow_list"], (nw["ncx"], nw["ncy"]), 4))
        k["dof_narrow_near"].set_args(nw["ncount"], nw["nrec"], nw["ntile"], i32(nw["ncx"]), i32(nw["ncy"]),
                                      i32(nw["ntx"]), i32(nw["nty"]))
        evs.append(_launch(rt, k["dof_narrow_near"], (nw["ntx"], nw["nty"]), 4))
    for lvl in range(c["nlev"]):
        k["dof_levels"].set_args(c["lv"], i32(c["pw"]), i32(c["ph"]), i32(2 ** lvl), i32(lvl))
        evs.append(_launch_rows(rt, k["dof_levels"], (c["pw"], c["ph"])))
    if c["tex_plane"]:  # the texture's rescale of every level's own CoC, one launch (dof_levels.cl)
        k["dof_texture_plane"].set_args(c["lv"], c["lsum"], i32(c["pw"]), i32(c["ph"]), i32(c["nlev"]))
        evs.append(_launch_rows(rt, k["dof_texture_plane"], (c["pw"], c["ph"]), per_item=1))
    k["dof_tile_max"].set_args(c["lv"], c["tmax"], c["tlight"], i32(c["ww"]), i32(c["hw"]), i32(c["pad"]), i32(c["tw"]),
                               i32(c["th"]))
    evs.append(_launch(rt, k["dof_tile_max"], (c["tw"], c["th"]), 4))
    k["dof_tile_dilate"].set_args(c["tmax"], c["tlight"], c["tn"], c["ntaps"], c["taps"][2], i32(c["tw"]),
                                  i32(c["th"]))
    evs.append(_launch(rt, k["dof_tile_dilate"], (c["tw"], c["th"]), 4))
    return evs


def _enqueue_gather(rt, c, target, tn, camera, inv_area, vec, prof):
    T, i32, f32 = D.TILE, np.int32, np.float32
    c["k"]["dof"].set_args(c["lv"], c["pv"], tn, *c["taps"], target, c["alpha"], i32(c["ww"]), i32(c["hw"]),
                           i32(c["pad"]), i32(c["tw"]), inv_area, f32(camera.spherical_aberration), *c["field"],
                           prof, c["lsum"])
    # one work-group per tile, DOF_VEC pixels of a row per work-item (dof.cl)
    return rt.launch(c["k"]["dof"], (c["tw"] * T // vec, c["th"] * T), (T // vec, T))


def _enqueue_upsample(rt, c, src, coc, dst, w, h, tn_mix):
    i32 = np.int32
    nw = c["narrow"]
    # without the layer its arguments are placeholders (DOF_NARROW 0: never read)
    ncount, nrec, ntile = (nw["ncount"], nw["nrec"], nw["ntile"]) if nw else (tn_mix, c["alpha"], tn_mix)
    c["k"]["dof_upsample"].set_args(src, coc, c["blur"], c["alpha"], dst, i32(w), i32(h), i32(c["ww"]),
                                    i32(c["hw"]), tn_mix, i32(c["tw"]), ncount, nrec, ntile,
                                    i32(nw.get("ncx", 0)), i32(nw.get("ncy", 0)), *c["aperture"])
    return _launch_rows(rt, c["k"]["dof_upsample"], (w, h))


def _profile_buffer(rt, stage, camera, width_px):
    """The traced lens's pencil map (:func:`dof.traced_profile`) as float4 (R, G, B, 0) per (row,
    bin), uploaded once per content; a one-element dummy for a thin lens."""
    entry = D.traced_profile_entry(camera, width_px)
    if entry is None:
        return rt.constant(np.zeros(4, np.float32), ("dof_profile", None))
    key, pm = ("dof_profile", *entry[0]), entry[1]  # a focus pull reuses a table within its tolerance

    def make():
        t = np.zeros(pm.table.shape[1:] + (4,), np.float32)
        t[..., :3] = np.moveaxis(pm.table, 0, -1)
        return t

    return rt.constant(make, key)


def enqueue_dof(stage, rt, camera, frame, src, dst, aux):
    """Launch sequence (module docstring). Final with a mixed-resolution configuration
    (:data:`dof.MIXED`) also plans and gathers at half resolution; ``dof_tile_mix`` skips the
    full-resolution gather of the big tiles (count 0) and the half-resolution gather outside the
    big tiles and their neighbours, and ``dof_upsample`` writes only the big tiles' pixels."""
    scale, rmax, budget = D.QUALITY[stage.quality]
    mixed = D.MIXED.get(stage.quality)
    w, h = frame.width, frame.height
    vec = gather_vector_width(rt)
    defines = {**stage.defines(camera), "DOF_VEC": vec, "DOF_TAIL_ROWS": TAIL_ROWS}
    # every camera field _config reads (its tables, "aperture" and "field"): the stage object, and
    # so this cache, outlives a plan — a camera differing only in σ or the cat's eye kept the last
    # camera's sum table and arguments
    key = (tuple(sorted(defines.items())), w, h, camera.blades, camera.blade_rotation_deg,
           camera.aperture_roundness, camera.spherical_aberration, camera.optical_vignetting)

    def make():
        cache = {
            "main": _config(rt, stage, "main", defines, camera, w, h, scale, rmax, budget,
                            built=D.MIXED_FULL_LEVELS if mixed else None),
            "coc": rt.scratch(stage, "coc", (h, w)),
            "depth": rt.scratch(stage, "depth", (h, w)),
            "moved": rt.scratch(stage, "moved", (h, -(-w // 16)), np.int32),
            "e1": rt.scratch(stage, "e1", (h, w)),
            "inv_area": np.float32(1.0 / D.aperture_area(camera.blades, camera.blade_rotation_deg,
                                                         camera.aperture_roundness)),
        }
        if mixed:
            hc = _config(rt, stage, "half", {**defines, "DOF_MIXED": 1}, camera, w, h, *mixed)
            hc["tn_gather"] = rt.scratch(stage, "half.tn_gather", (hc["th"], hc["tw"]), np.int32)
            hc["mix"] = rt.scratch(stage, "half.mix", (hc["th"], hc["tw"]), np.int32)
            cache["half"] = hc
            cache["tn_full"] = rt.scratch(stage, "tn_full", (cache["main"]["th"], cache["main"]["tw"]), np.int32)
        return cache

    cache = rt.cached(stage, "dof", key, make)
    c = cache["main"]
    prof = _profile_buffer(rt, stage, camera, fld.image_width_px(frame))
    kc, inv_u = D.coc_coefficients(camera, fld.image_width_px(frame))
    i32, f32 = np.int32, np.float32
    evs = []
    c["k"]["dof_despeckle"].set_args(src, aux["depth"], cache["depth"], i32(w), i32(h))
    evs.append(_launch_rows(rt, c["k"]["dof_despeckle"], (w, h)))
    for name, rows in (("dof_coc", h), ("dof_coc_tail", -(-h // TAIL_ROWS))):
        c["k"][name].set_args(src, cache["depth"], cache["e1"], cache["coc"], cache["moved"], i32(w), i32(h),
                              f32(kc), f32(inv_u), f32(scale * rmax))
        evs.append(_launch_rows(rt, c["k"][name], (w, rows)))
    evs += _enqueue_plan(rt, c, src, cache["coc"], w, h)
    if mixed:
        hc = cache["half"]
        evs += _enqueue_plan(rt, hc, src, cache["coc"], w, h)
        hc["k"]["dof_tile_mix"].set_args(hc["tn"], c["tn"], hc["tn_gather"], cache["tn_full"], hc["mix"],
                                         i32(hc["tw"]), i32(hc["th"]), i32(c["tw"]), i32(c["th"]))
        evs.append(_launch(rt, hc["k"]["dof_tile_mix"], (hc["tw"], hc["th"]), 4))
    evs.append(_enqueue_gather(rt, c, dst if scale == 1 else c["blur"], cache["tn_full"] if mixed else c["tn"],
                               camera, cache["inv_area"], vec, prof))
    if scale > 1:
        evs.append(_enqueue_upsample(rt, c, src, cache["coc"], dst, w, h, c["tn"]))
    if mixed:
        evs.append(_enqueue_gather(rt, hc, hc["blur"], hc["tn_gather"], camera, cache["inv_area"], vec, prof))
        evs.append(_enqueue_upsample(rt, hc, src, cache["coc"], dst, w, h, hc["mix"]))
    return evs
