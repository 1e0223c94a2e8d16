"""Code generation for the pointwise stages: one OpenCL kernel per fused group of consecutive
pointwise stages (one pass over memory), and the interleaved ↔ planar layout conversions.

Device layouts: the host frame (H, W, 3) is uploaded as is ("interleaved"); gathers work on
planar buffers (channel c of pixel i at ``c*W*H + i``). The first and last fused kernels convert
between the two as part of their single pass; a plan that starts or ends with a gather gets a
conversion kernel there.
"""
from __future__ import annotations

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
}


VECTOR_PIXELS = 16
"""Pixels per work-item of a fused kernel whose stages all have an explicit-vector form
(``PointwiseStage.vector``: ``<name>_apply16`` on float16 channels of 16 pixels of a row). PoCL
does not vectorise the one-pixel-per-work-item form of the fused stage code (its vectoriser
remarks: float3 values, library calls, selects), and explicit float16 is what it compiles to
AVX-512 (the dof and astigmatism gathers found the same)."""


def vector_path(stages: "list[PointwiseStage]") -> bool:
    """Whether :func:`fused_source` generates the :data:`VECTOR_PIXELS`-wide kernel for ``stages``
    (every stage has the vector form and none reads depth or velocity)."""
    return bool(stages) and all(getattr(s, "vector", False) and not s.reads for s in stages)


def _lanes(vec: str, first: int) -> str:
    """``(float16)(vec[first], vec[first + 3], …)`` from three float16 ``vec0..vec2`` holding 48
    consecutive interleaved floats: channel ``first`` of 16 pixels."""
    comps = [f"{vec}{(first + 3 * k) // 16}.s{(first + 3 * k) % 16:x}" for k in range(16)]
    return f"(float16)({', '.join(comps)})"


def _interleave(part: int) -> str:
    """The float16 holding interleaved floats 16·part … 16·part + 15 of channels r, g, b."""
    comps = [f"{'rgb'[f % 3]}.s{f // 3:x}" for f in range(16 * part, 16 * part + 16)]
    return f"(float16)({', '.join(comps)})"


def fused_source(stages: "list[PointwiseStage]", src_layout: str, dst_layout: str,
                 vector: bool | None = None) -> tuple[str, str]:
    """Generate one OpenCL kernel applying ``stages`` in order to each pixel.

    Returns ``(kernel_name, source)``. The kernel is named after its stages joined by ``__``
    (a single stage's kernel is named like the stage); with no stages it only converts layouts.
    Parameters: ``src, dst, width, height``, then ``depth`` / ``velocity`` if any stage reads
    them, then each stage's ``args`` prefixed ``<stage>_``. A stage that reads depth or velocity
    receives those pointers right after ``p``, in that order.
    """
    name = "__".join(s.name for s in stages) or f"convert_{src_layout}_to_{dst_layout}"
    params = ["__global const float *restrict src", "__global float *restrict dst",
              "const int width", "const int height"]
    aux = [b for b in AUX_BUFFERS if any(b in s.reads for s in stages)]
    params += [AUX_BUFFERS[b] for b in aux]
    body = []
    for s in stages:
        call_args = ["c", "p"] + [b for b in AUX_BUFFERS if b in s.reads]
        for cl_type, arg in s.args:
            params.append(f"{'const ' if '*' not in cl_type else ''}{cl_type} {s.name}_{arg}")
            call_args.append(f"{s.name}_{arg}")
        body.append(f"    c = {s.name}_apply({', '.join(call_args)});")
    if not stages and src_layout != dst_layout:
        return name, kernel_source("common") + _convert_source(name, src_layout)
    load = "load_interleaved(src, i)" if src_layout == INTERLEAVED else "load_planar(src, i, n)"
    store = ("store_interleaved(dst, i, c);" if dst_layout == INTERLEAVED
             else "store_planar(dst, i, n, c);")
    parts = [kernel_source("common")] + [s.source() for s in stages]
    nl = "\n"
    if vector_path(stages) if vector is None else vector:
        calls16 = []
        for s in stages:
            extra = "".join(f", {s.name}_{arg}" for _, arg in s.args)
            calls16.append(f"        {s.name}_apply16(&r, &g, &b, p16{extra});")
        if src_layout == INTERLEAVED:
            load16 = ("const float16 v0 = vload16(0, src + 3 * i), v1 = vload16(1, src + 3 * i), "
                      "v2 = vload16(2, src + 3 * i);\n"
                      f"        float16 r = {_lanes('v', 0)};\n        float16 g = {_lanes('v', 1)};\n"
                      f"        float16 b = {_lanes('v', 2)};")
        else:
            load16 = "float16 r = vload16(0, src + i), g = vload16(0, src + n + i), b = vload16(0, src + 2 * n + i);"
        if dst_layout == INTERLEAVED:
            store16 = "\n".join(f"        vstore16({_interleave(k)}, {k}, dst + 3 * i);" for k in range(3))
        else:
            store16 = ("        vstore16(r, 0, dst + i);\n        vstore16(g, 0, dst + n + i);\n"
                       "        vstore16(b, 0, dst + 2 * n + i);")
        tail = "\n".join("    " + line for line in body)
        parts.append(f"""
__kernel void {name}({", ".join(params)})
{{
    const int x0 = get_global_id(0) * {VECTOR_PIXELS};
    const int y = get_global_id(1);
    if (x0 >= width || y >= height) return;
    const size_t n = (size_t)width * (size_t)height;
    const size_t i0 = (size_t)y * (size_t)width + (size_t)x0;
    (void)n;
    if (x0 + {VECTOR_PIXELS} <= width) {{
        const size_t i = i0;
        const PixelCtx16 p16 = {{x0, y, width, height, i0}};
        {load16}
{nl.join(calls16)}
{store16}
    }} else {{  /* the row's last 1–15 pixels, one by one */
        for (int x = x0; x < width; ++x) {{
            const size_t i = i0 + (size_t)(x - x0);
            const PixelCtx p = {{x, y, width, height, i}};
            float3 c = {load};
{tail}
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
    float3 c = {load};
{nl.join(body)}
    {store}
}}
""")
    return name, "\n".join(parts)


CONVERT_PIXELS = 4
"""Pixels per work-item of a plain layout conversion: three ``vload4`` of 4 interleaved pixels
and one ``vstore4`` per plane (or the reverse). Measured at 1080p on the 2-core PoCL CPU (same
run, best of 17): 1.8 ms vs 6.2 ms for one pixel per work-item with scalar loads, whose stride-3
access PoCL does not vectorise."""


def global_size(stages: "list[PointwiseStage]", src_layout: str, dst_layout: str, w: int, h: int) -> tuple[int, int]:
    """NDRange of the kernel :func:`fused_source` generates for this group at ``w`` × ``h``."""
    if not stages and src_layout != dst_layout:
        return (w + CONVERT_PIXELS - 1) // CONVERT_PIXELS, h
    if vector_path(stages):
        return (w + VECTOR_PIXELS - 1) // VECTOR_PIXELS, h
    return w, h


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
