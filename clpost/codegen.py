"""Code generation for the pointwise stages: one OpenCL kernel per fused group of consecutive
pointwise stages (one pass over memory), and the interleaved ↔ planar layout conversions.

Device layouts: the host frame (H, W, 3) is uploaded as is ("interleaved"); gathers work on
planar buffers (channel c of pixel i at ``c*W*H + i``). The first and last fused kernels convert
between the two as part of their single pass; a plan that starts or ends with a gather gets a
conversion kernel there.
"""
from __future__ import annotations

import functools

from typing import TYPE_CHECKING

from .runtime import kernel_source

if TYPE_CHECKING:
    from .stages.base import PointwiseStage

INTERLEAVED, PLANAR = "interleaved", "planar"


AUX_BUFFERS = {
    # Frame buffer → OpenCL parameter of a fused kernel (uploaded once per frame when a planned
    # stage reads it). Layouts: depth H×W float32 (+inf sky); velocity H×W×2 float32 interleaved.
    "depth": "__global const float *restrict depth",
    "velocity": "__global const float *restrict velocity",
    # the front layer H×W×5 interleaved (premultiplied R, G, B, alpha, depth); the front_layer
    # stage's own kernels read it, no pointwise stage does
    "front": "__global const float *restrict front",
}


VECTOR_PIXELS = 16
"""Pixels per work-item of a fused pointwise kernel: PoCL does not vectorise the one-pixel-per-
work-item form of the fused stage code (its vectoriser remarks: float3 values, library calls,
selects), and explicit float16 is what it compiles to AVX-512 (the dof and astigmatism gathers
found the same)."""

# -- Width-generic code -------------------------------------------------------------------------
# A pointwise stage writes its per-pixel math once, in kernels/<name>.cl, as
#
#     inline void <name>_apply(CLP_F *r, CLP_F *g, CLP_F *b, const CLP_CTX p, <args>)
#
# on the three channels of CLP_W pixels of a row (helpers named CLP_FN(helper)), and the generator
# instantiates it at one pixel (float, PixelCtx: a row's last 1-31 pixels) and at VECTOR_PIXELS
# (float16 lanes, PixelCtx16) — so every fused group runs two 16-lane vectors per work-item
# (ITEM_VECTORS) and a new stage is fast without a hand-written twin; both instantiations do the
# same float operations, so they agree bit for bit (tests/test_pipeline.py). kernels/fastmath.cl and kernels/random.cl are written
# the same way. The macros (the style of dof's DOF_F / DOF_LOAD in kernels/dof.cl):

WIDTH_MACROS: dict[int, dict[str, str]] = {
    1: {
        "CLP_W": "1", "CLP_F": "float", "CLP_I": "int", "CLP_U": "uint", "CLP_CTX": "PixelCtx",
        "CLP_TO_F(x)": "convert_float(x)", "CLP_TO_I(x)": "convert_int(x)", "CLP_TO_U(x)": "convert_uint(x)",
        "CLP_AS_F(x)": "as_float(x)", "CLP_AS_I(x)": "as_int(x)", "CLP_AS_U(x)": "as_uint(x)",
        "CLP_ANY(c)": "(c)",
        "CLP_X(p)": "((float)(p).x)", "CLP_Y(p)": "((float)(p).y)", "CLP_INDEX(p)": "((uint)(p).i)",
        "CLP_PLANE(buf, p)": "((buf)[(p).i])",
        "CLP_PLANE2(buf, p, k)": "((buf)[2 * (p).i + (k)])",
        "CLP_GATHER(table, idx)": "((table)[idx])",
        "CLP_GATHERU(table, idx)": "((table)[idx])",
    },
    VECTOR_PIXELS: {
        "CLP_W": "16", "CLP_F": "float16", "CLP_I": "int16", "CLP_U": "uint16", "CLP_CTX": "PixelCtx16",
        "CLP_TO_F(x)": "convert_float16(x)", "CLP_TO_I(x)": "convert_int16(x)", "CLP_TO_U(x)": "convert_uint16(x)",
        "CLP_AS_F(x)": "as_float16(x)", "CLP_AS_I(x)": "as_int16(x)", "CLP_AS_U(x)": "as_uint16(x)",
        "CLP_ANY(c)": "clp_any16(c)",
        "CLP_X(p)": "((float)(p).x0 + CLP_LANES16)", "CLP_Y(p)": "((float16)((float)(p).y))",
        "CLP_INDEX(p)": "((uint16)((uint)(p).i0) + CLP_ULANES16)",
        "CLP_PLANE(buf, p)": "vload16(0, (buf) + (p).i0)",
        # component k of 16 interleaved pairs (velocity): the even or odd lanes of 32 floats
        "CLP_PLANE2(buf, p, k)": "((k) ? (float16)(vload16(0, (buf) + 2 * (p).i0).odd, vload16(1, (buf) + 2 * (p).i0).odd) "
                                 ": (float16)(vload16(0, (buf) + 2 * (p).i0).even, vload16(1, (buf) + 2 * (p).i0).even))",
        "CLP_GATHER(table, idx)": "CLP_GATHER16(table, idx)",
        "CLP_GATHERU(table, idx)": "CLP_GATHER16U(table, idx)",
    },
}
"""Per width: the types (``CLP_F`` float, ``CLP_I`` int — also what a comparison gives —,
``CLP_U`` uint, ``CLP_CTX`` the pixel context), conversions (``CLP_TO_*`` value, ``CLP_AS_*``
bits), ``CLP_ANY`` (any lane true), and what a pixel reads: ``CLP_X``/``CLP_Y`` its coordinates,
``CLP_INDEX`` its index (a counter for random.cl), ``CLP_PLANE`` one float per pixel of a W×H
plane, ``CLP_PLANE2`` component k of an interleaved pair (velocity), ``CLP_GATHER`` a table entry
per lane (data-dependent: one load per lane; ``CLP_GATHERU`` of a uint table)."""

LIBRARIES = ("fastmath", "random")
"""Width-generic kernels/*.cl every fused kernel instantiates, in this order, before its stages."""


def width_block(width: int, suffix: str | None = None) -> str:
    """``#define``s of :data:`WIDTH_MACROS` for ``width`` with ``CLP_FN(name)`` →
    ``name<suffix>`` (default ``_w<width>``; ``""``: plain names)."""
    sfx = f"_w{width}" if suffix is None else suffix
    macros = {**WIDTH_MACROS[width], "CLP_FN(name)": f"name##{sfx}" if sfx else "name"}
    lines = []
    for k, v in macros.items():
        lines.append(f"#undef {k.split('(')[0]}")
        lines.append(f"#define {k} {v}")
    return "\n".join(lines) + "\n"


@functools.lru_cache(maxsize=None)
def library(width: int = 1, suffix: str = "") -> str:
    """kernels/common.cl and the width-generic libraries (fastmath, random) at ``width`` with
    plain names (``clp_log2``, ``rnd_hash4``, ...): the head of a gather's program."""
    return kernel_source("common") + width_block(width, suffix) + "".join(kernel_source(n) for n in LIBRARIES)


@functools.lru_cache(maxsize=None)
def library_lanes16() -> str:
    """The width-generic libraries at :data:`VECTOR_PIXELS` lanes (``clp_log2_w16``,
    ``rnd_hash4_w16``, ...), to follow :func:`library` in a gather's program that works on 16
    pixels of a row per work-item (grain, motion_blur)."""
    return width_block(VECTOR_PIXELS) + "".join(kernel_source(n) for n in LIBRARIES)


def _instantiate(stages: "list[PointwiseStage]", width: int) -> str:
    """The libraries and every stage's source at ``width``; entry points ``<name>_apply_w<width>``."""
    parts = [width_block(width)] + [kernel_source(n) for n in LIBRARIES]
    for s in stages:
        parts.append(f"#define {s.name}_apply {s.name}_apply_w{width}\n{s.source()}\n#undef {s.name}_apply\n")
    return "\n".join(parts)


def vector_path(stages: "list[PointwiseStage]", wide: bool = True) -> bool:
    """Whether :func:`fused_source` generates the :data:`VECTOR_PIXELS`-wide kernel for ``stages``:
    every non-empty group (each stage's math is width-generic) on a device that wants wide
    work-items (``wide``: :attr:`clpost.runtime.Runtime.wide` — a CPU, whose compiler
    maps the 16 lanes onto SIMD registers; a GPU gets one pixel per work-item, so a warp's loads
    of a plane are one contiguous, coalesced span)."""
    return bool(stages) and wide


ITEM_VECTORS = 2
"""16-lane vectors per work-item of a fused kernel's vector path (32 pixels of a row; even: a
stateful stage's state covers a pair): each stage is applied to every vector before the next, which
gives PoCL's scheduler independent dependency chains per stage, and white grain's state (one
float16 of Box–Muller draws is the normals of a pair's 32 pixels) is shared by the pair. Two is the
measured best for the film chain with white grain (1, 2, 4, 6, 8 timed: docs/benchmarks.md, "White
grain fused with film and print"). A row's last pixels run as single vectors, then one by one."""


def item_pixels(stages: "list[PointwiseStage]", wide: bool = True) -> int:
    """Pixels per work-item of the fused kernel: :data:`ITEM_VECTORS` × :data:`VECTOR_PIXELS` on the
    vector path, 1 otherwise."""
    return ITEM_VECTORS * VECTOR_PIXELS if vector_path(stages, wide) else 1


def _lanes(vec: str, first: int) -> str:
    """``(float16)(vec[first], vec[first + 3], …)`` from three float16 ``vec0..vec2`` holding 48
    consecutive interleaved floats: channel ``first`` of 16 pixels."""
    comps = [f"{vec}{(first + 3 * k) // 16}.s{(first + 3 * k) % 16:x}" for k in range(16)]
    return f"(float16)({', '.join(comps)})"


def _interleave(part: int, sfx: str = "") -> str:
    """The float16 holding interleaved floats 16·part … 16·part + 15 of channels ``r<sfx>``,
    ``g<sfx>``, ``b<sfx>``."""
    comps = [f"{'rgb'[f % 3]}{sfx}.s{f // 3:x}" for f in range(16 * part, 16 * part + 16)]
    return f"(float16)({', '.join(comps)})"


def fused_source(stages: "list[PointwiseStage]", src_layout: str, dst_layout: str,
                 vector: bool | None = None, wide: bool = True) -> tuple[str, str]:
    """Generate one OpenCL kernel applying ``stages`` in order to each pixel.

    Returns ``(kernel_name, source)``. The kernel is named after its stages joined by ``__``
    (a single stage's kernel is named like the stage); with no stages it only converts layouts.
    Parameters: ``src, dst, width, height``, then ``depth`` / ``velocity`` if any stage reads
    them, then each stage's ``args`` prefixed ``<stage>_``. A stage that reads depth or velocity
    receives those pointers right after ``p``, in that order; a stage with ``state`` its state
    slot right after ``p`` (:attr:`~clpost.stages.base.PointwiseStage.state`). ``vector`` (default
    :func:`vector_path` with ``wide``): :func:`item_pixels` pixels per work-item, else one.
    """
    name = "__".join(s.name for s in stages) or f"convert_{src_layout}_to_{dst_layout}"
    params = ["__global const float *restrict src", "__global float *restrict dst",
              "const int width", "const int height"]
    aux = [b for b in AUX_BUFFERS if any(b in s.reads for s in stages)]
    params += [AUX_BUFFERS[b] for b in aux]
    if not stages and src_layout != dst_layout:
        return name, kernel_source("common") + _convert_source(name, src_layout)

    def call(s, width: int, ctx: str, indent: str, slot: str = "0", sfx: str = "") -> str:
        extra = f", &{s.name}_st{width}{slot}" if s.state else ""
        extra += "".join(f", {b}" for b in AUX_BUFFERS if b in s.reads)
        extra += "".join(f", {s.name}_{arg}" for _, arg in s.args)
        return f"{indent}{s.name}_apply_w{width}(&r{sfx}, &g{sfx}, &b{sfx}, {ctx}{extra});"

    def calls(width: int, ctx: str, indent: str) -> list[str]:
        return [call(s, width, ctx, indent, "[0]") for s in stages]

    for s in stages:
        for cl_type, arg in s.args:
            params.append(f"{'const ' if '*' not in cl_type else ''}{cl_type} {s.name}_{arg}")
    load = "load_interleaved(src, i)" if src_layout == INTERLEAVED else "load_planar(src, i, n)"
    store = ("store_interleaved(dst, i, (float3)(r, g, b));" if dst_layout == INTERLEAVED
             else "store_planar(dst, i, n, (float3)(r, g, b));")
    vec = vector_path(stages, wide) if vector is None else vector
    parts = [kernel_source("common"), _instantiate(stages, 1)]
    nl = "\n"

    def states(width: int, ctx: str, slots: int, indent: str, sfx: str = "") -> str:
        """The state of the stages that keep one: ``slots`` slots, filled by ``<name>_prepare``."""
        out = ""
        for s in stages:
            if s.state:
                extra = "".join(f", {s.name}_{arg}" for _, arg in s.args)
                out += (f"{indent}{s.name}_state_w{width} {s.name}_st{width}{sfx}[{slots}];\n"
                        f"{indent}{s.name}_prepare_w{width}({ctx}, {s.name}_st{width}{sfx}{extra});\n")
        return out

    if vec:
        pixels = item_pixels(stages)
        parts.append(_instantiate(stages, VECTOR_PIXELS))

        def load16(k, x: str, indent: str) -> str:  # vector k: pixels x … x + 15
            i = f"iv{k}"
            head = (f"{indent}const size_t {i} = i0 + (size_t)({x} - x0);\n"
                    f"{indent}const PixelCtx16 p16_{k} = {{{x}, y, width, height, {i}}};\n")
            if src_layout == INTERLEAVED:
                v = f"v{k}_"
                return head + (f"{indent}const float16 {v}0 = vload16(0, src + 3 * {i}), {v}1 = vload16(1, src + 3 * {i}), "
                               f"{v}2 = vload16(2, src + 3 * {i});\n"
                               f"{indent}float16 r{k} = {_lanes(v, 0)};\n{indent}float16 g{k} = {_lanes(v, 1)};\n"
                               f"{indent}float16 b{k} = {_lanes(v, 2)};")
            return head + (f"{indent}float16 r{k} = vload16(0, src + {i}), g{k} = vload16(0, src + n + {i}), "
                           f"b{k} = vload16(0, src + 2 * n + {i});")

        def store16(k, indent: str) -> str:
            i = f"iv{k}"
            if dst_layout == INTERLEAVED:
                return "\n".join(f"{indent}vstore16({_interleave(j, str(k))}, {j}, dst + 3 * {i});" for j in range(3))
            return (f"{indent}vstore16(r{k}, 0, dst + {i});\n{indent}vstore16(g{k}, 0, dst + n + {i});\n"
                    f"{indent}vstore16(b{k}, 0, dst + 2 * n + {i});")

        ind = "        "
        pair = 2 * VECTOR_PIXELS  # pixels one stage state covers (a pair of vectors)
        vectors = range(ITEM_VECTORS)
        body = "\n".join(
            [states(VECTOR_PIXELS, f"((PixelCtx16){{x0 + {pair * j}, y, width, height, i0 + {pair * j}}})", 2, ind, f"_{j}")
             for j in range(ITEM_VECTORS // 2) if any(s.state for s in stages)]
            + [load16(k, f"x0 + {k * VECTOR_PIXELS}", ind) for k in vectors]
            + [call(s, VECTOR_PIXELS, f"p16_{k}", ind, f"_{k // 2}[{k % 2}]", str(k)) for s in stages for k in vectors]
            + [store16(k, ind) for k in vectors])
        ind2 = "            "
        tail = "\n".join(
            [states(VECTOR_PIXELS, f"((PixelCtx16){{xv & ~{pair - 1}, y, width, height, i0 + (size_t)((xv & ~{pair - 1}) - x0)}})",
                    2, ind2, "_0") if any(s.state for s in stages) else ""]
            + [load16(0, "xv", ind2)]
            + [call(s, VECTOR_PIXELS, "p16_0", ind2, f"_0[(xv / {VECTOR_PIXELS}) & 1]", "0") for s in stages]
            + [store16(0, ind2)])
        parts.append(f"""
__kernel void {name}({", ".join(params)})
{{
    const int x0 = get_global_id(0) * {pixels};
    const int y = get_global_id(1);
    if (x0 >= width || y >= height) return;
    const size_t n = (size_t)width * (size_t)height;
    const size_t i0 = (size_t)y * (size_t)width + (size_t)x0;
    (void)n;
    if (x0 + {pixels} <= width) {{
{body}
    }} else {{  /* the row's last 1–{pixels - 1} pixels: whole 16-lane vectors, then one by one */
        int xv = x0;
        for (; xv + {VECTOR_PIXELS} <= width; xv += {VECTOR_PIXELS}) {{
{tail}
        }}
        for (int x = xv; x < width; ++x) {{
            const size_t i = i0 + (size_t)(x - x0);
            const PixelCtx p = {{x, y, width, height, i}};
{states(1, "p", 1, "            ")}            const float3 c = {load};
            float r = c.x, g = c.y, b = c.z;
{nl.join(calls(1, "p", "            "))}
            {store}
        }}
    }}
}}
""")
        return name, "\n".join(parts)
    parts.append(f"""
__kernel void {name}({", ".join(params)})
{{
    const int x = get_global_id(0);
    const int y = get_global_id(1);
    if (x >= width || y >= height) return;
    const size_t n = (size_t)width * (size_t)height;
    const size_t i = (size_t)y * (size_t)width + (size_t)x;
    const PixelCtx p = {{x, y, width, height, i}};
    (void)n; (void)p;
{states(1, "p", 1, "    ")}    const float3 c = {load};
    float r = c.x, g = c.y, b = c.z;
{nl.join(calls(1, "p", "    "))}
    {store}
}}
""")
    return name, "\n".join(parts)


CONVERT_PIXELS = 4
"""Pixels per work-item of a plain layout conversion: three ``vload4`` of 4 interleaved pixels
and one ``vstore4`` per plane (or the reverse), not one pixel per work-item with scalar loads, whose
stride-3 access PoCL does not vectorise (docs/measurements.md#kernel-forms-on-pocl)."""


def global_size(stages: "list[PointwiseStage]", src_layout: str, dst_layout: str, w: int, h: int,
                wide: bool = True) -> tuple[int, int]:
    """NDRange of the kernel :func:`fused_source` generates for this group at ``w`` × ``h``
    (``wide`` as given to :func:`vector_path`)."""
    if not stages and src_layout != dst_layout:
        return (w + CONVERT_PIXELS - 1) // CONVERT_PIXELS, h
    k = item_pixels(stages, wide)
    return (w + k - 1) // k, h


def _convert_source(name: str, src_layout: str) -> str:
    """Interleaved ↔ planar, :data:`CONVERT_PIXELS` pixels per work-item (a row's last 1–3 pixels
    one by one)."""
    if src_layout == INTERLEAVED:
        whole = """const float4 a = vload4(0, src + 3 * i), b = vload4(1, src + 3 * i), c = vload4(2, src + 3 * i);
        vstore4((float4)(a.x, a.w, b.z, c.y), 0, dst + i);
        vstore4((float4)(a.y, b.x, b.w, c.z), 0, dst + n + i);
        vstore4((float4)(a.z, b.y, c.x, c.w), 0, dst + 2 * n + i);"""
        one = "store_planar(dst, j, n, load_interleaved(src, j));"
    else:
        whole = """const float4 r = vload4(0, src + i), g = vload4(0, src + n + i), b = vload4(0, src + 2 * n + i);
        vstore4((float4)(r.x, g.x, b.x, r.y), 0, dst + 3 * i);
        vstore4((float4)(g.y, b.y, r.z, g.z), 0, dst + 3 * i + 4);
        vstore4((float4)(b.z, r.w, g.w, b.w), 0, dst + 3 * i + 8);"""
        one = "store_interleaved(dst, j, load_planar(src, j, n));"
    return f"""
__kernel void {name}(__global const float *restrict src, __global float *restrict dst,
                     const int width, const int height)
{{
    const int x = get_global_id(0) * {CONVERT_PIXELS};
    const int y = get_global_id(1);
    if (x >= width || y >= height) return;
    const size_t n = (size_t)width * (size_t)height;
    const size_t i = (size_t)y * (size_t)width + (size_t)x;
    if (x + {CONVERT_PIXELS} <= width) {{
        {whole}
    }} else {{
        for (size_t j = i; j < i + (size_t)(width - x); ++j)
            {one}
    }}
}}
"""
