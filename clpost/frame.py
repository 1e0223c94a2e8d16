"""The buffers of one rendered frame, validated once at the boundary.

Conventions (``docs/conventions.md``): arrays are C-contiguous ``(H, W, C)`` with row 0 at
the top; pixel centre of column i, row j at (x, y) = (i, j).

============  ==========  ====================================================================
buffer        shape       unit / meaning
============  ==========  ====================================================================
``color``     H×W×3       scene-referred linear RGB; Y = 1 is ``Camera.luminance_scale`` cd/m² (else: the signal)
``depth``     H×W         planar camera-space Z in metres, > 0, ``+inf`` for sky (optional)
``velocity``  H×W×2       forward screen-space motion, px per frame, +x right, +y down (optional)
``alpha``     H×W         coverage in [0, 1]; 0 marks "no data" (optional)
``labels``    H×W each    named label planes — instance/object ids, segmentation, normals, any AOV —
                          that follow the geometry but are never blended (optional, see below)
``front``     H×W×5       a second layer in front of the image: premultiplied linear R, G, B, its
                          coverage α in [0, 1], its planar depth in metres (> 0, ``+inf`` allowed
                          where α = 0); :func:`front_layer` packs it (optional, see below)
============  ==========  ====================================================================

``labels`` maps a channel name (the EXR's full name, e.g. ``ViewLayer.IndexOB.X``, ``id``,
``N.X``) to an (H, W) plane. A plane keeps its type if it is float32, int32 or uint32 (float16/64
become float32, smaller integers int32/uint32 — exact), so ids survive bit for bit; a float plane
must not hold NaN. The geometric stages move labels with the pixels by **nearest** sampling
(:mod:`clpost.labels.channels`): an output label is always one of its source's values.

A 4-channel ``color`` is split into ``color`` and ``alpha``. float16/32/64 input is converted
once to float32 (explicitly, here); any other dtype is refused rather than silently cast. A
Frame never keeps the caller's arrays: float32 input is copied, so writing into the caller's
array afterwards cannot slip unvalidated values (NaN) into the frame.
NaN is never valid; ±inf only as ``+inf`` in depth.

``front`` is what a renderer gives when the foreground is rendered as its own layer (a view layer
or render pass of the near objects over a transparent film, the rest hidden from the camera
or held out): the image (``color``, ``depth``) is then the background without them. The
``front_layer`` stage defocuses it by its own depth and composites it over the background
after depth of field, so the lens sees the background behind a blurred foreground's edge,
which a one-layer image does not hold (docs/fidelity.md, "Two layers: the foreground rendered
as its own layer"). The
stage consumes it: a processed frame has no ``front``.

``metadata["frame_index"]`` (int, default 0) is the frame number of a sequence; the renderer and
the batch loop set it, and the grain and sensor stages hash it into their noise.

``metadata["windows"]`` (a :class:`Windows`, set by the EXR reader) places the arrays in the
file's pixel space: the **display window** is the image (the format a compositor calls it, the
camera's sensor), the **data window** where the file has pixels — larger than the display window
for overscan, smaller for a crop, anywhere for the odd file. The arrays cover the bounding box of
both (:attr:`Frame.windows`); pixels outside the data window are "no data" (alpha 0). Without it
(or after a stage that resamples to another size), data and display are the whole array.
"""
from __future__ import annotations

from dataclasses import InitVar, dataclass, field
from typing import Any

import numpy as np

from .errors import InputError

_FLOAT_DTYPES = (np.float16, np.float32, np.float64)

Window = tuple[tuple[int, int], tuple[int, int]]
"""((x_min, y_min), (x_max, y_max)), inclusive, in the file's pixel space (OpenEXR's box2i)."""


def bbox(*windows: Window) -> Window:
    """The smallest window holding all of ``windows``."""
    return ((min(w[0][0] for w in windows), min(w[0][1] for w in windows)),
            (max(w[1][0] for w in windows), max(w[1][1] for w in windows)))


def window_size(w: Window) -> tuple[int, int]:
    """(width, height) of a window."""
    return w[1][0] - w[0][0] + 1, w[1][1] - w[0][1] + 1


@dataclass(frozen=True)
class Windows:
    """Where a frame's arrays lie in its file's pixel space (see the module docstring): array
    pixel (0, 0) is at ``origin``; the arrays span ``bbox(data, display)``."""

    data: Window
    display: Window

    @property
    def extent(self) -> Window:
        """The window the arrays cover: the bounding box of the data and display windows."""
        return bbox(self.data, self.display)

    @property
    def origin(self) -> tuple[int, int]:
        return self.extent[0]

    @property
    def display_size(self) -> tuple[int, int]:
        """(width, height) of the display window: the image a camera made."""
        return window_size(self.display)

    @property
    def display_offset(self) -> tuple[int, int]:
        """Array column and row of the display window's top-left pixel."""
        return self.display[0][0] - self.origin[0], self.display[0][1] - self.origin[1]

    @property
    def overscan(self) -> tuple[int, int, int, int]:
        """Pixels of data beyond the display window on each side (left, top, right, bottom), ≥ 0."""
        (dx0, dy0), (dx1, dy1) = self.data
        (ox0, oy0), (ox1, oy1) = self.display
        return max(ox0 - dx0, 0), max(oy0 - dy0, 0), max(dx1 - ox1, 0), max(dy1 - oy1, 0)

    @staticmethod
    def full(width: int, height: int) -> "Windows":
        """Data = display = the whole ``width`` × ``height`` array at (0, 0)."""
        w = ((0, 0), (int(width) - 1, int(height) - 1))
        return Windows(w, w)


def _as_float32(name: str, a: Any, copy: bool = True) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype.type not in _FLOAT_DTYPES:
        raise InputError(
            f"Frame.{name}: dtype {a.dtype} is not a float type; clpost takes linear float data "
            f"(float16/32/64) — convert integer images to linear float yourself, e.g. decode sRGB first"
        )
    out = np.ascontiguousarray(a, dtype=np.float32)
    if copy and np.may_share_memory(out, a):
        # Keep our own copy: a later write into the caller's array must not bypass validation.
        out = out.copy()
    return out


_LABEL_DTYPES = {"f": np.float32, "i": np.int32, "u": np.uint32}


def _label_plane(name: str, a: Any, shape: tuple[int, int], copy: bool) -> np.ndarray:
    """A label plane as a 4-byte type (see the module docstring), validated."""
    a = np.asarray(a)
    kind = a.dtype.kind
    if kind == "b":
        a, kind = a.astype(np.uint32), "u"
    if kind not in _LABEL_DTYPES or a.dtype.itemsize > 8:
        raise InputError(f"Frame.labels[{name!r}]: dtype {a.dtype} is not a number type; give ids as integers "
                         "or floats")
    if kind in "iu" and a.size and a.dtype.itemsize == 8:
        lo, hi = np.iinfo(_LABEL_DTYPES[kind]).min, np.iinfo(_LABEL_DTYPES[kind]).max
        if a.min() < lo or a.max() > hi:
            raise InputError(f"Frame.labels[{name!r}]: values outside {np.dtype(_LABEL_DTYPES[kind]).name}; "
                             "labels are kept as 32-bit values — renumber the ids")
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.shape != shape:
        raise InputError(f"Frame.labels[{name!r}]: shape {a.shape} does not match color {shape}; give one "
                         "(H, W) plane per channel (e.g. N.X, N.Y, N.Z for normals)")
    out = np.ascontiguousarray(a, dtype=_LABEL_DTYPES[kind])
    if copy and np.may_share_memory(out, a):
        out = out.copy()
    if kind == "f":
        _first_bad(f"labels[{name!r}]", np.isnan(out), "are NaN", "labels are ids or finite values, never NaN")
    return out


def _first_bad(name: str, bad: np.ndarray, what: str, fix: str) -> None:
    n = int(np.count_nonzero(bad))
    if n:
        idx = np.unravel_index(int(np.argmax(bad.reshape(-1))), bad.shape)
        y, x = int(idx[0]), int(idx[1])
        raise InputError(
            f"Frame.{name}: {n} pixel(s) {what}, first at (x={x}, y={y}); {fix}"
        )


@dataclass(frozen=True, eq=False)
class Frame:
    """One frame's buffers. See the module docstring for units and conventions."""

    color: np.ndarray
    depth: np.ndarray | None = None
    velocity: np.ndarray | None = None
    alpha: np.ndarray | None = None
    metadata: dict = field(default_factory=dict)
    labels: dict = field(default_factory=dict)
    """Named (H, W) label planes (module docstring); carried through the geometric stages by
    nearest sampling."""
    front: np.ndarray | None = None
    """The layer in front of the image, H×W×5 (module docstring; :func:`front_layer`)."""
    copy: InitVar[bool] = True
    """``False``: the Frame takes the caller's float32 arrays over instead of copying them (a
    reader's fresh buffers); the caller must not write them afterwards."""

    def __post_init__(self, copy: bool = True) -> None:
        color = _as_float32("color", self.color, copy)
        if color.ndim != 3 or color.shape[2] not in (3, 4):
            raise InputError(
                f"Frame.color: shape {color.shape} is not (H, W, 3) or (H, W, 4); "
                "pass channels last, row 0 at the top"
            )
        alpha = self.alpha
        if color.shape[2] == 4:
            if alpha is not None:
                raise InputError("Frame.color has 4 channels and alpha was also given; pass one of them")
            alpha = color[:, :, 3]
            color = np.ascontiguousarray(color[:, :, :3])
        h, w = color.shape[:2]
        if h < 1 or w < 1:
            raise InputError(f"Frame.color: empty image of shape {color.shape}")
        # one fast scan of the whole buffer; the per-pixel search (a slow reduction over the channel
        # axis) only to name the first bad pixel — a reader's frame is validated every frame
        if not np.isfinite(color).all():
            _first_bad("color", np.isnan(color).any(axis=2), "are NaN", "fix the renderer output (NaN is never valid)")
            _first_bad("color", np.isinf(color).any(axis=2), "are ±inf", "clamp color to finite values")
        object.__setattr__(self, "color", color)

        if self.depth is not None:
            depth = _as_float32("depth", self.depth, copy)
            if depth.ndim == 3 and depth.shape[2] == 1:
                depth = np.ascontiguousarray(depth[:, :, 0])
            if depth.shape != (h, w):
                raise InputError(f"Frame.depth: shape {depth.shape} does not match color {(h, w)}; give H×W planar depth")
            if not (depth > 0).all():  # NaN, <= 0 and -inf all fail `> 0`
                _first_bad("depth", np.isnan(depth), "are NaN", "use +inf for background, never NaN")
                _first_bad("depth", ~(depth > 0), "are <= 0 or -inf",
                           "depth is planar camera-space Z in metres (> 0); convert negative eye-space z or NDC depth first")
            object.__setattr__(self, "depth", depth)
            self.depth_range  # noqa: B018 — computed with the validation scans, not per plan run

        if self.velocity is not None:
            vel = _as_float32("velocity", self.velocity, copy)
            if vel.shape != (h, w, 2):
                raise InputError(f"Frame.velocity: shape {vel.shape} is not (H, W, 2) = {(h, w, 2)}")
            if not np.isfinite(vel).all():
                _first_bad("velocity", np.isnan(vel).any(axis=2), "are NaN", "fix the renderer's vector pass")
                _first_bad("velocity", np.isinf(vel).any(axis=2), "are ±inf", "clamp velocity to finite pixels per frame")
            object.__setattr__(self, "velocity", vel)
            self.velocity_max  # noqa: B018 — with the validation scans, not per plan run

        if alpha is not None:
            a = _as_float32("alpha", alpha, copy)
            if a.shape != (h, w):
                raise InputError(f"Frame.alpha: shape {a.shape} does not match color {(h, w)}")
            _first_bad("alpha", np.isnan(a), "are NaN", "alpha is coverage in [0, 1]")
            _first_bad("alpha", (a < 0) | (a > 1), "are outside [0, 1]", "alpha is coverage in [0, 1]; clip it")
            object.__setattr__(self, "alpha", np.ascontiguousarray(a))

        if self.front is not None:
            object.__setattr__(self, "front", _front_plane(self.front, (h, w), copy))

        labels = {} if self.labels is None else self.labels
        if not isinstance(labels, dict):
            raise InputError(f"Frame.labels must be a dict of name → (H, W) plane, not {type(labels).__name__}")
        object.__setattr__(self, "labels", {str(k): _label_plane(str(k), v, (h, w), copy) for k, v in labels.items()})

    @property
    def index(self) -> int:
        """The frame counter of the noise hash (CONVENTIONS "Randomness"):
        ``metadata["frame_index"]`` as an unsigned 32-bit integer, 0 when absent or not a number."""
        try:
            return int(self.metadata.get("frame_index", 0)) & 0xFFFFFFFF
        except (TypeError, ValueError):
            return 0

    @property
    def depth_range(self) -> tuple[float, float, bool] | None:
        """(nearest depth, farthest finite depth, any +inf) in metres, or None without depth; the
        farthest is ``inf`` when every pixel is sky. Computed once per depth buffer (the dof
        stage's skip rule reads it every frame)."""
        if self.depth is None:
            return None
        cached = self.__dict__.get("_depth_range")
        if cached is not None and cached[0] is self.depth:
            return cached[1]
        d = self.depth
        finite = np.isfinite(d)
        far = float(d.max(where=finite, initial=0.0)) if finite.any() else float("inf")
        rng = (float(d.min()), far, not bool(finite.all()))
        object.__setattr__(self, "_depth_range", (d, rng))
        return rng

    @property
    def velocity_max(self) -> float | None:
        """The largest |component| of the velocity buffer in px/frame (the inf-norm), or None
        without velocity. Computed once per velocity buffer (motion blur's skip rule)."""
        if self.velocity is None:
            return None
        cached = self.__dict__.get("_velocity_max")
        if cached is not None and cached[0] is self.velocity:
            return cached[1]
        vel = self.velocity
        # max |v| as max(max v, −min v): two reductions, no |v| copy of the buffer (NaN propagates)
        v = float(np.maximum(vel.max(), -vel.min())) if vel.size else 0.0
        object.__setattr__(self, "_velocity_max", (self.velocity, v))
        return v

    @property
    def windows(self) -> Windows:
        """The frame's data and display windows (``metadata["windows"]`` when it describes these
        arrays, else data = display = the whole array)."""
        w = self.metadata.get("windows") if isinstance(self.metadata, dict) else None
        if isinstance(w, Windows) and window_size(w.extent) == self.size:
            return w
        return Windows.full(self.width, self.height)

    @property
    def height(self) -> int:
        return int(self.color.shape[0])

    @property
    def width(self) -> int:
        return int(self.color.shape[1])

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return self.width, self.height

    def replace(self, *, validate: bool = True, **changes: Any) -> "Frame":
        """A new Frame with some buffers replaced.

        ``validate=False`` is for clpost's own stage outputs (float32, right shapes, finite by
        construction — each stage's tests check that): it skips the full-frame scans, which would
        otherwise cost more than an exposure pass.
        """
        kw = dict(color=self.color, depth=self.depth, velocity=self.velocity,
                  alpha=self.alpha, metadata=dict(self.metadata), labels=dict(self.labels), front=self.front)
        kw.update(changes)
        if validate:
            return Frame(**kw)
        out = object.__new__(Frame)
        for k, v in kw.items():
            object.__setattr__(out, k, v)
        return out

    def with_front(self, front: np.ndarray | None, copy: bool = True) -> "Frame":
        """A new Frame with ``front`` (H×W×5, :func:`front_layer`) validated and the other buffers as
        they are (already validated: no second scan of them); ``copy=False`` takes a fresh float32
        ``front`` over, as the constructor's ``copy``."""
        if front is not None:
            front = _front_plane(front, (self.height, self.width), copy)
        return self.replace(validate=False, front=front)


def front_layer(color: np.ndarray, alpha: np.ndarray, depth: np.ndarray, premultiplied: bool = True) -> np.ndarray:
    """The H×W×5 ``Frame.front`` array of a layer: ``color`` (H×W×3 linear RGB, premultiplied by
    ``alpha`` unless ``premultiplied=False``), ``alpha`` (H×W coverage) and ``depth`` (H×W planar
    metres; any value > 0 or ``+inf`` where alpha is 0). A partly covered pixel takes the nearest
    depth of its own and its covered neighbours' (the depth pass's one sample may have missed the
    layer there: :func:`_fill_missed`)."""
    color = np.asarray(color, np.float32)[..., :3]
    a = np.asarray(alpha, np.float32)
    if color.shape[:2] != a.shape or np.shape(depth) != a.shape:
        raise InputError(f"front_layer: color {color.shape}, alpha {a.shape} and depth {np.shape(depth)} "
                         "must share one H×W")
    if not premultiplied:
        color = color * a[..., None]
    return np.concatenate([color, a[..., None], _fill_missed(np.asarray(depth, np.float32), a)[..., None]],
                          axis=-1)


def front_of(layer: "Frame", name: str) -> np.ndarray:
    """The ``Frame.front`` array of a front layer read from a file (``name`` says which in an
    error: a path, ``--front PATH``): its colour taken as premultiplied (the EXR convention, what
    a transparent film writes), its alpha and depth required. A reader's alpha made up for a
    cropped data window (``metadata["alpha_channel"]`` False) is no coverage."""
    layout = layer.metadata.get("layout")
    if layer.alpha is None or not layer.metadata.get("alpha_channel", True):
        raise InputError(f"{name}: no alpha channel ({layout} layout); the front layer's coverage is its alpha: "
                         "render it over a transparent film (Blender: Film > Transparent) and write RGBA")
    if layer.depth is None:
        raise InputError(f"{name}: no depth channel ({layout} layout); the front layer is defocused by its own "
                         "depth: render it with a depth pass (Blender: Passes > Z)")
    return front_layer(layer.color, layer.alpha, layer.depth)


def _fill_missed(depth: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """A renderer's depth pass is one sample per pixel (Cycles: the first), so a pixel the layer
    covers only in part may record what lies behind the layer: no hit (+inf; a reader maps
    Blender's 1e10 to it), or a held-out or background surface where the renderer writes one.
    Such a pixel (0 < α < 1) takes the nearest depth of its own and its covered 3×3 neighbours';
    one with +inf and no covered neighbour with a depth takes it once one has, repeated until
    every covered pixel has one (a layer with no finite depth at all stays at +inf)."""
    covered = alpha > 0

    def nearest(d):  # the 3×3 minimum, separable (rows, then columns)
        p = np.pad(d, 1, constant_values=np.inf)
        m = np.minimum(np.minimum(p[:-2], p[1:-1]), p[2:])
        return np.minimum(np.minimum(m[:, :-2], m[:, 1:-1]), m[:, 2:])

    d = np.where(covered, depth, np.inf).astype(np.float32)
    d = np.where(covered & (alpha < 1), nearest(d), d)
    todo = covered & np.isinf(d)
    while todo.any():
        d = np.where(todo, nearest(d), d)
        left = covered & np.isinf(d)
        if left.sum() == todo.sum():
            break
        todo = left
    return np.where(covered, d, depth).astype(np.float32)


def _front_plane(front, hw: tuple[int, int], copy: bool) -> np.ndarray:
    f = _as_float32("front", front, copy)
    if f.shape != (*hw, 5):
        raise InputError(f"Frame.front: shape {f.shape} is not (H, W, 5) = {(*hw, 5)}: premultiplied R, G, B, "
                         "alpha, depth (clpost.frame.front_layer packs them)")
    rgba, depth = f[..., :4], f[..., 4]
    if not np.isfinite(rgba).all():
        _first_bad("front", ~np.isfinite(rgba).all(axis=2), "have a non-finite colour or alpha",
                   "fix the front layer's render (NaN and inf are never valid)")
    _first_bad("front", (f[..., 3] < 0) | (f[..., 3] > 1), "have alpha outside [0, 1]",
               "alpha is the front layer's coverage in [0, 1]; clip it")
    _first_bad("front", ~(depth > 0), "have depth NaN, <= 0 or -inf",
               "the front layer's depth is planar camera-space Z in metres (> 0, +inf where alpha is 0)")
    return np.ascontiguousarray(f)
