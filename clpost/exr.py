r"""OpenEXR input and output: each renderer's channel layout mapped to clpost's conventions.

Reading gives a :class:`clpost.frame.Frame` whose buffers follow ``shared/CONVENTIONS.md``:
color linear RGB (H×W×3, optional alpha), depth **planar** camera-space Z in metres with
``+inf`` for sky, velocity **forward** screen-space motion in pixels per frame, **+x right,
+y down**. Every renderer's convention is converted here, at the input boundary, and the
writer inverts the same conversion so each layout round-trips.

Pixel rows in an EXR file are stored top row first (``INCREASING_Y`` in the data window,
y down), exactly like our arrays — a "y up" convention below is about the *sign of vector
components*, never about row order.

Layouts
-------
Auto-detected from the channel names of all parts (:func:`detect_layout`, first match wins in
the order blender, arnold, nuke, clpost); ``layout=`` (CLI ``--channels``) overrides.

**clpost** (native, no conversion)

============  =========================  =====================================================
buffer        channels                   convention in the file → ours
============  =========================  =====================================================
color         ``R, G, B`` (+ ``A``)      linear RGB, unchanged
depth         ``Z``                      planar metres, ``+inf`` sky → unchanged
velocity      ``velocity.X/Y``           forward px/frame, +y down → unchanged
============  =========================  =====================================================

**blender** (multilayer; Blender 5.x writes *one part per pass*, all parts are read; the view
layer prefix — ``ViewLayer`` by default — is detected from ``<layer>.Combined.R``)

============  ================================  ==============================================
buffer        channels                          convention in the file → ours
============  ================================  ==============================================
color         ``<layer>.Combined.R/G/B/A``      linear RGB + alpha, unchanged
depth         ``<layer>.Depth.Z``               planar view distance in metres (verified);
                                                sky is written as ``1e10`` → values ≥ ``1e10``
                                                (or inf) become ``+inf``
velocity      ``<layer>.Vector.X/Y/Z/W``        px/frame, **y up**; XY = previous − current,
                                                ZW = current − next (verified with Blender
                                                5.2 / Cycles). Forward, y down: ``(−Z, +W)``.
                                                Without ZW, ``(−X, +Y)`` (assumes constant
                                                velocity over the two frame intervals).
============  ================================  ==============================================

**nuke** (Foundry Nuke, e.g. ScanlineRender output written by a Write node)

============  ===============================  ===============================================
buffer        channels                         convention in the file → ours
============  ===============================  ===============================================
color         ``R, G, B`` (+ ``A``)            linear RGB, unchanged
depth         ``depth.Z``                      **1/z** by default ("classic" ScanlineRender
                                               depth, its ``1/Z`` output knob on; 0 = no
                                               hit) → ``z = 1/depth.Z``, 0 → ``+inf``. Pass
                                               ``depth="planar"`` if the channel holds metres
                                               (e.g. a renderer's Z shuffled into depth.Z).
velocity      ``forward.u/v``                  px to the next frame ("distance" motion-vector
                                               mode), Nuke's image space is **y up** (origin
                                               bottom-left) → ``(u, −v)``
              ``backward.u/v`` (fallback)      px to the previous frame, y up → forward is
                                               approximated as ``(−u, +v)`` (assumes constant
                                               velocity; used only when forward.u/v is absent)
============  ===============================  ===============================================

Verified vs assumed (Nuke): 1/z depth with 0 for "no hit" is Foundry's documented classic
ScanlineRender output and the reason ZDefocus defaults to ``math = far = 0``; y up is Nuke's
documented image coordinate system; that ``forward`` holds pixels to the next frame is the
VectorGenerator/ScanlineRender documentation. None of this was checked against a file written
by Nuke itself, and whether classic 1/z is of planar or radial distance is assumed planar.

**arnold** (Autodesk Arnold, ``driver_exr``)

============  ===================================  ===========================================
buffer        channels                             convention in the file → ours
============  ===================================  ===========================================
color         ``R, G, B`` (+ ``A``)                linear RGB, unchanged
depth         ``Z``                                **radial** distance along the camera ray
                                                   assumed (NOT verified). Converted to planar
                                                   with ``focal_px``; without it the depth is
                                                   kept radial, ``metadata["depth_kind"]`` says
                                                   ``"radial"`` and :class:`DepthConventionWarning`
                                                   is issued. Values ≥ ``1e10`` → ``+inf``.
velocity      ``motionvector.R/G`` (or ``.X/Y``)   raw pixels over the normalised shutter
                                                   [0, 1] = one frame, forward in time
                                                   (Arnold's motion_vector docs); y **up**
                                                   assumed (NOT verified) → ``(R, −G)``.
                                                   ``velocity_y_up=False`` overrides.
============  ===================================  ===========================================

Verified vs assumed (Arnold): the ``motion_vector`` shader documentation states the vector is
the motion over a normalised shutter [0, 1] and must be rendered with an instantaneous shutter;
the y sign and whether the built-in ``motionvector`` AOV is raw pixels (not normalised by
``max_displace``) are assumptions, as is radial ``Z`` (CONVENTIONS.md: "Arnold Z may be radial
distance rather than planar (not verified)"). Check a frame with :func:`info` before trusting it.

Radial → planar (pinhole, principal point at the image centre ((W−1)/2, (H−1)/2) in the
OpenCV pixel convention of CONVENTIONS.md, focal lengths :math:`f_x, f_y` in pixels):

.. math::

    z = \frac{r}{\sqrt{1 + \left(\frac{x - c_x}{f_x}\right)^2 + \left(\frac{y - c_y}{f_y}\right)^2}}

Windows
-------
A data window inside the display window is placed at its offset; pixels outside it are "no
data": color 0, alpha 0, depth ``+inf``, velocity 0 (an alpha plane is created if the file has
none). A data window reaching outside the display window (overscan) is refused — never
silently cropped or misplaced. All parts used must share one data and display window.

Writing
-------
:func:`write_frame` is atomic (temporary file in the output directory, then ``os.replace``),
ZIP-compressed. ``half=True`` stores color, alpha and velocity as float16 but **depth stays
float32** (half tops out at 65504 and has an 11-bit mantissa; Blender also keeps Z full float).
``+inf`` depth is kept as ``+inf`` (clpost, arnold), ``1e10`` (blender) or ``0`` (nuke, 1/z).

References: OpenEXR file layout and multi-part files, https://openexr.com/en/latest/;
Blender manual, "Render Passes" (Depth, Vector); Foundry Nuke reference guide, ScanlineRender,
ZDefocus, VectorBlur; Autodesk Arnold user guide, "AOVs" and the ``motion_vector`` shader.
"""
from __future__ import annotations

import math
import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np
import OpenEXR

from .atomic import atomic_path
from .errors import InputError, OutputError
from .frame import Frame

LAYOUTS = ("clpost", "blender", "nuke", "arnold")
DEPTH_KINDS = ("planar", "radial", "inverse")
"""How a file's depth channel is to be read: metres along the optical axis, metres along the
camera ray, or 1/planar metres (Nuke classic)."""

SKY_DEPTH_M = 1e10
"""Blender writes this for "no hit"; any depth at or above it is read as ``+inf``."""

BLENDER_VIEW_LAYER = "ViewLayer"
_HALF_MAX = float(np.finfo(np.float16).max)
_DEFAULT_DEPTH_KIND = {"clpost": "planar", "blender": "planar", "nuke": "inverse", "arnold": "radial"}
# Blender's vectors are converted by _blender_velocity (verified), the others here.
_DEFAULT_Y_UP = {"clpost": False, "nuke": True, "arnold": True}
# Attributes OpenEXR manages itself; a user header must not override them.
_RESERVED_ATTRS = frozenset({
    "channels", "compression", "dataWindow", "displayWindow", "lineOrder", "pixelAspectRatio",
    "screenWindowCenter", "screenWindowWidth", "type", "name", "tiles", "chunkCount", "version",
})
_BLENDER_COMBINED_R = re.compile(r"^(?P<layer>.+)\.Combined\.R$")


class DepthConventionWarning(UserWarning):
    """The depth could not be converted to planar metres at import (e.g. radial, no focal)."""


Window = tuple[tuple[int, int], tuple[int, int]]
"""((x_min, y_min), (x_max, y_max)), inclusive, as in the EXR header."""


@dataclass(frozen=True)
class _Part:
    """One part of a file as read: its channels already as numpy planes of the data window."""

    index: int
    name: str
    header: dict
    planes: dict[str, np.ndarray]
    types: dict[str, str]
    data_window: Window
    display_window: Window


# ----------------------------------------------------------------------------------------------
# Reading
# ----------------------------------------------------------------------------------------------

def _window(header: dict, key: str) -> Window:
    lo, hi = header[key]
    return (int(lo[0]), int(lo[1])), (int(hi[0]), int(hi[1]))


def _window_str(w: Window) -> str:
    (x0, y0), (x1, y1) = w
    return f"({x0},{y0})-({x1},{y1})"


def _load(path: str | os.PathLike) -> list[_Part]:
    """All parts of ``path`` with their pixel planes; InputError for anything unreadable."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: no such file; check the path (and the frame number of a sequence)")
    if not p.is_file():
        raise InputError(f"{p}: is not a file; give the path of an .exr image")
    if not OpenEXR.isOpenExrFile(str(p)):
        raise InputError(f"{p}: not an OpenEXR file (bad magic number); clpost reads .exr images only")
    try:
        f = OpenEXR.File(str(p), separate_channels=True)
        raw_parts = list(f.parts)
    except Exception as e:  # the bindings raise RuntimeError/ValueError for damaged files
        raise InputError(f"{p}: cannot read EXR ({e}); the file is corrupt or truncated — re-render or re-copy it") from None
    if not raw_parts:
        # A damaged chunk table makes the bindings drop every part instead of raising.
        raise InputError(f"{p}: cannot read any image part; the file is corrupt or truncated — re-render or re-copy it")
    return [_part(p, i, rp) for i, rp in enumerate(raw_parts)]


def _part(path: Path, index: int, rp: Any) -> _Part:
    header = dict(rp.header)
    name = str(rp.name() or header.get("name") or "")
    label = f"part {index}" + (f" '{name}'" if name else "")
    storage = rp.type()
    if storage not in (OpenEXR.scanlineimage, OpenEXR.tiledimage):
        raise InputError(f"{path}: {label} is a deep image ({storage.name}); flatten it to a regular EXR first")
    dw, disp = _window(header, "dataWindow"), _window(header, "displayWindow")
    shape = (dw[1][1] - dw[0][1] + 1, dw[1][0] - dw[0][0] + 1)
    planes: dict[str, np.ndarray] = {}
    types: dict[str, str] = {}
    for cname, ch in rp.channels.items():
        if ch.xSampling != 1 or ch.ySampling != 1:
            raise InputError(f"{path}: channel {cname!r} in {label} is subsampled "
                             f"({ch.xSampling}×{ch.ySampling}); write full-resolution channels")
        px = np.asarray(ch.pixels)
        if px.shape != shape:
            raise InputError(f"{path}: channel {cname!r} in {label} has {px.shape} pixels, data window "
                             f"{_window_str(dw)} needs {shape}; the file is corrupt or truncated — re-render it")
        planes[cname] = px
        types[cname] = ch.type().name.lower()
    return _Part(index, name, header, planes, types, dw, disp)


def _merge(path: Path, parts: Sequence[_Part]) -> tuple[dict[str, np.ndarray], Window, Window]:
    """Channels of all parts in one dict, after checking the parts agree on their windows."""
    first = parts[0]
    planes: dict[str, np.ndarray] = {}
    for part in parts:
        if (part.data_window, part.display_window) != (first.data_window, first.display_window):
            raise InputError(
                f"{path}: part {part.index} '{part.name}' has data window {_window_str(part.data_window)} / "
                f"display window {_window_str(part.display_window)} but part 0 has "
                f"{_window_str(first.data_window)} / {_window_str(first.display_window)}; "
                "write all passes at one resolution and one region"
            )
        for cname, px in part.planes.items():
            if cname in planes:
                raise InputError(f"{path}: channel {cname!r} appears in more than one part; "
                                 "rename one of them so the layout is unambiguous")
            planes[cname] = px
    return planes, first.data_window, first.display_window


def _blender_layer(names: Iterable[str]) -> str | None:
    layers = {m["layer"] for n in names if (m := _BLENDER_COMBINED_R.match(n))}
    if not layers:
        return None
    # With several view layers, prefer Blender's default name, else the first alphabetically.
    return BLENDER_VIEW_LAYER if BLENDER_VIEW_LAYER in layers else sorted(layers)[0]


def _names_preview(names: Iterable[str], limit: int = 24) -> str:
    names = sorted(names)
    more = f", … (+{len(names) - limit} more)" if len(names) > limit else ""
    return ", ".join(names[:limit]) + more if names else "(none)"


def detect_layout(channel_names: Iterable[str]) -> str:
    """The layout (one of :data:`LAYOUTS`) that channel names (of all parts) were written in.

    Rules, first match wins: ``<layer>.Combined.R/G/B`` → blender; ``R, G, B`` with
    ``motionvector.*`` → arnold; ``R, G, B`` with ``depth.Z``, ``forward.*`` or ``backward.*``
    → nuke; ``R, G, B`` → clpost. An Arnold file without a motion vector AOV looks exactly
    like a clpost one (``R, G, B, Z``): pass the layout explicitly for those.
    """
    names = set(channel_names)
    layer = _blender_layer(names)
    if layer is not None and {f"{layer}.Combined.{c}" for c in "GB"} <= names:
        return "blender"
    if {"R", "G", "B"} <= names:
        if any(n.startswith("motionvector.") for n in names):
            return "arnold"
        if "depth.Z" in names or any(n.startswith(("forward.", "backward.")) for n in names):
            return "nuke"
        return "clpost"
    raise InputError(
        f"no known channel layout in channels [{_names_preview(names)}]; clpost needs color as "
        "R, G, B (clpost/nuke/arnold) or <ViewLayer>.Combined.R/G/B (blender) — rename the "
        f"channels or pass the layout explicitly, one of {', '.join(LAYOUTS)}"
    )


@dataclass(frozen=True)
class _Mapped:
    """Planes picked for one layout, still in the file's conventions."""

    color: tuple[np.ndarray, np.ndarray, np.ndarray]
    alpha: np.ndarray | None
    depth: np.ndarray | None
    velocity: tuple[np.ndarray, np.ndarray] | None
    velocity_note: str
    """How the velocity was derived, for the conversion below ("forward" or "backward")."""


def _take(path: Path, planes: dict[str, np.ndarray], names: Sequence[str], what: str,
          layout: str, required: bool) -> list[np.ndarray] | None:
    present = [n for n in names if n in planes]
    if not present and not required:
        return None
    if len(present) != len(names):
        missing = [n for n in names if n not in planes]
        raise InputError(
            f"{path}: layout {layout!r} needs {what} channels {', '.join(names)}; missing "
            f"{', '.join(missing)} (channels found: {_names_preview(planes)}); "
            "pick the right layout (--channels) or re-render with that pass"
        )
    out = []
    for n in names:
        a = planes[n]
        if a.dtype.kind != "f":
            raise InputError(f"{path}: channel {n!r} is {a.dtype} (integer), {what} must be half or float; "
                             "re-render the pass as float")
        out.append(a)
    return out


def _one(planes: list[np.ndarray] | None) -> np.ndarray | None:
    return None if planes is None else planes[0]


def _map_channels(path: Path, planes: dict[str, np.ndarray], layout: str) -> _Mapped:
    if layout == "blender":
        layer = _blender_layer(planes) or BLENDER_VIEW_LAYER
        pre = f"{layer}."
        color = _take(path, planes, [pre + "Combined." + c for c in "RGB"], "color", layout, True)
        alpha = _take(path, planes, [pre + "Combined.A"], "alpha", layout, False)
        depth = _take(path, planes, [pre + "Depth.Z"], "depth", layout, False)
        vel = _take(path, planes, [pre + "Vector.Z", pre + "Vector.W"], "velocity", layout, False)
        note = "forward"
        if vel is None:
            vel = _take(path, planes, [pre + "Vector.X", pre + "Vector.Y"], "velocity", layout, False)
            note = "backward"
        return _Mapped(tuple(color), _one(alpha), _one(depth), vel and tuple(vel), note)
    color = _take(path, planes, ["R", "G", "B"], "color", layout, True)
    alpha = _take(path, planes, ["A"], "alpha", layout, False)
    if layout == "clpost":
        depth = _take(path, planes, ["Z"], "depth", layout, False)
        vel = _take(path, planes, ["velocity.X", "velocity.Y"], "velocity", layout, False)
        note = "forward"
    elif layout == "nuke":
        depth = _take(path, planes, ["depth.Z"], "depth", layout, False)
        vel = _take(path, planes, ["forward.u", "forward.v"], "velocity", layout, False)
        note = "forward"
        if vel is None:
            vel = _take(path, planes, ["backward.u", "backward.v"], "velocity", layout, False)
            note = "backward"
    else:  # arnold
        depth = _take(path, planes, ["Z"], "depth", layout, False)
        xy = ("X", "Y") if "motionvector.X" in planes else ("R", "G")
        vel = _take(path, planes, [f"motionvector.{c}" for c in xy], "velocity", layout, False)
        note = "forward"
    return _Mapped(tuple(color), _one(alpha), _one(depth), vel and tuple(vel), note)


def _place(plane: np.ndarray, data: Window, display: Window, fill: float) -> np.ndarray:
    """The data-window plane put at its place in a display-window-sized plane."""
    (dx0, dy0), (dx1, dy1) = data
    (ox0, oy0), (ox1, oy1) = display
    if (dx0, dy0, dx1, dy1) == (ox0, oy0, ox1, oy1):
        return plane
    out = np.full((oy1 - oy0 + 1, ox1 - ox0 + 1), fill, dtype=plane.dtype)
    out[dy0 - oy0:dy1 - oy0 + 1, dx0 - ox0:dx1 - ox0 + 1] = plane
    return out


def _check_windows(path: Path, data: Window, display: Window) -> None:
    (dx0, dy0), (dx1, dy1) = data
    (ox0, oy0), (ox1, oy1) = display
    if dx1 < dx0 or dy1 < dy0:
        raise InputError(f"{path}: empty data window {_window_str(data)}; re-render the frame")
    if dx0 < ox0 or dy0 < oy0 or dx1 > ox1 or dy1 > oy1:
        raise InputError(
            f"{path}: data window {_window_str(data)} extends beyond the display window "
            f"{_window_str(display)} (overscan); clpost will not crop or misplace pixels — "
            "render without overscan or crop to the display window (e.g. oiiotool --crop)"
        )


def _focal_xy(focal_px: float | tuple[float, float]) -> tuple[float, float]:
    fx, fy = (focal_px, focal_px) if np.isscalar(focal_px) else focal_px
    fx, fy = float(fx), float(fy)
    if not (math.isfinite(fx) and math.isfinite(fy) and fx > 0 and fy > 0):
        raise InputError(f"focal_px={focal_px!r} must be > 0 pixels (focal length mm / pixel pitch mm)")
    return fx, fy


def _ray_stretch(shape: tuple[int, int], focal_px: float | tuple[float, float]) -> np.ndarray:
    """|ray| / z per pixel for a pinhole with its principal point at the image centre."""
    fx, fy = _focal_xy(focal_px)
    h, w = shape
    x = (np.arange(w, dtype=np.float64) - (w - 1) / 2) / fx
    y = (np.arange(h, dtype=np.float64) - (h - 1) / 2) / fy
    return np.sqrt(1.0 + x[None, :] ** 2 + y[:, None] ** 2)


def radial_to_planar(depth: np.ndarray, focal_px: float | tuple[float, float]) -> np.ndarray:
    """Planar depth (camera-space Z) from distance along the camera ray, both in metres.

    ``focal_px`` is the focal length in pixels (scalar or ``(f_x, f_y)``): the focal length in
    mm divided by the pixel pitch in mm. ``+inf`` stays ``+inf``. See the module docstring.
    """
    d = np.asarray(depth, dtype=np.float32)
    return (d / _ray_stretch(d.shape, focal_px)).astype(np.float32)


def planar_to_radial(depth: np.ndarray, focal_px: float | tuple[float, float]) -> np.ndarray:
    """Inverse of :func:`radial_to_planar`."""
    d = np.asarray(depth, dtype=np.float32)
    return (d * _ray_stretch(d.shape, focal_px)).astype(np.float32)


def _depth_to_planar(path: Path, raw: np.ndarray, kind: str,
                     focal_px: float | tuple[float, float] | None) -> tuple[np.ndarray, str]:
    # Arithmetic on half planes would lose precision: one explicit conversion here.
    d = np.asarray(raw, dtype=np.float32)
    if kind == "inverse":
        with np.errstate(divide="ignore"):
            d = np.where(d == 0, np.float32(np.inf), np.float32(1) / d).astype(np.float32)
    d = np.where(d >= SKY_DEPTH_M, np.float32(np.inf), d).astype(np.float32)
    if kind == "radial":
        if focal_px is None:
            warnings.warn(
                f"{path}: depth is radial distance (layout default for Arnold Z, not verified) and "
                "no focal_px was given, so it is kept radial (metadata depth_kind='radial'); pass "
                "focal_px to convert to planar, or depth='planar' if your Z is planar",
                DepthConventionWarning, stacklevel=3,
            )
            return d, "radial"
        d = radial_to_planar(d, focal_px)
    return d, "planar"


def _velocity(m: _Mapped, y_up: bool) -> np.ndarray:
    u = np.asarray(m.velocity[0], dtype=np.float32)
    v = np.asarray(m.velocity[1], dtype=np.float32)
    # A "backward" pair (Nuke backward.u/v, Blender XY) or Blender's ZW (current − next) points
    # against the motion; negate it, assuming constant velocity for the backward case.
    sign = -1.0 if (m.velocity_note == "backward") else 1.0
    return np.stack([sign * u, sign * (-v if y_up else v)], axis=-1).astype(np.float32)


def _blender_velocity(m: _Mapped) -> np.ndarray:
    # ZW = current − next and XY = previous − current, both y up: forward y-down is (−a, +b).
    a = np.asarray(m.velocity[0], dtype=np.float32)
    b = np.asarray(m.velocity[1], dtype=np.float32)
    return np.stack([-a, b], axis=-1).astype(np.float32)


def _str_attrs(header: dict) -> dict[str, str]:
    return {str(k): v for k, v in header.items() if isinstance(v, str)}


def _frame_from_parts(path: Path, parts: Sequence[_Part], layout: str | None, depth: str | None,
                      focal_px: float | tuple[float, float] | None,
                      velocity_y_up: bool | None) -> Frame:
    planes, data, display = _merge(path, parts)
    if layout is None:
        try:
            layout = detect_layout(planes)
        except InputError as e:
            raise InputError(f"{path}: {e}") from None
    elif layout not in LAYOUTS:
        raise InputError(f"{path}: layout {layout!r} is unknown; use one of {', '.join(LAYOUTS)}")
    kind = depth or _DEFAULT_DEPTH_KIND[layout]
    if kind not in DEPTH_KINDS:
        raise InputError(f"depth={depth!r} is unknown; use one of {', '.join(DEPTH_KINDS)}")
    _check_windows(path, data, display)
    m = _map_channels(path, planes, layout)

    color = np.stack([_place(c, data, display, 0.0) for c in m.color], axis=-1)
    alpha = None
    if m.alpha is not None:
        # Filters with negative lobes overshoot coverage a hair; only that much is clipped.
        a = np.asarray(m.alpha)
        a = np.where((a > 1) & (a <= 1 + 1e-3), 1, np.where((a < 0) & (a >= -1e-3), 0, a)).astype(a.dtype)
        alpha = _place(a, data, display, 0.0)
    elif data != display:
        alpha = _place(np.ones_like(m.color[0]), data, display, 0.0)
    depth_m, kind_out = None, "planar"
    if m.depth is not None:
        d, kind_out = _depth_to_planar(path, _place(m.depth, data, display, np.inf), kind, focal_px)
        depth_m = d
    vel = None
    if m.velocity is not None:
        if layout == "blender":
            vel = _blender_velocity(m)
        else:
            y_up = _DEFAULT_Y_UP[layout] if velocity_y_up is None else bool(velocity_y_up)
            vel = _velocity(m, y_up)
        vel = np.stack([_place(vel[..., i], data, display, 0.0) for i in range(2)], axis=-1)
    metadata = {"path": str(path), "layout": layout, "header": _str_attrs(parts[0].header),
                "depth_kind": kind_out}
    try:
        return Frame(color=color, depth=depth_m, velocity=vel, alpha=alpha, metadata=metadata)
    except InputError as e:
        raise InputError(f"{path} (layout {layout}): {e}") from None


def read_frame(path: str | os.PathLike, layout: str | None = None, *, depth: str | None = None,
               focal_px: float | tuple[float, float] | None = None,
               velocity_y_up: bool | None = None) -> Frame:
    """Read one EXR (single- or multi-part, half or float) into a :class:`Frame`.

    ``layout`` (one of :data:`LAYOUTS`) overrides auto-detection. The keyword options override
    a layout's documented assumptions (module docstring): ``depth`` is one of
    :data:`DEPTH_KINDS`; ``focal_px`` (focal length in pixels, scalar or ``(f_x, f_y)``) lets
    radial depth be converted to planar; ``velocity_y_up`` sets the vector's y sign for the
    clpost, nuke and arnold layouts (Blender's verified convention is fixed).

    ``metadata`` = ``{"path", "layout", "header": str attributes of the first part,
    "depth_kind": "planar" | "radial"}``. Color is required; depth and velocity are optional
    (``None`` when the file has no such pass).
    """
    p = Path(path)
    return _frame_from_parts(p, _load(p), layout, depth, focal_px, velocity_y_up)


# ----------------------------------------------------------------------------------------------
# Writing
# ----------------------------------------------------------------------------------------------

def _encode(path: Path, name: str, a: np.ndarray, half: bool) -> np.ndarray:
    if not half:
        return np.ascontiguousarray(a, dtype=np.float32)
    big = float(np.max(np.abs(a))) if a.size else 0.0
    if big > _HALF_MAX:
        raise InputError(f"{path}: {name} reaches {big:g}, beyond float16's {_HALF_MAX:g}; "
                         "write with half=False (float32) or scale the data")
    return np.ascontiguousarray(a, dtype=np.float16)


def _layout_parts(path: Path, frame: Frame, layout: str, half: bool,
                  focal_px: float | tuple[float, float] | None) -> list[tuple[str, dict[str, np.ndarray]]]:
    """(part name, channels) for each part to write, with our conventions inverted."""
    c = frame.color
    rgb = {k: _encode(path, "color", c[..., i], half) for i, k in enumerate("RGB")}
    alpha = None if frame.alpha is None else _encode(path, "alpha", frame.alpha, half)
    z = frame.depth
    vel = frame.velocity
    vx = vy = None
    if vel is not None:
        vx = _encode(path, "velocity", vel[..., 0], half)
        vy = _encode(path, "velocity", vel[..., 1], half)
    # Depth stays float32 even for half files (precision and range, see the module docstring).
    if layout == "blender":
        pre = BLENDER_VIEW_LAYER
        combined = {f"{pre}.Combined.{k}": a for k, a in rgb.items()}
        # Blender always writes RGBA for Combined; no alpha means opaque.
        combined[f"{pre}.Combined.A"] = alpha if alpha is not None else np.ones_like(rgb["R"])
        parts = [(f"{pre}.Combined", combined)]
        if z is not None:
            parts.append((f"{pre}.Depth", {f"{pre}.Depth.Z": np.where(np.isinf(z), SKY_DEPTH_M, z).astype(np.float32)}))
        if vel is not None:
            # Constant velocity: previous − current = current − next = (−vx, +vy) in y up.
            parts.append((f"{pre}.Vector", {f"{pre}.Vector.X": -vx, f"{pre}.Vector.Y": vy,
                                            f"{pre}.Vector.Z": -vx, f"{pre}.Vector.W": vy}))
        return parts
    ch = dict(rgb)
    if alpha is not None:
        ch["A"] = alpha
    if layout == "clpost":
        if z is not None:
            ch["Z"] = np.ascontiguousarray(z, dtype=np.float32)
        if vel is not None:
            ch["velocity.X"], ch["velocity.Y"] = vx, vy
    elif layout == "nuke":
        if z is not None:
            ch["depth.Z"] = np.where(np.isinf(z), 0, np.float32(1) / z).astype(np.float32)
        if vel is not None:
            ch["forward.u"], ch["forward.v"] = vx, -vy
    else:  # arnold
        if z is not None:
            ch["Z"] = planar_to_radial(z, focal_px) if focal_px is not None else np.ascontiguousarray(z, dtype=np.float32)
        if vel is not None:
            ch["motionvector.R"], ch["motionvector.G"] = vx, -vy
            ch["motionvector.B"] = np.zeros_like(vx)
    return [("", ch)]


def _user_header(path: Path, header: dict[str, str] | None) -> dict[str, str]:
    out: dict[str, str] = {}
    for k, v in (header or {}).items():
        if not isinstance(k, str) or not isinstance(v, str):
            raise InputError(f"{path}: header attribute {k!r}={v!r} must be a str name and a str value; "
                             "format numbers with str() first")
        if k in _RESERVED_ATTRS:
            raise InputError(f"{path}: header attribute {k!r} is managed by OpenEXR; use another name, "
                             "e.g. 'clpost.<name>'")
        out[k] = v
    return out


COMPRESSIONS = {
    # name: (OpenEXR constant, why pick it). Measured here on a 1280×720 frame with 6 float32
    # channels (2-core machine): write / read / size.
    "zip": ("ZIP_COMPRESSION", "lossless, what Blender and most tools write: 280 / 75 ms, 16.9 MB"),
    "zips": ("ZIPS_COMPRESSION", "lossless, one scanline per block: 240 / 78 ms, 18.5 MB"),
    "piz": ("PIZ_COMPRESSION", "lossless wavelet, smallest for noisy renders: 450 / 115 ms, 14.1 MB"),
    "rle": ("RLE_COMPRESSION", "lossless run-length, fast: 66 / 21 ms, 21.9 MB"),
    "none": ("NO_COMPRESSION", "fastest for sequences on local disks: 21 / 22 ms, 22.1 MB"),
}
"""Lossless compressions offered for writing (lossy DWA/B44 are not: outputs are data)."""


def _build_file(parts: list[tuple[str, dict[str, np.ndarray]]], attrs: dict[str, str],
                compression: str = "zip") -> Any:
    base = {"compression": getattr(OpenEXR, COMPRESSIONS[compression][0]), "type": OpenEXR.scanlineimage}
    if len(parts) == 1 and not parts[0][0]:
        return OpenEXR.File({**base, **attrs}, parts[0][1])
    # Blender tags its multilayer files so other tools recognise the layer.pass.channel naming.
    extra = {"BlenderMultiChannel": "Blender V2.55.1 and newer"}
    return OpenEXR.File([OpenEXR.Part({**base, **extra, **attrs}, ch, name) for name, ch in parts])


def _write_exr(exr_file: Any, tmp_path: str) -> None:
    """The one call that puts bytes on disk (a seam for tests that simulate a failed write)."""
    exr_file.write(tmp_path)


def write_frame(path: str | os.PathLike, frame: Frame, header: dict[str, str] | None = None,
                half: bool = False, layout: str = "clpost", *,
                focal_px: float | tuple[float, float] | None = None, compression: str = "zip") -> None:
    """Write ``frame``'s color (+alpha), depth and velocity in one layout, atomically.

    ``clpost``, ``nuke`` and ``arnold`` are single-part files; ``blender`` is one part per pass
    (Combined RGBA, Depth, Vector) as Blender 5.x writes them. ``header`` holds extra string
    attributes (added to every part). ``half`` stores color/alpha/velocity as float16 (depth
    stays float32). ``compression`` is one of :data:`COMPRESSIONS` (lossless). For ``arnold``, ``focal_px`` writes Z as radial distance (what the reader
    assumes); without it Z is written planar. Any failure leaves an existing ``path`` untouched
    and no temporary file behind.
    """
    p = Path(path)
    if layout not in LAYOUTS:
        raise InputError(f"{p}: layout {layout!r} is unknown; use one of {', '.join(LAYOUTS)}")
    if not isinstance(frame, Frame):
        raise InputError(f"{p}: write_frame needs a clpost.frame.Frame, got {type(frame).__name__}")
    if compression not in COMPRESSIONS:
        raise InputError(f"{p}: compression {compression!r} is unknown; use one of {', '.join(COMPRESSIONS)}")
    exr_file = _build_file(_layout_parts(p, frame, layout, half, focal_px), _user_header(p, header),
                           compression)
    # Whatever goes wrong (including Ctrl-C), the old output stays and no temp file remains.
    with atomic_path(p) as tmp:
        try:
            _write_exr(exr_file, str(tmp))
        except Exception as e:
            raise OutputError(f"{p}: cannot write EXR ({e}); check the disk has space and the path "
                              "is a writable file") from None


# ----------------------------------------------------------------------------------------------
# Inspection
# ----------------------------------------------------------------------------------------------

def _depth_stats(depth: np.ndarray | None) -> dict | None:
    if depth is None:
        return None
    finite = depth[np.isfinite(depth)]
    return {
        "min": float(finite.min()) if finite.size else None,
        "max": float(finite.max()) if finite.size else None,
        "inf_count": int(np.count_nonzero(np.isinf(depth))),
    }


def _velocity_stats(vel: np.ndarray | None) -> dict | None:
    if vel is None:
        return None
    mag = np.hypot(vel[..., 0].astype(np.float64), vel[..., 1].astype(np.float64))
    return {
        "x": (float(vel[..., 0].min()), float(vel[..., 0].max())),
        "y": (float(vel[..., 1].min()), float(vel[..., 1].max())),
        "max_magnitude": float(mag.max()),
    }


def info(path: str | os.PathLike) -> dict:
    """What ``clpost info`` prints: parts, channels, windows, detected layout, depth and velocity.

    Keys: ``path``, ``parts`` (list of ``{"name", "channels": [(name, type)], "data_window",
    "display_window"}``), ``size`` ((width, height) of the display window), ``layout`` (None if
    no layout fits), ``depth_kind``, ``depth`` (``{"min", "max", "inf_count"}`` over finite
    values, or None), ``velocity`` (``{"x": (min, max), "y": (min, max), "max_magnitude"}`` in
    our convention, or None), ``problems`` (messages that stop :func:`read_frame`, or warnings).
    """
    p = Path(path)
    parts = _load(p)
    (ox0, oy0), (ox1, oy1) = parts[0].display_window
    out: dict[str, Any] = {
        "path": str(p),
        "parts": [{"name": pt.name, "channels": sorted(pt.types.items()),
                   "data_window": pt.data_window, "display_window": pt.display_window} for pt in parts],
        "size": (ox1 - ox0 + 1, oy1 - oy0 + 1),
        "layout": None, "depth_kind": None, "depth": None, "velocity": None, "problems": [],
    }
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", DepthConventionWarning)
            frame = _frame_from_parts(p, parts, None, None, None, None)
    except InputError as e:
        out["problems"].append(str(e))
        return out
    out["problems"].extend(str(w.message) for w in caught)
    out["layout"] = frame.metadata["layout"]
    out["depth_kind"] = frame.metadata["depth_kind"]
    out["depth"] = _depth_stats(frame.depth)
    out["velocity"] = _velocity_stats(frame.velocity)
    return out


def _fmt(v: float | None) -> str:
    return "—" if v is None else f"{v:.6g}"


def format_info(d: dict) -> str:
    """Human-readable text of an :func:`info` dict."""
    w, h = d["size"]
    lines = [f"{d['path']}: {w}×{h}, layout {d['layout'] or 'unknown'}, {len(d['parts'])} part(s)"]
    for i, part in enumerate(d["parts"]):
        chans = ", ".join(f"{n} ({t})" for n, t in part["channels"])
        lines.append(f"  part {i} {part['name'] or '(unnamed)'}: data {_window_str(part['data_window'])}, "
                     f"display {_window_str(part['display_window'])}")
        lines.append(f"    channels: {chans}")
    dep = d["depth"]
    if dep is None:
        lines.append("  depth: none")
    else:
        lines.append(f"  depth ({d['depth_kind']}, m): min {_fmt(dep['min'])}, max {_fmt(dep['max'])}, "
                     f"+inf (sky) {dep['inf_count']} px")
    vel = d["velocity"]
    if vel is None:
        lines.append("  velocity: none")
    else:
        lines.append(f"  velocity (px/frame, +x right, +y down): x [{_fmt(vel['x'][0])}, {_fmt(vel['x'][1])}], "
                     f"y [{_fmt(vel['y'][0])}, {_fmt(vel['y'][1])}], max |v| {_fmt(vel['max_magnitude'])}")
    lines.extend(f"  problem: {msg}" for msg in d["problems"])
    return "\n".join(lines)
