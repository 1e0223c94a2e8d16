"""OpenCL side of the astigmatism stage: its program, buffers and launch sequence.

Kept apart from :mod:`clpost.stages.astigmatism` (physics, tile planner and float64 oracle), as
:mod:`clpost.stages.dof_cl` is from dof. Launch sequence: ``astigmatism_offsets`` (per-pixel focal
offsets; once per camera and size) → ``astigmatism_pad`` (padded copy + per-pixel semi-axes) →
``astigmatism_tiles`` (tile bounds and class lists) → ``astigmatism_reach`` (and which tiles the
point classes read) → ``astigmatism_box`` (the point classes' prefiltered colour there) → per class:
copy, one kernel per tap count, one per point class, exact per-pixel, each over every tile of the
frame (the groups beyond the class's count return at once — on a CPU the class's tiles are
spread over the launch's groups, ``ASTIGMATISM_SPREAD`` — nothing is read back, so the launches
are data-independent and a plan records them once).

Everything that depends only on the camera's structure and the frame size — the program source
with its tap table, the tile directions, the inner-tile mask and its ring, the focal-offset LUT —
is built once per (tap count, size, principal point, LUT) through :meth:`Runtime.cached`, not per
frame.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from . import _field as fld


# astigmatism_tiles' work-group: this many tiles of a row count their classes in local memory
TILES_GROUP = 64


def _f(v: float) -> str:
    """A float32 literal of ``v`` (exact round trip)."""
    return f"{float(np.float32(v))!r}f"


@lru_cache(maxsize=8)
def program_source(classes: tuple[int, ...]) -> str:
    """The astigmatism program for tap classes ``classes`` (4, 8, ..., N), generated so the kernels
    cannot drift from their Python twins: kernels/common.cl, the stage's constants as
    ``#define``s, the ``astigmatism_taps`` table, ``astigmatism_point_class`` (a tile's smallest
    semi-axis → its point class, from :func:`~clpost.stages.astigmatism.point_classes` of N =
    ``classes[-1]``), kernels/astigmatism.cl, one gather kernel
    ``astigmatism_t<n>`` per class below N and one ``astigmatism_p<n>`` per point class (table
    offset: the spirals before it; the point classes' spirals follow the tap classes').

    The table (float32 literals, exact round trip) holds the Vogel spirals of every tap class one
    after the other, a program-scope constant (from a buffer, PoCL's SLP pass packed the loads of
    the work-item vectoriser into vector gathers; the explicit float16 loop reads them as
    scalars)."""
    from ..runtime import kernel_source
    from .astigmatism import (MAX_SEMI_PX, MIN_DEPTH_MM, MIN_SEMI_PX, POINT_SHRINK_PX2, Astigmatism,
                              point_classes)

    consts = {"ASTIGMATISM_MAX_SEMI": MAX_SEMI_PX, "ASTIGMATISM_MIN_SEMI": MIN_SEMI_PX,
              "ASTIGMATISM_MIN_DEPTH_MM": MIN_DEPTH_MM, "ASTIGMATISM_EXACT_PX": Astigmatism.EXACT_PX,
              "ASTIGMATISM_MIXED": Astigmatism.MIXED, "ASTIGMATISM_POINT_SHRINK": POINT_SHRINK_PX2}
    head = "".join(f"#define {k} {_f(v)}\n" for k, v in consts.items())
    pclasses = point_classes(classes[-1])
    points = tuple(n for _, n in pclasses)
    spirals = classes + points
    taps = np.concatenate([fld.vogel_disc(n) for n in spirals]).ravel()
    vals = ", ".join(f"{float(v)!r}f" for v in taps)
    table = f"__constant float astigmatism_taps[{taps.size}] = {{{vals}}};\n"
    offsets = np.concatenate([[0], np.cumsum(spirals)])
    # class numbers: 0 copy, 1 .. len(classes) the tap classes, then the point classes, exact last
    first = len(classes) + 1
    rule = "".join(f"    if (mn >= {_f(px)}) return {first + k};\n" for k, (px, _) in enumerate(pclasses))
    point_class = f"inline int astigmatism_point_class(const float mn)\n{{\n{rule}    return -1;\n}}\n"
    kernels = "".join(f"__kernel void astigmatism_t{n}(ASTIGMATISM_GATHER_ARGS) "
                      f"{{ ASTIGMATISM_GATHER_CALL({n}, {offsets[k]}, 0); }}\n"
                      for k, n in enumerate(classes[:-1]))
    kernels += "".join(f"__kernel void astigmatism_p{n}(ASTIGMATISM_GATHER_ARGS) "
                       f"{{ ASTIGMATISM_GATHER_CALL({n}, {offsets[len(classes) + k]}, 1); }}\n"
                       for k, n in enumerate(points))
    return kernel_source("common") + head + table + point_class + kernel_source("astigmatism") + kernels


def _plan(stage, rt, camera, w, h, cx, cy, pitch, lut):
    """Device buffers and host constants of one (tap count, size, principal point, LUT)."""
    from .astigmatism import point_classes

    classes = tuple(stage.tap_classes())
    ntx, nty = fld.tiles(w, h)
    pw, ph = ntx * fld.TILE_W + 2 * fld.PAD, nty * fld.TILE_H + 2 * fld.PAD
    pclasses = point_classes(stage.taps)
    nclass = len(classes) + len(pclasses) + 2
    whole = (ntx * fld.TILE_W, nty * fld.TILE_H) == (w, h)
    lanes = 16 if rt.wide else 1  # the gather's pixels per work-item (kernels/astigmatism.cl)
    # the CPU form spreads each class's tiles over its launch (kernels/astigmatism.cl, astigmatism_slot)
    defines = {**stage.defines(camera), "ASTIGMATISM_WHOLE_TILES": int(whole), "ASTIGMATISM_LANES": lanes,
               "ASTIGMATISM_SPREAD": int(rt.wide)}
    source = program_source(classes)
    sizes = (np.int32(w), np.int32(h), np.int32(pw), np.int32(ph))
    geometry = (np.float32(cx), np.float32(cy), np.float32(pitch),
                np.float32((fld.LUT_SIZE - 1) / fld.lut_range_mm(camera)))
    return dict(
        kernel=lambda name: rt.kernel(source, name, defines, "astigmatism"),
        classes=classes, points=tuple(n for _, n in pclasses), nclass=nclass, lanes=lanes, ntx=ntx, nty=nty,
        pw=pw, ph=ph, sizes=sizes, geometry=geometry,
        ring=tuple(np.int32(e) for e in stage.ring(w, h)),
        tiles_host=stage.tile_directions(w, h, cx, cy),
        zeros=np.zeros(nclass, np.int32),
        lut=rt.constant(lut),
        inner=rt.constant(np.ascontiguousarray(stage.inner_tiles(w, h), np.int32), ("astigmatism_inner", w, h)),
        pad=rt.scratch(stage, "pad", (3, ph, pw)), axes=rt.scratch(stage, "axes", (4, ph, pw)),
        offs=rt.scratch(stage, "offs", (2, ph, pw)),
        tmin=rt.scratch(stage, "tmin", (nty, ntx, 2)), reach=rt.scratch(stage, "reach", (nty, ntx), np.int32),
        point=rt.scratch(stage, "point", (nty, ntx), np.int32), need=rt.scratch(stage, "need", (nty, ntx), np.int32),
        pre=rt.scratch(stage, "pre", (3, ph, pw)),
        tiles=rt.scratch(stage, "tiles", (nty, ntx, 4)), counts=rt.scratch(stage, "counts", (nclass,), np.int32),
        lists=rt.scratch(stage, "lists", (nclass, nty * ntx), np.int32),
        offsets_done=False,
    )


def device_plan(stage, rt, camera, w, h, k=None) -> dict:
    """The cached plan of :func:`_plan` for this camera and size (tests read its buffers)."""
    cx, cy = fld.principal_point_px(camera, w, h, k)
    lut = stage._lut(camera).astype(np.float32)
    pitch = fld.pitch_mm(camera, w, k)
    key = (stage.taps, rt.wide, w, h, cx, cy, lut.tobytes(), pitch, fld.lut_range_mm(camera),
           tuple(sorted(stage.defines(camera).items())))
    return rt.cached(stage, "plan", key, lambda: _plan(stage, rt, camera, w, h, cx, cy, pitch, lut))


def enqueue_astigmatism(stage, rt, camera, frame, src, dst, aux):
    from .astigmatism import thin_lens

    w, h = frame.width, frame.height
    b = device_plan(stage, rt, camera, w, h, fld.frame_geometry(camera, frame))
    kernel, ntx, nty, nclass = b["kernel"], b["ntx"], b["nty"], b["nclass"]
    pw, ph = b["pw"], b["ph"]
    aperture, v, f = thin_lens(camera)
    events = [rt.copy(b["tiles"], b["tiles_host"])]
    if not b["offsets_done"]:
        # the per-pixel focal offsets depend on the camera and frame size only: once, not per frame
        events.append(rt.launch_once(kernel("astigmatism_offsets"), (pw // 16, ph), None,
                                     b["lut"], b["offs"], *b["sizes"], *b["geometry"]))
        b["offsets_done"] = True
    # 16 pixels of a padded row per work-item (pw is a multiple of 16)
    events.append(rt.launch(kernel("astigmatism_pad"), (pw // 16, ph), None,
                            src, aux["depth"], b["offs"], b["pad"], b["axes"], *b["sizes"], b["geometry"][2],
                            np.float32(aperture), np.float32(v), np.float32(1.0 / f), *b["ring"]))
    events.append(rt.copy(b["counts"], b["zeros"]))
    tg = TILES_GROUP  # tiles of a row per work-group (kernels/astigmatism.cl, astigmatism_tiles)
    events.append(rt.launch(kernel("astigmatism_tiles"), (-(-ntx // tg) * tg, nty), (tg, 1),
                            b["axes"], b["tiles"], b["tmin"], b["point"], b["counts"], b["lists"], np.int32(w),
                            np.int32(h), np.int32(ntx), np.int32(nty)))
    # which tiles' gathers can skip the reach test (every weight of it is 1 there), and which
    # tiles' prefiltered colour a point class reads
    events.append(rt.launch(kernel("astigmatism_reach"), (ntx, nty), None,
                            b["tiles"], b["tmin"], b["point"], b["reach"], b["need"], np.int32(ntx), np.int32(nty)))
    # the point classes' box-filtered colour, 16 pixels of a padded row per work-item, where needed
    events.append(rt.launch(kernel("astigmatism_box"), (pw // 16, ph), None,
                            src, b["need"], b["pre"], *b["sizes"], np.int32(ntx), np.int32(nty)))
    # every class is launched over as many work-groups as the frame has tiles, the most its list
    # can hold; the groups beyond the class's count return at once (astigmatism_slot and
    # ASTIGMATISM_LISTED in kernels/astigmatism.cl), so the host reads nothing back and the
    # launches can be recorded
    n = ntx * nty
    args = (np.int32(ntx), np.int32(nty), np.int32(w), np.int32(h))
    group = (fld.TILE_W // b["lanes"], fld.TILE_H)  # a tile per work-group
    for c in range(nclass):
        sub = (b["lists"], b["counts"], np.int32(c * n))  # this class's row of the lists, its count
        if c == 0:
            events.append(rt.launch(kernel("astigmatism_copy"), (n * group[0], group[1]), group,
                                    b["pad"], src, b["inner"], dst, *sub, *args))
        elif c == nclass - 1:
            events.append(rt.launch(kernel("astigmatism_exact"), (n * group[0], group[1]), group,
                                    b["pad"], src, b["inner"], b["axes"], dst, *sub,
                                    *args, *b["geometry"][:2]))
        else:
            nt = len(b["classes"])
            if c > nt:  # a point class
                name = f"astigmatism_p{b['points'][c - nt - 1]}"
            else:  # one kernel per tap count (compile-time loop)
                n_taps = b["classes"][c - 1]
                name = "astigmatism" if n_taps == stage.taps else f"astigmatism_t{n_taps}"
            events.append(rt.launch(kernel(name), (n * group[0], group[1]), group,
                                    b["pad"], src, b["pre"], b["inner"], b["reach"], b["axes"], dst, b["tiles"],
                                    *sub, *args))
    return events
