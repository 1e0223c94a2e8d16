"""Camera track files: keyframes of camera parameters over a shot (``--camera-track``).

A track gives, per frame number, values of any :class:`~clpost.camera.Camera` parameter, named
by its field (``focus_distance_m``) or its command-line flag with or without the dashes
(``focus``, ``--f-number``). Each parameter has its own keyframes (a keyframe need not name
every parameter) and its own interpolation:

- ``linear`` (default for float parameters): straight-line between the two nearest keyframes;
- ``step`` (default for whole numbers, on/off and text values, and the only one for structural
  parameters): the value of the last keyframe at or before the frame.

Frames before the first keyframe of a parameter hold its first value, frames after the last
hold its last one. Values are numbers, or text read as the flag reads it (``"1/50"``,
``"auto"``, ``"36x24"``, ``"thin:35"``). Two formats, chosen by the file's extension
(``docs/camera-tracks.md`` has examples):

- **JSON** ``.json``: ``{"interpolation": {"f_number": "step"}, "keys": [{"frame": 1,
  "focus": 1.2}, ...]}`` (or the ``keys`` list alone);
- **CSV** ``.csv``: a header row ``frame,focus,f_number:step`` (``:step``/``:linear`` after a
  column name sets its interpolation), one row per keyframe; an empty cell is no key; lines
  starting with ``#`` are comments.

Every mistake is one :class:`~clpost.errors.InputError` line naming the file, the line (CSV,
and JSON syntax) or key, and the fix.
"""
from __future__ import annotations

import bisect
import csv
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import InputError

INTERPOLATIONS = ("linear", "step")


def _field_names(camera_cls) -> dict[str, Any]:
    """Every name a track may use for a parameter → its :class:`~clpost.params.ParamSpec`."""
    out = {}
    for s in camera_cls.param_specs():
        if s.name == "distortion":  # a calibration object, not a value a track can hold
            continue
        out[s.name] = s
        if s.meta.flag:
            out[s.meta.flag] = s
            out[s.meta.flag.lstrip("-")] = s
    return out


def default_interpolation(spec) -> str:
    """``linear`` for a per-frame float parameter, else ``step``."""
    is_float = "float" in str(spec.type) and "tuple" not in str(spec.type)
    return "linear" if spec.meta.scalar and is_float else "step"


@dataclass(frozen=True)
class Channel:
    """One parameter's keyframes: sorted frames, their values, and the interpolation."""

    name: str
    frames: tuple[int, ...]
    values: tuple[Any, ...]
    interpolation: str

    def at(self, frame: int) -> Any:
        i = bisect.bisect_right(self.frames, frame)
        if i == 0:
            return self.values[0]
        if i == len(self.frames):
            return self.values[-1]
        v0 = self.values[i - 1]
        if self.interpolation == "step":
            return v0
        f0, f1, v1 = self.frames[i - 1], self.frames[i], self.values[i]
        if v0 is None or v1 is None:  # 'auto' keys do not interpolate
            return v0
        t = (frame - f0) / (f1 - f0)
        return v0 + (v1 - v0) * t


@dataclass(frozen=True)
class CameraTrack:
    """The keyframed parameters of one track file (``channels`` by Camera field name)."""

    path: str
    channels: tuple[Channel, ...]

    def values_at(self, frame: int) -> dict[str, Any]:
        """Every tracked parameter's value at ``frame`` (Camera field → value)."""
        return {c.name: c.at(frame) for c in self.channels}

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.channels)


class _Where:
    """Builds the one-line errors: file, then the line or key."""

    def __init__(self, path: Path):
        self.path = path

    def error(self, where: str, what: str) -> InputError:
        return InputError(f"{self.path}: {where}: {what}; see docs/camera-tracks.md")


def load_track(path: str | Path, camera_cls=None) -> CameraTrack:
    """Read and check a track file (JSON or CSV by extension)."""
    if camera_cls is None:
        from .camera import Camera as camera_cls
    p = Path(path)
    if not p.is_file():
        raise InputError(f"--camera-track {p}: no such file; give a .json or .csv track (docs/camera-tracks.md)")
    ext = p.suffix.lower()
    if ext not in (".json", ".csv"):
        raise InputError(f"--camera-track {p}: unknown extension {p.suffix!r}; name it .json or .csv "
                         "(docs/camera-tracks.md)")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"--camera-track {p}: cannot read ({e}); check the file") from None
    w = _Where(p)
    rows, interp = (_json_rows if ext == ".json" else _csv_rows)(text, w)
    return _build(p, rows, interp, w, camera_cls)


def _json_rows(text: str, w: _Where):
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise w.error(f"line {e.lineno}, column {e.colno}", f"not valid JSON ({e.msg})") from None
    interp: dict[str, tuple[str, str]] = {}
    if isinstance(doc, dict):
        unknown = set(doc) - {"keys", "interpolation", "comment", "format"}
        if unknown:
            raise w.error(f"key {sorted(unknown)[0]!r}", "unknown top-level key; use 'keys' and 'interpolation'")
        keys = doc.get("keys")
        ip = doc.get("interpolation", {})
        if not isinstance(ip, dict):
            raise w.error("key 'interpolation'", 'must be an object like {"f_number": "step"}')
        for k, v in ip.items():
            interp[k] = (v, f"interpolation[{k!r}]")
    else:
        keys = doc
    if not isinstance(keys, list) or not keys:
        raise w.error("key 'keys'", 'must be a non-empty list of keyframes like {"frame": 1, "focus": 2.0}')
    rows = []
    for i, k in enumerate(keys):
        if not isinstance(k, dict):
            raise w.error(f"keys[{i}]", 'a keyframe must be an object like {"frame": 1, "focus": 2.0}')
        rows.append((f"keys[{i}]", k))
    return rows, interp


def _csv_rows(text: str, w: _Where):
    lines = [(n, ln) for n, ln in enumerate(text.splitlines(), 1) if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise w.error("line 1", "empty track; write a header row like 'frame,focus' and one row per keyframe")
    hdr_no, hdr = lines[0]
    head = [h.strip() for h in next(csv.reader(io.StringIO(hdr)))]
    if not head or head[0] != "frame":
        raise w.error(f"line {hdr_no}", f"the header row must start with 'frame' (got {head[0] if head else ''!r}), "
                                        "e.g. 'frame,focus,f_number:step'")
    names, interp = [], {}
    for col in head[1:]:
        name, _, how = col.partition(":")
        name = name.strip()
        if not name:
            raise w.error(f"line {hdr_no}", "an empty column name; name every column, e.g. 'frame,focus'")
        if how:
            interp[name] = (how.strip(), f"line {hdr_no}, column {col!r}")
        names.append(name)
    rows = []
    for n, ln in lines[1:]:
        cells = [c.strip() for c in next(csv.reader(io.StringIO(ln)))]
        if len(cells) != len(head):
            raise w.error(f"line {n}", f"{len(cells)} cells but the header has {len(head)} columns; "
                                       "leave a cell empty for no key, keep the commas")
        row = {"frame": cells[0]}
        row.update({name: c for name, c in zip(names, cells[1:]) if c != ""})
        rows.append((f"line {n}", row))
    if not rows:
        raise w.error(f"line {hdr_no}", "a header but no keyframe rows; add rows like '1,2.5'")
    return rows, interp


def _frame_number(v: Any, w: _Where, where: str) -> int:
    try:
        f = float(v) if isinstance(v, str) else v
        ok = isinstance(f, (int, float)) and not isinstance(f, bool) and math.isfinite(f) and int(f) == f
    except ValueError:
        ok = False
    if not ok:
        raise w.error(f"{where} 'frame'", f"{v!r} is not a whole frame number; use e.g. 1, 24 (no sub-frames)")
    return int(f)


def _value(spec, raw: Any, w: _Where, where: str) -> Any:
    """A cell/JSON value → the parameter's value, checked by its own declaration."""
    import argparse

    v = raw
    if isinstance(raw, str) and spec.meta.parse is not None:
        try:
            v = spec.meta.parse(raw)
        except (argparse.ArgumentTypeError, ValueError) as e:
            raise w.error(f"{where} {spec.name!r}", f"{raw!r} is not a value of {spec.meta.flag or spec.name} ({e})") from None
    elif isinstance(raw, list) and "tuple" in str(spec.type):
        v = tuple(raw)
    elif raw is None and spec.meta.check is not None:
        v = None
    if spec.meta.check is not None and not spec.meta.input_only:
        try:
            v = spec.meta.check(spec.name, v)
        except InputError as e:
            raise w.error(f"{where} {spec.name!r}", str(e)) from None
    elif spec.meta.input_only and not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)):
        raise w.error(f"{where} {spec.name!r}", f"{raw!r} must be a number ({spec.meta.unit})")
    return v


def _build(p: Path, rows, interp_given, w: _Where, camera_cls) -> CameraTrack:
    names = _field_names(camera_cls)
    keyed: dict[str, dict[int, Any]] = {}
    specs = {}
    for where, row in rows:
        if "frame" not in row:
            raise w.error(where, "a keyframe without 'frame'; give its frame number, e.g. \"frame\": 1")
        frame = _frame_number(row["frame"], w, where)
        for key, raw in row.items():
            if key == "frame":
                continue
            spec = names.get(key)
            if spec is None:
                raise w.error(f"{where} {key!r}", "unknown camera parameter; use a Camera field or flag name "
                                                  "(focus_distance_m or focus, f_number or f-number, ...; "
                                                  "`clpost process --help` lists them)")
            if spec.name in keyed and frame in keyed[spec.name] and specs[spec.name] is spec:
                raise w.error(f"{where} {key!r}", f"frame {frame} has two keys for {spec.name}; keep one")
            specs[spec.name] = spec
            keyed.setdefault(spec.name, {})[frame] = _value(spec, raw, w, where)
    if not keyed:
        raise w.error("keys", "no parameter is keyed; add e.g. a 'focus' value to a keyframe")
    how: dict[str, str] = {}
    for key, (mode, where) in interp_given.items():
        spec = names.get(key)
        if spec is None:
            raise w.error(where, f"{key!r} is not a camera parameter; name a keyed parameter")
        if mode not in INTERPOLATIONS:
            raise w.error(where, f"interpolation {mode!r} is unknown; use 'linear' or 'step'")
        if mode == "linear" and default_interpolation(spec) != "linear":
            why = ("structural: each value builds its own kernels" if not spec.meta.scalar
                   else "not a float parameter")
            raise w.error(where, f"{spec.name} cannot be interpolated linearly ({why}); use 'step'")
        how[spec.name] = mode
    channels = []
    for name, by_frame in keyed.items():
        frames = tuple(sorted(by_frame))
        channels.append(Channel(name, frames, tuple(by_frame[f] for f in frames),
                                how.get(name, default_interpolation(specs[name]))))
    return CameraTrack(str(p), tuple(channels))
