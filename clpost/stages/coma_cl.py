"""OpenCL side of the coma stage: its program, buffers and launch sequence.

Kept apart from :mod:`clpost.stages.coma` (physics, tile planner and float64 oracle), as
:mod:`clpost.stages.dof_cl` is from dof. Launch sequence: ``coma_shape`` (every pixel's comet;
once per camera and size) → ``coma_pad`` (the padded copy's ring) → ``coma`` on the window tiles →
``coma_s<S>`` / ``coma_c<S>`` on the uniform tiles, one launch per stencil size.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from . import _field as fld


@lru_cache(maxsize=8)
def program_source(taps: int) -> str:
    """The coma program for ``taps`` spiral points, generated so its kernel list cannot drift from
    :data:`~clpost.stages.coma.STENCIL_SIZES`: kernels/common.cl, the ``coma_taps`` table (the
    comet offsets of the Vogel spiral, float32 literals, exact round trip), kernels/coma.cl, and
    per stencil size S the kernels ``coma_s<S>`` (each pixel's Jacobian) and ``coma_c<S>`` (the
    tile's one)."""
    from ..runtime import kernel_source
    from .coma import STENCIL_SIZES, comet_offsets

    off = comet_offsets(fld.vogel_disc(taps).astype(np.float64)).astype(np.float32).ravel()
    vals = ", ".join(f"{float(v)!r}f" for v in off)
    table = f"__constant float coma_taps[{off.size}] = {{{vals}}};\n"
    kernels = "".join(f"__kernel void coma_{kind}{size}(COMA_STENCIL_ARGS) {{ COMA_STENCIL_CALL({size}, {jac}); }}\n"
                      for kind, jac in (("s", 1), ("c", 0)) for size in STENCIL_SIZES)
    return kernel_source("common") + table + kernel_source("coma") + kernels


def _tile_lists(stage, rt, camera, w, h, k=None) -> dict:
    """Device lists of the tiles for the window kernel and, per stencil size, the uniform tiles
    with their stencils (uploaded once per camera map, frame size and tap count: coma does not
    depend on the frame's content)."""
    mk = rt.constant
    window = np.flatnonzero(~stage.tile_uniform(camera, w, h, k).ravel()).astype(np.int32)
    inner = stage.inner_tiles(w, h).ravel()
    stencils = [(f"coma_{'c' if const else 's'}{size}", mk(ids), ids.size, mk(inner[ids].astype(np.int32)),
                 mk(np.stack([dx, dy], -1).astype(np.int32)), mk(wts.astype(np.float32)))
                for size, const, ids, dx, dy, wts in stage.uniform_stencils(camera, w, h, k)]
    # the padded copy's inside that no tile reads (padded coordinates, x0, x1, y0, y1): the
    # inner tiles read the source, and the border tiles' reads (|d| <= PAD) stay within
    # 2 PAD + tile of the frame's edge; the window kernel reads the padded copy everywhere
    p, tw, th = fld.PAD, fld.TILE_W, fld.TILE_H
    skip = (0, 0, 0, 0) if window.size else (3 * p + tw, w - p - tw, 3 * p + th, h - p - th)
    return dict(window=mk(window), n_window=window.size, stencils=stencils, skip=tuple(np.int32(v) for v in skip))


def enqueue_coma(stage, rt, camera, frame, src, dst, aux):
    w, h = frame.width, frame.height
    k = fld.frame_geometry(camera, frame)
    cx, cy = fld.principal_point_px(camera, w, h, k)
    ntx, nty = fld.tiles(w, h)
    ow, oh = ntx * fld.TILE_W, nty * fld.TILE_H
    whole = (ow, oh) == (w, h)
    pitch = fld.pitch_mm(camera, w, k)
    # COMA_WHOLE_TILES (the frame is whole tiles: stores need no branch) is a property of the
    # frame size, not of the camera, so it is added here rather than in defines()
    source, defines = program_source(stage.taps), {**stage.defines(camera), "COMA_WHOLE_TILES": int(whole)}

    def kernel(name):
        return rt.kernel(source, name, defines, "coma")

    pad = rt.scratch(stage, "pad", (3, oh + 2 * fld.PAD, ow + 2 * fld.PAD))
    shape = rt.scratch(stage, "shape", (4, oh, ow))
    events = []
    key = (stage._uniform_key(camera, w, h, k), cx, cy)

    def make_shape():
        # the comet of every pixel depends on the camera and the frame size only (not on the
        # frame's content): computed once, kept on the device for the next frames
        lut = rt.constant(stage._lut(camera))
        tiles = rt.constant(stage.tile_axes_px(camera, w, h, k).astype(np.float32))
        events.append(rt.launch_once(kernel("coma_shape"), (ow, oh), None, shape, lut, np.int32(ow), np.int32(oh),
                                np.float32(cx), np.float32(cy), np.float32(pitch),
                                np.float32((fld.LUT_SIZE - 1) / fld.lut_range_mm(camera))))
        return dict(tiles=tiles, lists=_tile_lists(stage, rt, camera, w, h, k))

    plan = rt.cached(stage, "plan", key, make_shape)
    lists = plan["lists"]
    # 16 pixels of a padded row per work-item
    events.append(rt.launch(kernel("coma_pad"), ((ow + 2 * fld.PAD) // 16, oh + 2 * fld.PAD), None,
                            src, pad, np.int32(w), np.int32(h), np.int32(ow + 2 * fld.PAD),
                            np.int32(oh + 2 * fld.PAD), *lists["skip"]))
    group = (fld.TILE_W // 16, fld.TILE_H)  # 16 pixels (a float16) per work-item
    args = (np.int32(ntx), np.int32(nty), np.int32(w), np.int32(h))
    if lists["n_window"]:
        events.append(rt.launch(kernel("coma"), (group[0] * lists["n_window"], group[1]), group,
                                pad, shape, dst, plan["tiles"], lists["window"], *args))
    for name, ids, n_ids, inner, offs, wts in lists["stencils"]:
        # one kernel per stencil size (a compile-time loop count) and Jacobian kind
        events.append(rt.launch(kernel(name), (group[0] * n_ids, group[1]), group,
                                pad, src, shape, dst, ids, inner, offs, wts, *args))
    return events
