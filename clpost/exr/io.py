"""Reading and writing EXR files; the channel conventions are the :mod:`~clpost.exr.layouts`' job.

Before OpenEXR reads a pixel, :func:`read_header` parses the headers of every part itself
(OpenEXR file layout: magic, version flags, ``name\\0 type\\0 size value`` attributes, an empty
name ending each header, an empty header ending a multi-part list) and :func:`check_header`
refuses sizes that cannot be a frame we can hold: window sides, channel counts, and the bytes
the read would allocate against the memory this process may use. A damaged or hostile header is
one :class:`~clpost.errors.InputError` line, never an allocation of gigabytes. OpenEXR's own
messages (stdout and stderr) are swallowed during the read; the error we raise says what happened.

Reference: OpenEXR file layout, https://openexr.com/en/latest/OpenEXRFileLayout.html
"""
from __future__ import annotations

import contextlib
import math
import os
import resource
import struct
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np
import OpenEXR

from ..atomic import atomic_path
from ..errors import InputError, OutputError
from ..frame import Frame, Window, Windows, bbox, window_size
from . import deep, yca
from .layouts import (DEPTH_KINDS, DepthConventionWarning, depth_to_planar,
                      detect_layout, get_layout)

_HALF_MAX = float(np.finfo(np.float16).max)
# Attributes OpenEXR manages itself; a user header must not override them.
_RESERVED_ATTRS = frozenset({
    "channels", "compression", "dataWindow", "displayWindow", "lineOrder", "pixelAspectRatio",
    "screenWindowCenter", "screenWindowWidth", "type", "name", "tiles", "chunkCount", "version",
})

MAGIC = b"\x76\x2f\x31\x01"
MAX_SIDE = 1 << 17
"""Largest window side read (131072 px; 16K renders are 15360 wide)."""
MAX_PIXELS = 1 << 30
"""Largest window area read (32768², 1.07 Gpx), whatever the memory."""
MAX_CHANNELS = 1024
"""Channels per part (Blender's busiest multilayer files have a few hundred)."""
MAX_PARTS = 1024
_PIXEL_BYTES = {0: 4, 1: 2, 2: 4}  # UINT, HALF, FLOAT
_FRAME_BYTES_PER_PX = 4 * 8
"""What a read allocates per display pixel besides the file's planes: float32 color (3), alpha,
depth, velocity (2) and one temporary plane."""
_FLAG_LONG_NAMES, _FLAG_MULTIPART = 0x400, 0x1000

CAMERA_ATTRIBUTES = {
    "focus": "m", "aperture": "f-number", "expTime": "s", "isoSpeed": "ISO", "nominalFocalLength": "mm",
    "tStop": "T-number", "shutterAngle": "degrees", "captureRate": "frames per second",
}
"""The OpenEXR standard attributes that describe the camera (ImfStandardAttributes.h; captureRate
is a rational, the others floats), read as floats into ``Frame.metadata["attributes"]`` and by
:func:`read_attributes`; their mapping to camera parameters is :mod:`clpost.camera_sources`."""


# ----------------------------------------------------------------------------------------------
# Headers, parsed and checked before OpenEXR allocates anything
# ----------------------------------------------------------------------------------------------

@dataclass
class PartHeader:
    """What :func:`check_header` needs of one part's header."""

    channels: dict[str, int] = field(default_factory=dict)
    """channel name → pixel type (0 uint, 1 half, 2 float)."""
    sampling: dict[str, tuple[int, int]] = field(default_factory=dict)
    """channel name → (x, y) sampling."""
    data_window: Window | None = None
    display_window: Window | None = None
    type: str = ""
    attributes: dict[str, float] = field(default_factory=dict)
    """The :data:`CAMERA_ATTRIBUTES` present, as floats."""
    strings: dict[str, str] = field(default_factory=dict)
    """Every string attribute (e.g. the ``clpost.*`` keys a camera wrote)."""


class _NeedMore(Exception):
    """The header goes on past the bytes read so far (the file has more)."""


class _Reader:
    def __init__(self, data: bytes, path: Path, complete: bool = True):
        self.b, self.i, self.path, self.complete = data, 0, path, complete

    def corrupt(self, what: str) -> Exception:
        if not self.complete:
            return _NeedMore()
        return InputError(f"{self.path}: EXR header is damaged ({what} at byte {self.i}); the file is corrupt "
                          "or truncated — re-render or re-copy it")

    def take(self, n: int) -> bytes:
        if n < 0 or self.i + n > len(self.b):
            raise self.corrupt("ends early")
        out = self.b[self.i:self.i + n]
        self.i += n
        return out

    def name(self, limit: int) -> str:
        end = self.b.find(b"\0", self.i, self.i + limit + 1)
        if end < 0:
            raise self.corrupt("a name without its terminator")
        out = self.b[self.i:end]
        self.i = end + 1
        return out.decode("latin-1")

    def int32(self) -> int:
        return struct.unpack("<i", self.take(4))[0]


def _box(r: _Reader, size: int) -> Window:
    if size != 16:
        raise r.corrupt(f"a box2i of {size} bytes")
    x0, y0, x1, y1 = struct.unpack("<4i", r.take(16))
    return (x0, y0), (x1, y1)


def _chlist(r: _Reader, size: int, limit: int, sampling: dict[str, tuple[int, int]]) -> dict[str, int]:
    end = r.i + size
    out: dict[str, int] = {}
    while True:
        name = r.name(limit)
        if not name:
            break
        ptype, _, xs, ys = struct.unpack("<iB3xii", r.take(16))
        if ptype not in _PIXEL_BYTES:
            raise r.corrupt(f"channel {name!r} of unknown pixel type {ptype}")
        if len(out) >= MAX_CHANNELS:
            raise InputError(f"{r.path}: a part declares more than {MAX_CHANNELS} channels; the file is "
                             "corrupt or not a rendered frame — re-render or re-copy it")
        out[name] = ptype
        sampling[name] = (xs, ys)
    if r.i != end:
        raise r.corrupt("a channel list of the wrong size")
    return out


def read_header(path: str | os.PathLike, max_bytes: int = 64 << 20) -> list[PartHeader]:
    """The headers of all parts of ``path`` (only the fields :func:`check_header` uses); reads
    64 KiB, more only while the headers go on (at most ``max_bytes``)."""
    p = Path(path)
    n = 1 << 16
    with open(p, "rb") as f:
        data = f.read(n)
        while True:
            complete = len(data) < n or n >= max_bytes
            try:
                return _parse_headers(_Reader(data, p, complete))
            except _NeedMore:
                n *= 4
                f.seek(0)
                data = f.read(min(n, max_bytes))


def _parse_headers(r: _Reader) -> list[PartHeader]:
    p, data = r.path, r.b
    if data[:4] != MAGIC:
        raise InputError(f"{p}: not an OpenEXR file (bad magic number); clpost reads .exr images only")
    r.i = 4
    flags = r.int32()
    limit = 255 if flags & _FLAG_LONG_NAMES else 31
    multipart = bool(flags & _FLAG_MULTIPART)
    parts = []
    while True:
        ph = PartHeader()
        while True:
            name = r.name(limit)
            if not name:
                break
            typ = r.name(limit)
            size = r.int32()
            if size < 0 or r.i + size > len(data):
                raise r.corrupt(f"attribute {name!r} of {size} bytes")
            if typ == "box2i" and name in ("dataWindow", "displayWindow"):
                setattr(ph, "data_window" if name == "dataWindow" else "display_window", _box(r, size))
            elif typ == "chlist" and name == "channels":
                ph.channels = _chlist(r, size, limit, ph.sampling)
            elif typ == "string":
                text = r.take(size).decode("utf-8", "replace")
                if name == "type":
                    ph.type = text
                ph.strings[name] = text
            elif name in CAMERA_ATTRIBUTES and (typ, size) in _NUMERIC_ATTRS:
                ph.attributes[name] = _NUMERIC_ATTRS[typ, size](r.take(size))
            else:
                r.take(size)
        parts.append(ph)
        if not multipart or len(parts) >= MAX_PARTS:
            break
        if r.b[r.i:r.i + 1] == b"\0":  # the empty header ending the list
            break
    return parts


def _f32(v: float) -> float:
    """A float32 attribute as the shortest decimal that rounds to it (2.8, not 2.7999999523)."""
    # format_float_scientific(unique=True) is the shortest round-trip text whatever numpy's
    # print options (str(np.float32) follows them)
    return float(np.format_float_scientific(np.float32(v), unique=True))


_NUMERIC_ATTRS = {
    ("float", 4): lambda b: _f32(struct.unpack("<f", b)[0]),
    ("double", 8): lambda b: float(struct.unpack("<d", b)[0]),
    ("rational", 8): lambda b: (lambda n, d: n / d if d else float("nan"))(*struct.unpack("<iI", b)),
}


def read_attributes(path: str | os.PathLike) -> tuple[dict[str, float], dict[str, str]]:
    """The camera's standard attributes (:data:`CAMERA_ATTRIBUTES`, floats) and the string
    attributes of the first part of ``path``, from the header alone (no pixels are read)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such file; check the path")
    try:
        first = read_header(p)[0]
    except OSError as e:
        raise InputError(f"{p}: cannot read ({e.strerror}); check the file's permissions") from None
    return dict(first.attributes), dict(first.strings)


def display_size(path: str | os.PathLike) -> tuple[int, int]:
    """(width, height) of the display window of ``path``'s first part, from the checked header
    alone (no pixels are read): the size :func:`read_frame`'s frame will have."""
    return _side(_checked_headers(Path(path))[0].display_window)  # type: ignore[arg-type]


def _camera_attrs(header: dict) -> dict[str, float]:
    """:data:`CAMERA_ATTRIBUTES` of an OpenEXR binding header as floats (a rational as n/d)."""
    out = {}
    for k in CAMERA_ATTRIBUTES:
        v = header.get(k)
        if hasattr(v, "n") and hasattr(v, "d"):
            v = v.n / v.d if v.d else float("nan")
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            out[k] = float(v) if k == "captureRate" else _f32(v)
    return out


def _limit_bytes() -> int:
    """Bytes this process may still allocate: available memory, and the address-space limit."""
    avail = None
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
    if avail is None:
        with contextlib.suppress(ValueError, OSError, AttributeError):
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    room = None
    if soft != resource.RLIM_INFINITY:
        used = 0
        with contextlib.suppress(OSError, ValueError, IndexError):
            with open("/proc/self/status") as f:
                used = next(int(ln.split()[1]) * 1024 for ln in f if ln.startswith("VmSize:"))
        room = max(soft - used, 1)
    limits = [x for x in (avail, room) if x]
    return min(limits) if limits else 1 << 40


def _side(w: Window) -> tuple[int, int]:
    (x0, y0), (x1, y1) = w
    return x1 - x0 + 1, y1 - y0 + 1


def check_header(path: Path, parts: Sequence[PartHeader]) -> None:
    """InputError (one line, naming the file and the size) unless every part's windows and
    channels are sane and the read fits in the memory this process may use."""
    total = 0
    for i, ph in enumerate(parts):
        label = f"part {i}"
        if ph.data_window is None or ph.display_window is None or not ph.channels:
            missing = [n for n, v in (("dataWindow", ph.data_window), ("displayWindow", ph.display_window),
                                      ("channels", ph.channels)) if not v]
            raise InputError(f"{path}: EXR header of {label} lacks {', '.join(missing)}; the file is corrupt "
                             "or truncated — re-render or re-copy it")
        for what, win in (("data", ph.data_window), ("display", ph.display_window)):
            w, h = _side(win)
            if not (1 <= w <= MAX_SIDE and 1 <= h <= MAX_SIDE):
                raise InputError(f"{path}: {label} declares a {w}x{h} {what} window; clpost reads windows "
                                 f"of 1 to {MAX_SIDE} px a side — the file is corrupt or not a frame, "
                                 "re-render or re-copy it")
        dw, dh = _side(ph.data_window)
        ow, oh = _side(ph.display_window)
        total += dw * dh * sum(_PIXEL_BYTES[t] for t in ph.channels.values())
        total += ow * oh * _FRAME_BYTES_PER_PX if i == 0 else 0
    ow, oh = _side(parts[0].display_window)  # type: ignore[arg-type]
    dw, dh = _side(parts[0].data_window)  # type: ignore[arg-type]
    limit = _limit_bytes()
    if total > limit or max(ow * oh, dw * dh) > MAX_PIXELS:
        why = (f"clpost's limit of {MAX_PIXELS} pixels a frame" if max(ow * oh, dw * dh) > MAX_PIXELS
               else f"the {limit / 2**30:.1f} GiB available")
        raise InputError(f"{path}: reading it needs {total / 2**30:.1f} GiB ({ow}x{oh} display window, "
                         f"{dw}x{dh} data window, {sum(len(p.channels) for p in parts)} channel(s)), more than "
                         f"{why}; the header is corrupt — re-render or re-copy it — or, for a real frame this "
                         "big, free memory or crop it first")


@contextlib.contextmanager
def quiet_openexr() -> Iterator[None]:
    """Send file descriptors 1 and 2 to /dev/null meanwhile: OpenEXR prints its own diagnostics
    on damaged files (the Python bindings' warnings to stdout, the library's to stderr), and the
    caller reports the error as one line of its own."""
    saved = []
    try:
        for stream, fd in ((sys.stdout, 1), (sys.stderr, 2)):
            with contextlib.suppress(AttributeError, ValueError, OSError):
                stream.flush()
            saved.append((fd, os.dup(fd)))
    except OSError:
        for _, dup in saved:
            os.close(dup)
        yield
        return
    try:
        with open(os.devnull, "wb") as null:
            for fd, _ in saved:
                os.dup2(null.fileno(), fd)
        yield
    finally:
        for fd, dup in saved:
            os.dup2(dup, fd)
            os.close(dup)


# ----------------------------------------------------------------------------------------------
# Reading
# ----------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Part:
    """One part of a file as read: its channels already as numpy planes of the data window
    (subsampled chroma at its own resolution; a deep part's planes as per-pixel sample arrays
    until :func:`_flat`)."""

    index: int
    name: str
    header: dict
    planes: dict[str, np.ndarray]
    types: dict[str, str]
    data_window: Window
    display_window: Window
    deep: bool = False


@dataclass(frozen=True)
class ReadSpec:
    """How to read a file where a plain layout name is not enough: the ``layout`` (None: detect)
    and the ``view`` of a multi-view file (None: its default view). Accepted wherever a layout
    name is (``read_frame(path, ReadSpec(...))``, the batch functions' ``layout``)."""

    layout: str | None = None
    view: str | None = None


def _window(header: dict, key: str) -> Window:
    lo, hi = header[key]
    return (int(lo[0]), int(lo[1])), (int(hi[0]), int(hi[1]))


def window_str(w: Window) -> str:
    (x0, y0), (x1, y1) = w
    return f"({x0},{y0})-({x1},{y1})"


def _checked_headers(p: Path) -> list:
    """``p``'s part headers, checked (:func:`check_header`); InputError naming the fix for a path
    that is missing, a directory or unreadable."""
    if not p.exists():
        raise InputError(f"{p}: no such file; check the path (and the frame number of a sequence)")
    if p.is_dir():
        raise InputError(f"{p}: is a directory, not an EXR file; give the path of an .exr image or a "
                         "frame pattern such as dir/render.####.exr")
    if not p.is_file():
        raise InputError(f"{p}: is not a file; give the path of an .exr image")
    try:
        headers = read_header(p)
    except OSError as e:
        raise InputError(f"{p}: cannot read ({e.strerror}); check the file's permissions") from None
    check_header(p, headers)
    return headers


def _load(path: str | os.PathLike) -> list[_Part]:
    """All parts of ``path`` with their pixel planes; InputError for anything unreadable."""
    p = Path(path)
    headers = _checked_headers(p)
    try:
        with quiet_openexr():
            f = OpenEXR.File(str(p), separate_channels=not _can_interleave(headers))
            raw_parts = list(f.parts)
    except MemoryError:
        raise InputError(f"{p}: out of memory reading it; the file is corrupt, or free memory first") from None
    except Exception as e:  # the bindings raise RuntimeError/ValueError for damaged files
        reason = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise InputError(f"{p}: cannot read EXR ({reason}); the file is corrupt or truncated — re-render or "
                         "re-copy it") from None
    if not raw_parts:
        # A damaged chunk table makes the bindings drop every part instead of raising.
        raise InputError(f"{p}: cannot read any image part; the file is corrupt or truncated — re-render or re-copy it")
    if len(raw_parts) != len(headers):
        # ... or drop only the damaged parts (a truncated Blender file loses its last passes).
        raise InputError(f"{p}: {len(headers) - len(raw_parts)} of its {len(headers)} parts cannot be read; the "
                         "file is corrupt or truncated — re-render or re-copy it")
    return [_part(p, i, rp) for i, rp in enumerate(raw_parts)]


def _rgba_groups(ph: PartHeader) -> dict[str, list[str]]:
    """The channels OpenEXR's bindings read interleaved when asked (``separate_channels=False``):
    per key (``RGB``/``RGBA``, or the layer of ``layer.R`` …), the names of the layer's R, G, B
    (and A) — every layer that has all of R, G and B."""
    out = {}
    for n in ph.channels:
        pre = n[:-1]
        if n[-1] == "R" and (not pre or pre.endswith(".")) and all(pre + c in ph.channels for c in "GB"):
            members = [pre + c for c in "RGBA" if pre + c in ph.channels]
            out[pre[:-1] if pre else "RGBA"[:len(members)]] = members
    return out


def _can_interleave(headers: Sequence[PartHeader]) -> bool:
    """Whether OpenEXR can read every part's colour layers straight into interleaved (H, W, 3|4)
    arrays — what a Frame's colour is, so the reader need not stack planes: flat parts whose
    layers' channels share one pixel type and full resolution, with no channel named like a
    layer's key. Otherwise planes are read one by one."""
    for ph in headers:
        if ph.type.startswith("deep"):
            return False
        for key, members in _rgba_groups(ph).items():
            if (key in ph.channels or len({ph.channels[m] for m in members}) != 1
                    or any(ph.sampling.get(m) != (1, 1) for m in members)):
                return False
    return True


_CHROMA = ("RY", "BY")
"""The channels OpenEXR subsamples 2 × 2 in luminance/chroma images (:mod:`clpost.exr.yca`)."""


def _part(path: Path, index: int, rp: Any) -> _Part:
    header = dict(rp.header)
    name = str(rp.name() or header.get("name") or "")
    label = f"part {index}" + (f" '{name}'" if name else "")
    storage = rp.type()
    is_deep = storage in (OpenEXR.deepscanline, OpenEXR.deeptile)
    if storage not in (OpenEXR.scanlineimage, OpenEXR.tiledimage) and not is_deep:
        raise InputError(f"{path}: {label} has storage {storage.name}, which clpost cannot read; "
                         "convert it to a scanline or tiled EXR")
    dw, disp = _window(header, "dataWindow"), _window(header, "displayWindow")
    shape = (dw[1][1] - dw[0][1] + 1, dw[1][0] - dw[0][0] + 1)
    planes: dict[str, np.ndarray] = {}
    types: dict[str, str] = {}
    for cname, ch in rp.channels.items():
        xs, ys = ch.xSampling, ch.ySampling
        if (xs, ys) != (1, 1) and not (cname.rsplit(".", 1)[-1] in _CHROMA and (xs, ys) == (2, 2)):
            raise InputError(f"{path}: channel {cname!r} in {label} is subsampled ({xs}×{ys}); clpost reads "
                             "subsampled channels only as the RY/BY chroma of luminance/chroma images — "
                             "write full-resolution channels")
        px = np.asarray(ch.pixels)
        want = (-(-shape[0] // ys), -(-shape[1] // xs))
        if px.shape[:2] != want or px.ndim not in ((2,) if is_deep else (2, 3)):
            raise InputError(f"{path}: channel {cname!r} in {label} has {px.shape} pixels, data window "
                             f"{window_str(dw)} needs {want}; the file is corrupt or truncated — re-render it")
        if px.ndim == 3:  # an interleaved layer (_can_interleave): its channels are views of it
            pre = "" if cname in ("RGB", "RGBA") else cname + "."
            for i, c in enumerate("RGBA"[:px.shape[2]]):
                planes[pre + c], types[pre + c] = px[..., i], ch.type().name.lower()
            continue
        planes[cname] = px
        types[cname] = ch.type().name.lower()
    return _Part(index, name, header, planes, types, dw, disp, is_deep)


def _flat(part: _Part) -> _Part:
    """A deep part flattened front to back (:mod:`clpost.exr.deep`); other parts as they are."""
    if not part.deep:
        return part
    return _Part(part.index, part.name, part.header, deep.flatten(part.planes), part.types,
                 part.data_window, part.display_window)


def _view_of(channel: str, views: Sequence[str]) -> tuple[str, str]:
    """(view, name without the view) of a channel of a single-part multi-view file (OpenEXR
    ``ImfMultiView``: the view is the next-to-last period-separated field when it names a view;
    otherwise the channel belongs to the default view, the first of ``multiView``)."""
    fields = channel.split(".")
    if len(fields) >= 2 and fields[-2] in views:
        return fields[-2], ".".join(fields[:-2] + fields[-1:])
    return views[0], channel


def _select_view(path: Path, parts: Sequence[_Part], view: str | None) -> list[_Part]:
    """The parts and channels of one view of a multi-view file, with the view's name taken out of
    the channel names (so ``left.R`` reads as ``R``). Single-part files list their views in the
    ``multiView`` attribute (the first is the default); multi-part files name each part's
    ``view`` (the first part's is the default; parts without one belong to every view)."""
    multi = parts[0].header.get("multiView")
    part_views = [pt.header.get("view") for pt in parts]
    if len(parts) == 1 and multi:
        views = [str(v) for v in multi]
    else:
        views = list(dict.fromkeys(str(v) for v in part_views if v))
    if not views:
        if view is not None:
            raise InputError(f"{path}: --view {view}: the file has no views; leave --view out")
        return list(parts)
    chosen = views[0] if view is None else view
    if chosen not in views:
        raise InputError(f"{path}: --view {chosen}: the file's views are {', '.join(views)}; pick one of them")
    if len(parts) == 1 and multi:
        pt = parts[0]
        planes, types = {}, {}
        for cname, px in pt.planes.items():
            v, bare = _view_of(cname, views)
            if v == chosen:
                planes[bare], types[bare] = px, pt.types[cname]
        return [_Part(pt.index, pt.name, pt.header, planes, types, pt.data_window, pt.display_window, pt.deep)]
    return [pt for pt, v in zip(parts, part_views) if not v or str(v) == chosen]


def _merge(path: Path, parts: Sequence[_Part]) -> tuple[dict[str, np.ndarray], dict[str, Window], Window, Window]:
    """Channels of all parts in one dict, each with its part's data window; the union of the data
    windows and the display window, which the parts must share."""
    first = parts[0]
    planes: dict[str, np.ndarray] = {}
    windows: dict[str, Window] = {}
    for part in parts:
        if part.display_window != first.display_window:
            raise InputError(
                f"{path}: part {part.index} '{part.name}' has display window {window_str(part.display_window)} "
                f"but part {first.index} has {window_str(first.display_window)}; write all passes of one "
                "image with one display window")
        _check_windows(path, part.data_window)
        for cname, px in part.planes.items():
            if cname in planes:
                raise InputError(f"{path}: channel {cname!r} appears in more than one part; "
                                 "rename one of them so the layout is unambiguous")
            planes[cname] = px
            windows[cname] = part.data_window
    return planes, windows, bbox(*(p.data_window for p in parts)), first.display_window


def _place(plane: np.ndarray, window: Window, extent: Window, fill: float) -> np.ndarray:
    """A plane of ``window`` put at its place in an ``extent``-sized plane filled with ``fill``."""
    if window == extent:
        return plane
    (dx0, dy0), (dx1, dy1) = window
    (ox0, oy0), _ = extent
    w, h = window_size(extent)
    out = np.full((h, w), fill, dtype=plane.dtype)
    out[dy0 - oy0:dy1 - oy0 + 1, dx0 - ox0:dx1 - ox0 + 1] = plane
    return out


def _check_windows(path: Path, data: Window) -> None:
    (dx0, dy0), (dx1, dy1) = data
    if dx1 < dx0 or dy1 < dy0:
        raise InputError(f"{path}: empty data window {window_str(data)}; re-render the frame")


def _rgb_planes(path: Path, planes: dict[str, np.ndarray], windows: dict[str, Window],
                header: dict) -> tuple[dict[str, np.ndarray], dict[str, Window]]:
    """R, G, B made from what the file has when it has no R, G and B: luminance/chroma (Y, RY,
    BY) converted with the file's chromaticities, luminance (Y) as grey (:mod:`clpost.exr.yca`),
    or a lone R, G or B as grey (a monochrome image; two of the three stay an error)."""
    if {"R", "G", "B"} <= planes.keys() or any(n.endswith(".Combined.R") for n in planes):
        return planes, windows
    planes, windows = dict(planes), dict(windows)
    if "Y" in planes:
        y = planes.pop("Y")
        win = windows.pop("Y")
        chroma = [planes.pop(c, None) for c in _CHROMA]
        for c in _CHROMA:
            windows.pop(c, None)
        if chroma[0] is not None and chroma[1] is not None:
            cr = header.get("chromaticities") or yca.REC709_CHROMATICITIES
            try:
                rgb = yca.yca_to_rgb(y, chroma[0], chroma[1], cr)
            except InputError as e:
                raise InputError(f"{path}: {e}") from None
            rgb_planes = [rgb[..., i] for i in range(3)]
        else:
            grey = np.asarray(y, np.float32)
            rgb_planes = [grey, grey, grey]
    elif len(present := [c for c in "RGB" if c in planes]) == 1:
        win = windows.pop(present[0])
        grey = np.asarray(planes.pop(present[0]), np.float32)
        rgb_planes = [grey, grey, grey]
    else:
        return planes, windows
    for c, plane in zip("RGB", rgb_planes):
        planes[c], windows[c] = plane, win
    return planes, windows


def _str_attrs(header: dict) -> dict[str, str]:
    return {str(k): v for k, v in header.items() if isinstance(v, str)}


def _frame_from_parts(path: Path, parts: Sequence[_Part], layout: "str | ReadSpec | None", depth: str | None,
                      focal_px: float | tuple[float, float] | None,
                      velocity_y_up: bool | None, labels: str = "auto") -> Frame:
    view = None
    if isinstance(layout, ReadSpec):
        layout, view = layout.layout, layout.view
    parts = [_flat(pt) for pt in _select_view(path, parts, view)]
    planes, wins, data, display = _merge(path, parts)
    planes, wins = _rgb_planes(path, planes, wins, parts[0].header)
    if layout is None:
        try:
            layout = detect_layout(planes)
        except InputError as e:
            raise InputError(f"{path}: {e}") from None
    lay = get_layout(path, layout)
    kind = depth or lay.depth_kind
    if kind not in DEPTH_KINDS:
        raise InputError(f"depth={depth!r} is unknown; use one of {', '.join(DEPTH_KINDS)}")
    m = lay.map_channels(path, planes)
    window_of = {id(px): wins[name] for name, px in planes.items()}
    extent = bbox(data, display)

    def place(plane, fill):
        return _place(plane, window_of[id(plane)], extent, fill)

    rgb = _interleaved(m.color)  # read interleaved (_can_interleave): no copy
    if rgb is not None and window_of[id(m.color[0])] == extent:
        color = rgb
    else:
        color = np.stack([place(c, 0.0) for c in m.color], axis=-1)
    alpha = None
    if m.alpha is not None:
        alpha = _place(_clip_coverage(np.asarray(m.alpha)), window_of[id(m.alpha)], extent, 0.0)
    elif window_of[id(m.color[0])] != extent:
        alpha = _place(np.ones(m.color[0].shape, np.float32), window_of[id(m.color[0])], extent, 0.0)
    depth_m, kind_out = None, "planar"
    if m.depth is not None:
        # placed with a neutral 1 (radial depth converts by pixel position), no data → +inf after;
        # the plane is this read's own, converted in place
        depth_m, kind_out = depth_to_planar(path, place(m.depth, 1.0), kind, focal_px, in_place=True)
        if window_of[id(m.depth)] != extent:
            covered = _place(np.ones(m.depth.shape, bool), window_of[id(m.depth)], extent, False)
            depth_m = np.where(covered, depth_m, np.float32(np.inf)).astype(np.float32)
    vel = None
    if m.velocity is not None:
        win = window_of[id(m.velocity[0])]
        vel = lay.velocity(m, velocity_y_up)
        if win != extent:
            vel = np.stack([_place(vel[..., i], win, extent, 0.0) for i in range(2)], axis=-1)
    label_planes = {name: place(planes[name], 0) for name in _label_channels(path, planes, m, labels)}
    header = parts[0].header
    metadata = {"path": str(path), "layout": layout, "header": _str_attrs(header),
                "attributes": _camera_attrs(header), "depth_kind": kind_out,
                "windows": Windows(data, display), "alpha_channel": m.alpha is not None}
    if view is not None or header.get("multiView") or header.get("view"):
        metadata["view"] = view or str(header.get("view") or header["multiView"][0])
    if header.get("chromaticities") is not None:
        metadata["chromaticities"] = tuple(float(c) for c in header["chromaticities"])
    try:
        return Frame(color=color, depth=depth_m, velocity=vel, alpha=alpha, metadata=metadata, labels=label_planes,
                     copy=False)
    except InputError as e:
        raise InputError(f"{path} (layout {layout}): {e}") from None


def _interleaved(planes: Sequence[np.ndarray]) -> np.ndarray | None:
    """The C-contiguous (H, W, len(planes)) array whose channels ``planes`` are, in order (views
    of an interleaved read, or the first channels of one: RGB of RGBA is a strided view), else None."""
    base = planes[0].base
    if not isinstance(base, np.ndarray) or base.ndim != 3 or not base.flags.c_contiguous:
        return None
    start = base.__array_interface__["data"][0]
    for i, p in enumerate(planes):
        if p.base is not base or p.__array_interface__["data"][0] != start + i * base.itemsize or p.shape != base.shape[:2]:
            return None
    return base if base.shape[2] == len(planes) else base[..., :len(planes)]


def _clip_coverage(a: np.ndarray) -> np.ndarray:
    """Alpha with the hair that filters with negative lobes overshoot coverage by (1e-3) clipped
    to [0, 1]; values further out are left for the Frame to refuse. Two reductions when nothing
    overshoots (the usual case)."""
    if not a.size or (a.min() >= 0 and a.max() <= 1):  # NaN takes the long way, keeping it for the Frame to name
        return a
    return np.where((a > 1) & (a <= 1 + 1e-3), 1, np.where((a < 0) & (a >= -1e-3), 0, a)).astype(a.dtype)


def _label_channels(path: Path, planes: dict[str, np.ndarray], m, spec: str) -> list[str]:
    """The channels ``spec`` (``Camera.labels``, :mod:`clpost.labels.channels`) reads into
    ``Frame.labels``, among those the layout leaves: not a plane it reads, nor in a layer it reads
    from (Blender's Vector.X/Y beside the Z/W it uses)."""
    from ..labels.channels import select_labels

    if spec == "none":
        return []
    used = {id(a) for a in (*m.color, m.alpha, m.depth, *(m.velocity or ())) if a is not None}
    layers = {n.rsplit(".", 1)[0] for n, px in planes.items() if id(px) in used and "." in n}
    rest = [n for n, px in planes.items() if id(px) not in used and not ("." in n and n.rsplit(".", 1)[0] in layers)]
    return select_labels(spec, rest, str(path))


def read_frame(path: str | os.PathLike, layout: "str | ReadSpec | None" = None, *, depth: str | None = None,
               focal_px: float | tuple[float, float] | None = None,
               velocity_y_up: bool | None = None, view: str | None = None, labels: str = "auto") -> Frame:
    """Read one EXR (single- or multi-part, scanline or tiled — level 0 of a mip-map —, flat or
    deep, half or float) into a :class:`Frame`.

    ``layout`` (one of :data:`LAYOUTS`, or a :class:`ReadSpec`) overrides auto-detection;
    ``view`` picks a view of a multi-view file (default: its default view). The keyword options
    override a layout's documented assumptions (:mod:`clpost.exr`): ``depth`` is one of
    :data:`DEPTH_KINDS`; ``focal_px`` (focal length in pixels, scalar or ``(f_x, f_y)``) lets
    radial depth be converted to planar; ``velocity_y_up`` sets the vector's y sign for the
    clpost, nuke and arnold layouts (Blender's verified convention is fixed).

    The arrays cover the data and display windows (``Frame.windows``; outside the data window:
    color 0, alpha 0, depth ``+inf``, velocity 0). ``metadata`` = ``{"path", "layout", "header":
    str attributes of the first part, "attributes": its camera standard attributes
    (:data:`CAMERA_ATTRIBUTES`, floats), "depth_kind": "planar" | "radial", "windows",
    "alpha_channel": whether the file has an alpha channel (else alpha is None, or 1 over a data
    window smaller than the frame)}``, plus
    ``"view"`` for a multi-view file and ``"chromaticities"`` when the file declares them. Color is
    required; depth and velocity are optional (``None`` when the file has no such pass).
    ``labels`` (``Camera.labels``: ``auto``, ``all``, ``none`` or names; :mod:`clpost.labels.channels`)
    picks the other channels read into ``Frame.labels`` (ids, segmentation, normals, AOVs).
    """
    p = Path(path)
    if view is not None:
        base = layout.layout if isinstance(layout, ReadSpec) else layout
        layout = ReadSpec(base, view)
    return _frame_from_parts(p, _load(p), layout, depth, focal_px, velocity_y_up, labels)


# ----------------------------------------------------------------------------------------------
# Writing
# ----------------------------------------------------------------------------------------------

def _encode(path: Path, name: str, a: np.ndarray, half: bool) -> np.ndarray:
    if not half:
        return np.ascontiguousarray(a, dtype=np.float32)
    big = float(np.maximum(a.max(), -a.min())) if a.size else 0.0  # max |a| without an |a| copy
    if big > _HALF_MAX:
        raise InputError(f"{path}: {name} reaches {big:g}, beyond float16's {_HALF_MAX:g}; "
                         "write with half=False (float32) or scale the data")
    return np.ascontiguousarray(a, dtype=np.float16)


def _layout_parts(path: Path, frame: Frame, layout: str, half: bool,
                  focal_px: float | tuple[float, float] | None) -> list[tuple[str, dict[str, np.ndarray]]]:
    """(part name, channels) for each part to write, with our conventions inverted; colour and
    velocity as views of the (encoded) interleaved arrays (:func:`_writable` makes them writable)."""
    c = _encode(path, "color", frame.color, half)
    rgb = {k: c[..., i] for i, k in enumerate("RGB")}
    alpha = None if frame.alpha is None else _encode(path, "alpha", frame.alpha, half)
    vel = None
    if frame.velocity is not None:
        v = _encode(path, "velocity", frame.velocity, half)
        vel = (v[..., 0], v[..., 1])
    # Depth stays float32 even for half files (precision and range, see clpost.exr).
    return get_layout(path, layout).parts(rgb, alpha, frame.depth, vel, focal_px)


def _writable(channels: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Channels as OpenEXR's bindings write them correctly: each layer's R, G, B that are the
    channels of one interleaved array, in order, as that array under the layer's key (``RGB``,
    or the layer's name: the bindings write an (H, W, 3) array's channels with their strides,
    on OpenEXR's threads, no copy); every other plane C-contiguous — the bindings ignore a
    plane's strides and would write a strided view's memory as it lies."""
    out = dict(channels)
    for name in channels:
        pre = name[:-1]
        if name[-1:] != "R" or (pre and not pre.endswith(".")) or not all(pre + c in out for c in "GB"):
            continue
        rgb = _interleaved([out[pre + c] for c in "RGB"])
        key = pre[:-1] if pre else "RGB"
        if rgb is None or not rgb.flags.c_contiguous or key in out:
            continue
        for c in "RGB":
            del out[pre + c]
        out[key] = rgb
    return {k: v if v.ndim == 3 else np.ascontiguousarray(v) for k, v in out.items()}


def _user_header(path: Path, header: dict[str, str | float] | None) -> dict[str, str | float]:
    out: dict[str, str | float] = {}
    for k, v in (header or {}).items():
        if isinstance(v, float) and k in CAMERA_ATTRIBUTES and k != "captureRate" and math.isfinite(v):
            out[k] = v  # an OpenEXR standard float attribute (focus, aperture, expTime, ...)
            continue
        if not isinstance(k, str) or not isinstance(v, str):
            raise InputError(f"{path}: header attribute {k!r}={v!r} must be a str name and a str value "
                             f"(or a finite float for {', '.join(a for a in CAMERA_ATTRIBUTES if a != 'captureRate')}); "
                             "format numbers with str() first")
        if k in _RESERVED_ATTRS:
            raise InputError(f"{path}: header attribute {k!r} is managed by OpenEXR; use another name, "
                             "e.g. 'clpost.<name>'")
        out[k] = v
    return out


COMPRESSIONS = {
    # name: (OpenEXR constant, why pick it). Write/read times and sizes:
    # docs/measurements.md#exr-compression
    "zip": ("ZIP_COMPRESSION", "lossless, what Blender and most tools write"),
    "zips": ("ZIPS_COMPRESSION", "lossless, one scanline per block"),
    "piz": ("PIZ_COMPRESSION", "lossless wavelet, smallest for noisy renders"),
    "rle": ("RLE_COMPRESSION", "lossless run-length, fast, larger files"),
    "none": ("NO_COMPRESSION", "fastest for sequences on local disks, largest files"),
}
"""Lossless compressions offered for writing (lossy DWA/B44 are not: outputs are data)."""


def _box2i(w: Window) -> tuple[np.ndarray, np.ndarray]:
    return np.array(w[0], np.int32), np.array(w[1], np.int32)


def _data_crop(frame: Frame, a: np.ndarray | None) -> np.ndarray | None:
    """``a`` (one of the frame's arrays, or a plane of its size) cut to the frame's data window."""
    win = frame.windows
    if a is None or window_size(win.data) == frame.size:
        return a
    (dx0, dy0), (dx1, dy1) = win.data
    ox, oy = win.origin
    return np.ascontiguousarray(a[dy0 - oy:dy1 - oy + 1, dx0 - ox:dx1 - ox + 1])


def _data_only(frame: Frame) -> Frame:
    """The frame's data window alone (what an EXR stores), its arrays cropped to it."""
    if window_size(frame.windows.data) == frame.size:
        return frame
    return frame.replace(color=_data_crop(frame, frame.color), depth=_data_crop(frame, frame.depth),
                         velocity=_data_crop(frame, frame.velocity), alpha=_data_crop(frame, frame.alpha),
                         labels={k: _data_crop(frame, v) for k, v in frame.labels.items()}, validate=False)


def _label_encode(path: Path, name: str, a: np.ndarray) -> np.ndarray:
    """A label plane as an EXR channel, exactly: float32 → FLOAT, uint32 → UINT, int32 → UINT when
    ≥ 0, else FLOAT when exact (|v| < 2²⁴). Never half (ids would lose bits)."""
    a = np.ascontiguousarray(a)
    if a.dtype == np.int32:
        if not a.size or a.min() >= 0:
            return a.astype(np.uint32)
        if np.abs(a).max() >= 1 << 24:
            raise InputError(f"{path}: label channel {name!r} has negative ids beyond ±2^24, which no EXR channel "
                             "type holds exactly; renumber them as non-negative ids")
        return a.astype(np.float32)
    return a


def _build_file(parts: list[tuple[str, dict[str, np.ndarray]]], attrs: dict[str, str],
                compression: str = "zip", windows: Windows | None = None) -> Any:
    base = {"compression": getattr(OpenEXR, COMPRESSIONS[compression][0]), "type": OpenEXR.scanlineimage}
    if windows is not None:
        base.update(dataWindow=_box2i(windows.data), displayWindow=_box2i(windows.display))
    parts = [(name, _writable(ch)) for name, ch in parts]
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
                focal_px: float | tuple[float, float] | None = None, compression: str = "zip",
                extra: dict[str, np.ndarray] | None = None) -> None:
    """Write ``frame``'s color (+alpha), depth and velocity in one layout, atomically.

    ``clpost``, ``nuke`` and ``arnold`` are single-part files; ``blender`` is one part per pass
    (Combined RGBA, Depth, Vector) as Blender 5.x writes them. ``header`` holds extra string
    attributes (added to every part). ``half`` stores color/alpha/velocity as float16 (depth
    stays float32). ``compression`` is one of :data:`COMPRESSIONS` (lossless). For ``arnold``,
    ``focal_px`` writes Z as radial distance (what the reader assumes); without it Z is written
    planar. The frame's data and display windows (:attr:`Frame.windows`) are written as the file's:
    the data window's pixels, placed where they were read. ``extra``: further (H, W) channels by
    full name (e.g. ``coc.Y``, :mod:`clpost.aovs`), float32, the frame's size, added to the first
    part (cut to the data window as the image is); so are the frame's label planes
    (``Frame.labels``, under their names, exactly: :func:`_label_encode`). Any failure leaves an existing ``path``
    untouched and no temporary file behind.
    """
    p = Path(path)
    get_layout(p, layout)
    if not isinstance(frame, Frame):
        raise InputError(f"{p}: write_frame needs a clpost.frame.Frame, got {type(frame).__name__}")
    if compression not in COMPRESSIONS:
        raise InputError(f"{p}: compression {compression!r} is unknown; use one of {', '.join(COMPRESSIONS)}")
    parts = _layout_parts(p, _data_only(frame), layout, half, focal_px)
    for name, plane in (extra or {}).items():
        if any(name in ch for _, ch in parts) or np.shape(plane) != (frame.height, frame.width):
            raise InputError(f"{p}: extra channel {name!r} clashes with a written channel or is not "
                             f"{frame.height}x{frame.width}; name it differently / give an (H, W) plane")
        parts[0][1][name] = np.ascontiguousarray(_data_crop(frame, plane), dtype=np.float32)
    for name, plane in frame.labels.items():
        if any(name in ch for _, ch in parts):
            raise InputError(f"{p}: label channel {name!r} clashes with a written channel; rename it in the input "
                             "or leave it out with --labels")
        parts[0][1][name] = _label_encode(p, name, _data_crop(frame, plane))
    exr_file = _build_file(parts, _user_header(p, header), compression, frame.windows)
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
    our convention, or None), ``alpha`` (``{"covered", "opaque", "pixels"}``: pixel counts of alpha
    > 0, alpha = 1 and all, or None without an alpha channel), ``problems`` (messages that stop
    :func:`read_frame`, or warnings),
    ``camera_attributes`` (the :data:`CAMERA_ATTRIBUTES` present: what ``process`` reads per frame).
    """
    p = Path(path)
    parts = _load(p)
    (ox0, oy0), (ox1, oy1) = parts[0].display_window
    out: dict[str, Any] = {
        "path": str(p),
        "parts": [{"name": pt.name, "channels": sorted(pt.types.items()),
                   "data_window": pt.data_window, "display_window": pt.display_window} for pt in parts],
        "size": (ox1 - ox0 + 1, oy1 - oy0 + 1),
        "layout": None, "depth_kind": None, "depth": None, "velocity": None, "alpha": None, "problems": [],
        "camera_attributes": _camera_attrs(parts[0].header),
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
    if frame.metadata.get("alpha_channel") and frame.alpha is not None:
        a = frame.alpha
        out["alpha"] = {"covered": int(np.count_nonzero(a > 0)), "opaque": int(np.count_nonzero(a >= 1)),
                        "pixels": int(a.size)}
    return out


def _fmt(v: float | None) -> str:
    return "—" if v is None else f"{v:.6g}"


def format_info(d: dict) -> str:
    """Human-readable text of an :func:`info` dict."""
    w, h = d["size"]
    lines = [f"{d['path']}: {w}×{h}, layout {d['layout'] or 'unknown'}, {len(d['parts'])} part(s)"]
    for i, part in enumerate(d["parts"]):
        chans = ", ".join(f"{n} ({t})" for n, t in part["channels"])
        lines.append(f"  part {i} {part['name'] or '(unnamed)'}: data {window_str(part['data_window'])}, "
                     f"display {window_str(part['display_window'])}")
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
    al = d.get("alpha")
    if al is not None:
        front = dep is not None and al["opaque"] < al["pixels"]
        use = "; with depth: usable as a front layer (process --front)" if front else ""
        lines.append(f"  alpha: covers {al['covered']} of {al['pixels']} px, {al['opaque']} opaque{use}")
    cam = d.get("camera_attributes")
    if cam:
        lines.append("  camera attributes: " + ", ".join(
            f"{k} {v:g}{'' if CAMERA_ATTRIBUTES[k] in ('f-number', 'ISO', 'T-number') else ' ' + CAMERA_ATTRIBUTES[k]}"
            for k, v in cam.items()))
    lines.extend(f"  problem: {msg}" for msg in d["problems"])
    return "\n".join(lines)
