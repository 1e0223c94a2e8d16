r"""One :class:`Layout` object per renderer convention (clpost, Blender, Nuke, Arnold).

A layout knows the channel names its renderer writes, how to recognise them, and how to convert
its depth and velocity to clpost's conventions and back; :mod:`clpost.exr.io` does the file
reading and writing and never looks at a channel name itself. The conventions (and which of
them are verified) are tabled in the :mod:`clpost.exr` docstring.

Radial → planar (pinhole, principal point at the image centre ((W−1)/2, (H−1)/2) in the
OpenCV pixel convention of CONVENTIONS.md, focal lengths :math:`f_x, f_y` in pixels):

.. math::

    z = \frac{r}{\sqrt{1 + \left(\frac{x - c_x}{f_x}\right)^2 + \left(\frac{y - c_y}{f_y}\right)^2}}
"""
from __future__ import annotations

import math
import re
import warnings
from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ..errors import InputError

DEPTH_KINDS = ("planar", "radial", "inverse")
"""How a file's depth channel is to be read: metres along the optical axis, metres along the
camera ray, or 1/planar metres (Nuke classic)."""

SKY_DEPTH_M = 1e10
"""Blender writes this for "no hit"; any depth at or above it is read as ``+inf``."""

BLENDER_VIEW_LAYER = "ViewLayer"
_BLENDER_COMBINED_R = re.compile(r"^(?P<layer>.+)\.Combined\.R$")

Parts = list[tuple[str, dict[str, np.ndarray]]]
"""(part name, channels) per part to write; one unnamed part is a single-part file."""


class DepthConventionWarning(UserWarning):
    """The depth could not be converted to planar metres at import (e.g. radial, no focal)."""


@dataclass(frozen=True)
class Mapped:
    """Planes picked by a layout, still in the file's conventions."""

    color: tuple[np.ndarray, np.ndarray, np.ndarray]
    alpha: np.ndarray | None
    depth: np.ndarray | None
    velocity: tuple[np.ndarray, np.ndarray] | None
    velocity_note: str
    """How the velocity pair was written: "forward" or "backward" (points against the motion)."""


def names_preview(names: Iterable[str], limit: int = 24) -> str:
    names = sorted(names)
    more = f", … (+{len(names) - limit} more)" if len(names) > limit else ""
    return ", ".join(names[:limit]) + more if names else "(none)"


def _take(path: Path, planes: dict[str, np.ndarray], names: Sequence[str], what: str,
          layout: str, required: bool) -> list[np.ndarray] | None:
    present = [n for n in names if n in planes]
    if not present and not required:
        return None
    if len(present) != len(names):
        missing = [n for n in names if n not in planes]
        raise InputError(
            f"{path}: layout {layout!r} needs {what} channels {', '.join(names)}; missing "
            f"{', '.join(missing)} (channels found: {names_preview(planes)}); "
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


def _pair(planes: list[np.ndarray] | None) -> tuple[np.ndarray, np.ndarray] | None:
    return None if planes is None else (planes[0], planes[1])


def _rgb_alpha(path: Path, planes: dict[str, np.ndarray], layout: str):
    color = _take(path, planes, ["R", "G", "B"], "color", layout, True)
    alpha = _take(path, planes, ["A"], "alpha", layout, False)
    return tuple(color), _one(alpha)


# -- depth conventions ---------------------------------------------------------------------------

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


def depth_to_planar(path: Path, raw: np.ndarray, kind: str,
                    focal_px: float | tuple[float, float] | None, *, in_place: bool = False) -> tuple[np.ndarray, str]:
    """A file's depth plane of ``kind`` (:data:`DEPTH_KINDS`) as planar metres, ``+inf`` sky;
    radial depth without ``focal_px`` stays radial (returned kind says which). ``in_place``: a
    float32 ``raw`` is the caller's to overwrite (a reader's own plane: no copy)."""
    # Arithmetic on half planes would lose precision: one explicit conversion here.
    d = np.asarray(raw, dtype=np.float32)
    if kind == "inverse":
        with np.errstate(divide="ignore"):
            d = np.where(d == 0, np.float32(np.inf), np.float32(1) / d).astype(np.float32)
    elif (d is raw and not in_place) or not d.flags.writeable:
        d = d.copy()
    np.copyto(d, np.float32(np.inf), where=d >= SKY_DEPTH_M)
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


def _interleave(x: np.ndarray, y: np.ndarray, sx: float, sy: float) -> np.ndarray:
    """(H, W, 2) float32 of ``sx·x`` and ``sy·y`` (signs ±1), written once (half planes convert
    on the way)."""
    out = np.empty(np.shape(x) + (2,), np.float32)
    for i, (a, s) in enumerate(((x, sx), (y, sy))):
        if s < 0:
            np.negative(a, out=out[..., i], casting="unsafe")
        else:
            np.copyto(out[..., i], a, casting="unsafe")
    return out


def _pair_velocity(m: Mapped, y_up: bool) -> np.ndarray:
    # A "backward" pair (Nuke backward.u/v) points against the motion; negate it, assuming
    # constant velocity.
    sign = -1.0 if (m.velocity_note == "backward") else 1.0
    return _interleave(m.velocity[0], m.velocity[1], sign, -sign if y_up else sign)


# -- the layouts --------------------------------------------------------------------------------

class Layout(ABC):
    """One renderer's channel convention. Subclasses set :attr:`name`, :attr:`depth_kind` (the
    default reading of its depth channel) and :attr:`velocity_y_up` (None: fixed by the layout,
    not overridable)."""

    name: str = ""
    depth_kind: str = "planar"
    velocity_y_up: bool | None = False

    @abstractmethod
    def matches(self, names: set[str]) -> bool:
        """Whether channel names (of all parts) look written in this layout."""

    @abstractmethod
    def map_channels(self, path: Path, planes: dict[str, np.ndarray]) -> Mapped:
        """The planes this layout reads, in the file's conventions."""

    def velocity(self, m: Mapped, y_up: bool | None) -> np.ndarray:
        """(H, W, 2) forward, y down px/frame from the mapped pair; ``y_up`` overrides the default."""
        return _pair_velocity(m, self.velocity_y_up if y_up is None else bool(y_up))

    @abstractmethod
    def parts(self, rgb: dict[str, np.ndarray], alpha: np.ndarray | None, depth: np.ndarray | None,
              vel: tuple[np.ndarray, np.ndarray] | None,
              focal_px: float | tuple[float, float] | None) -> Parts:
        """The parts to write: encoded color/alpha/velocity planes (float16 or 32) and planar depth
        (float32, ``+inf`` sky) with this layout's conventions applied."""

    def __repr__(self) -> str:
        return f"<exr layout {self.name}>"


class ClpostLayout(Layout):
    """``R, G, B, (A)``, ``Z`` planar metres, ``velocity.X/Y`` forward px/frame y down."""

    name = "clpost"

    def matches(self, names):
        return {"R", "G", "B"} <= names

    def map_channels(self, path, planes):
        color, alpha = _rgb_alpha(path, planes, self.name)
        depth = _take(path, planes, ["Z"], "depth", self.name, False)
        vel = _take(path, planes, ["velocity.X", "velocity.Y"], "velocity", self.name, False)
        return Mapped(color, alpha, _one(depth), _pair(vel), "forward")

    def parts(self, rgb, alpha, depth, vel, focal_px):
        ch = dict(rgb)
        if alpha is not None:
            ch["A"] = alpha
        if depth is not None:
            ch["Z"] = np.ascontiguousarray(depth, dtype=np.float32)
        if vel is not None:
            ch["velocity.X"], ch["velocity.Y"] = vel
        return [("", ch)]


class BlenderLayout(Layout):
    """Multilayer, one part per pass: ``<layer>.Combined.RGBA``, ``.Depth.Z`` (planar, 1e10 sky),
    ``.Vector.XYZW`` (y up; XY = previous − current, ZW = current − next)."""

    name = "blender"
    velocity_y_up = None

    @staticmethod
    def view_layer(names: Iterable[str]) -> str | None:
        layers = {m["layer"] for n in names if (m := _BLENDER_COMBINED_R.match(n))}
        if not layers:
            return None
        # With several view layers, prefer Blender's default name, else the first alphabetically.
        return BLENDER_VIEW_LAYER if BLENDER_VIEW_LAYER in layers else sorted(layers)[0]

    def matches(self, names):
        layer = self.view_layer(names)
        return layer is not None and {f"{layer}.Combined.{c}" for c in "GB"} <= names

    def map_channels(self, path, planes):
        pre = f"{self.view_layer(planes) or BLENDER_VIEW_LAYER}."
        color = _take(path, planes, [pre + "Combined." + c for c in "RGB"], "color", self.name, True)
        alpha = _take(path, planes, [pre + "Combined.A"], "alpha", self.name, False)
        depth = _take(path, planes, [pre + "Depth.Z"], "depth", self.name, False)
        vel = _take(path, planes, [pre + "Vector.Z", pre + "Vector.W"], "velocity", self.name, False)
        note = "forward"
        if vel is None:
            vel = _take(path, planes, [pre + "Vector.X", pre + "Vector.Y"], "velocity", self.name, False)
            note = "backward"
        return Mapped(tuple(color), _one(alpha), _one(depth), _pair(vel), note)

    def velocity(self, m, y_up):
        # ZW = current − next and XY = previous − current, both y up: forward y-down is (−a, +b)
        # (verified with Blender 5.2 / Cycles; XY assumes constant velocity).
        return _interleave(m.velocity[0], m.velocity[1], -1.0, 1.0)

    def parts(self, rgb, alpha, depth, vel, focal_px):
        pre = BLENDER_VIEW_LAYER
        combined = {f"{pre}.Combined.{k}": a for k, a in rgb.items()}
        # Blender always writes RGBA for Combined; no alpha means opaque.
        combined[f"{pre}.Combined.A"] = alpha if alpha is not None else np.ones_like(rgb["R"])
        out = [(f"{pre}.Combined", combined)]
        if depth is not None:
            out.append((f"{pre}.Depth", {f"{pre}.Depth.Z": np.where(np.isinf(depth), SKY_DEPTH_M, depth).astype(np.float32)}))
        if vel is not None:
            vx, vy = vel
            # Constant velocity: previous − current = current − next = (−vx, +vy) in y up.
            out.append((f"{pre}.Vector", {f"{pre}.Vector.X": -vx, f"{pre}.Vector.Y": vy,
                                          f"{pre}.Vector.Z": -vx, f"{pre}.Vector.W": vy}))
        return out


class NukeLayout(Layout):
    """``R, G, B, (A)``, ``depth.Z`` = 1/z (0 = no hit), ``forward.u/v`` (or ``backward.u/v``) y up."""

    name = "nuke"
    depth_kind = "inverse"
    velocity_y_up = True

    def matches(self, names):
        return {"R", "G", "B"} <= names and (
            "depth.Z" in names or any(n.startswith(("forward.", "backward.")) for n in names))

    def map_channels(self, path, planes):
        color, alpha = _rgb_alpha(path, planes, self.name)
        depth = _take(path, planes, ["depth.Z"], "depth", self.name, False)
        vel = _take(path, planes, ["forward.u", "forward.v"], "velocity", self.name, False)
        note = "forward"
        if vel is None:
            vel = _take(path, planes, ["backward.u", "backward.v"], "velocity", self.name, False)
            note = "backward"
        return Mapped(color, alpha, _one(depth), _pair(vel), note)

    def parts(self, rgb, alpha, depth, vel, focal_px):
        ch = dict(rgb)
        if alpha is not None:
            ch["A"] = alpha
        if depth is not None:
            ch["depth.Z"] = np.where(np.isinf(depth), 0, np.float32(1) / depth).astype(np.float32)
        if vel is not None:
            ch["forward.u"], ch["forward.v"] = vel[0], -vel[1]
        return [("", ch)]


class ArnoldLayout(Layout):
    """``R, G, B, (A)``, ``Z`` radial (assumed), ``motionvector.R/G`` (or ``.X/Y``) y up (assumed)."""

    name = "arnold"
    depth_kind = "radial"
    velocity_y_up = True

    def matches(self, names):
        return {"R", "G", "B"} <= names and any(n.startswith("motionvector.") for n in names)

    def map_channels(self, path, planes):
        color, alpha = _rgb_alpha(path, planes, self.name)
        depth = _take(path, planes, ["Z"], "depth", self.name, False)
        xy = ("X", "Y") if "motionvector.X" in planes else ("R", "G")
        vel = _take(path, planes, [f"motionvector.{c}" for c in xy], "velocity", self.name, False)
        return Mapped(color, alpha, _one(depth), _pair(vel), "forward")

    def parts(self, rgb, alpha, depth, vel, focal_px):
        ch = dict(rgb)
        if alpha is not None:
            ch["A"] = alpha
        if depth is not None:
            ch["Z"] = (planar_to_radial(depth, focal_px) if focal_px is not None
                       else np.ascontiguousarray(depth, dtype=np.float32))
        if vel is not None:
            ch["motionvector.R"], ch["motionvector.G"] = vel[0], -vel[1]
            ch["motionvector.B"] = np.zeros_like(vel[0])
        return [("", ch)]


REGISTRY: dict[str, Layout] = {lay.name: lay for lay in
                               (ClpostLayout(), BlenderLayout(), NukeLayout(), ArnoldLayout())}
LAYOUTS = tuple(REGISTRY)
_DETECT_ORDER = ("blender", "arnold", "nuke", "clpost")


def get_layout(path: Path | str, layout: str) -> Layout:
    """The :class:`Layout` named ``layout``; InputError naming the known ones otherwise."""
    try:
        return REGISTRY[layout]
    except (KeyError, TypeError):
        raise InputError(f"{path}: layout {layout!r} is unknown; use one of {', '.join(LAYOUTS)}") from None


def detect_layout(channel_names: Iterable[str]) -> str:
    """The layout (one of :data:`LAYOUTS`) that channel names (of all parts) were written in.

    Rules, first match wins: ``<layer>.Combined.R/G/B`` → blender; ``R, G, B`` with
    ``motionvector.*`` → arnold; ``R, G, B`` with ``depth.Z``, ``forward.*`` or ``backward.*``
    → nuke; ``R, G, B`` → clpost. An Arnold file without a motion vector AOV looks exactly
    like a clpost one (``R, G, B, Z``): pass the layout explicitly for those.
    """
    names = set(channel_names)
    for name in _DETECT_ORDER:
        if REGISTRY[name].matches(names):
            return name
    raise InputError(
        f"no known channel layout in channels [{names_preview(names)}]; clpost needs color as "
        "R, G, B (clpost/nuke/arnold) or <ViewLayer>.Combined.R/G/B (blender) — rename the "
        f"channels or pass the layout explicitly, one of {', '.join(LAYOUTS)}"
    )
