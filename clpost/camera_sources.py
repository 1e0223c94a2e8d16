"""Where each camera parameter's value comes from, per frame (an animated camera).

Sources, highest priority first (``docs/camera-tracks.md``):

1. ``flag`` — options given on the command line (constant over the shot);
2. ``camera-from`` — the camera recorded in an output's header (``--camera-from OUT.exr``: the
   ``clpost.*`` keys :meth:`~clpost.camera.Camera.describe` writes), constant;
3. ``track`` — a camera track file (``--camera-track``, :mod:`clpost.camera_track`), per frame;
4. ``exr`` — the input frame's OpenEXR standard attributes (table below, :func:`exr_values`), per frame;
5. ``default`` — the camera's defaults.

Each parameter takes the highest source that sets it. ``shutter_s`` and ``shutter_angle_deg``
are one quantity (an angle is a shutter time at the frame rate): the source that sets either
sets both. A per-frame parameter (``scalar=True``) changes without rebuilding anything; a
structural one that changes over a shot (a zoom: ``nominalFocalLength``; a track's ``blades``)
gets one plan per distinct value, cached (``Pipeline.MAX_PLANS``) — allowed, and said by
``--explain``.

OpenEXR standard attributes (ImfStandardAttributes.h) ↔ camera parameters, read from inputs
and written into outputs beside the ``clpost.*`` keys (:func:`standard_attributes`):

====================  ======================================  ====================================
attribute             read as                                  written from
====================  ======================================  ====================================
``focus`` (m)         ``focus_distance_m``                     ``focus_distance_m`` (finite only)
``aperture``          ``f_number``                             ``f_number``
``expTime`` (s)       ``shutter_s``                            ``shutter_s``
``isoSpeed``          ``iso``                                  ``iso``
``nominalFocalLength``  ``lens = thin:<mm>`` (thin lens only)  the lens's focal length (mm)
``tStop``             with ``aperture``: ``transmittance =     ``f_number / sqrt(transmittance)``
                      (N/T)²``; alone: ``f_number = T·√τ``
``shutterAngle`` (°)  with ``captureRate`` and no ``expTime``:  ``shutter_s · fps · 360`` with
                      ``shutter_s = angle / (360 · rate)``      ``--fps``
``captureRate``       only to turn ``shutterAngle`` into a      not written (a rational; the
                      time; it does not set ``--fps``           Python binding cannot write it)
====================  ======================================  ====================================

(T-stop: T = N/√τ, SMPTE RP 2005 / ISO 517.)
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

from .errors import InputError

_LINKED = ({"shutter_s", "shutter_angle_deg"}, {"focus_distance_m", "focus_scale_m"})
"""Fields that are one quantity: the highest source of any of them sets all of them."""


def _positive(v: float | None) -> bool:
    return v is not None and math.isfinite(v) and v > 0


def exr_values(attrs: Mapping[str, float], above: Mapping[str, Any], camera_cls) -> dict[str, tuple[Any, str]]:
    """Camera fields from a frame's standard attributes: ``field → (value, attribute name)``.
    ``above`` holds the values of higher sources and defaults (the lens, the transmittance) that
    the mapping of ``nominalFocalLength`` and ``tStop`` depends on."""
    out: dict[str, tuple[Any, str]] = {}
    a = {k: v for k, v in attrs.items() if isinstance(v, float) and math.isfinite(v)}
    if _positive(a.get("focus")):  # 0 is how some tools write "unknown"
        out["focus_distance_m"] = (a["focus"], "focus")
    if _positive(a.get("aperture")):
        out["f_number"] = (a["aperture"], "aperture")
    if _positive(a.get("tStop")):
        if "f_number" in out:
            tau = (out["f_number"][0] / a["tStop"]) ** 2
            out["transmittance"] = (min(tau, 1.0), "tStop and aperture")
        else:
            tau = above["transmittance"]
            out["f_number"] = (a["tStop"] * math.sqrt(tau), "tStop")
    if _positive(a.get("expTime")):
        out["shutter_s"] = (a["expTime"], "expTime")
    elif _positive(a.get("shutterAngle")) and _positive(a.get("captureRate")):
        out["shutter_s"] = (a["shutterAngle"] / 360.0 / a["captureRate"], "shutterAngle / captureRate")
    if _positive(a.get("isoSpeed")):
        out["iso"] = (a["isoSpeed"], "isoSpeed")
    if _positive(a.get("nominalFocalLength")) and str(above.get("lens", "thin:")).startswith("thin:"):
        out["lens"] = (f"thin:{a['nominalFocalLength']:g}", "nominalFocalLength")
    return out


def standard_attributes(camera) -> dict[str, float]:
    """The OpenEXR standard attributes of a (resolved) camera, written beside the clpost.* keys."""
    out: dict[str, float] = {}
    if math.isfinite(camera.focus_distance_m):
        out["focus"] = float(camera.focus_distance_m)
    if camera.f_number is not None:
        out["aperture"] = float(camera.f_number)
        out["tStop"] = float(camera.f_number / math.sqrt(camera.transmittance))
    if camera.shutter_s is not None:
        out["expTime"] = float(camera.shutter_s)
        fps = getattr(camera, "frame_rate_fps", None)
        if fps is not None:
            out["shutterAngle"] = float(camera.shutter_s * fps * 360.0)
    if not camera.__dict__.get("iso_default"):  # a defaulted ISO is not the user's: not recorded as one
        out["isoSpeed"] = float(camera.iso)
    out["nominalFocalLength"] = float(camera.focal_length_mm)
    return out


# -- --camera-from: the camera an output's header records ---------------------------------------

def _calibration_from_header(text: str):
    from .calibration.header import model_from_header

    return model_from_header(text, source="--camera-from header")


def _none_text(spec) -> str | None:
    """What the header shows for None (e.g. ``none``), if it shows None at all."""
    try:
        return spec.header_text(None)
    except (TypeError, ValueError, AttributeError):
        return None


def values_from_header(strings: Mapping[str, str], where: str, camera_cls) -> dict[str, Any]:
    """Camera fields from the ``clpost.*`` string attributes :meth:`Camera.describe` wrote. A
    field whose key is absent was unset/off (omitted by describe) and takes its default."""
    import argparse

    specs = [s for s in camera_cls.param_specs() if s.meta.header is not None and not s.meta.input_only]
    if not any(s.meta.header in strings for s in specs):
        raise InputError(f"--camera-from {where}: its header records no clpost camera (no clpost.* keys); "
                         "give an EXR written by `clpost process` or `clpost demo`")
    out: dict[str, Any] = {}
    for s in specs:
        text = strings.get(s.meta.header)
        if text is None:
            if s.header_text(s.default) is None:
                out[s.name] = s.default  # omitted = unset / off
            continue
        try:
            if _none_text(s) == text:  # show_none's "none": unset
                v = None
            elif s.name == "distortion":
                v = _calibration_from_header(text)
            elif s.meta.parse is not None:
                v = s.meta.parse(text)
            else:
                v = text
            if s.meta.check is not None:
                v = s.meta.check(s.name, v)
        except (argparse.ArgumentTypeError, ValueError, IndexError, InputError) as e:
            raise InputError(f"--camera-from {where}: header {s.meta.header}={text!r} is not a value of "
                             f"{s.meta.flag or s.name} ({e}); fix or remove that key") from None
        out[s.name] = v
    return out


def camera_from_file(path, camera_cls=None) -> dict[str, Any]:
    """The recorded camera of an output EXR (header only), as Camera field values."""
    from . import exr

    if camera_cls is None:
        from .camera import Camera as camera_cls
    from pathlib import Path

    if not Path(path).is_file():
        raise InputError(f"--camera-from {path}: no such file; give an output EXR written by `clpost process`")
    _, strings = exr.read_attributes(path)
    return values_from_header(strings, str(path), camera_cls)


# -- resolving a frame's camera -------------------------------------------------------------------

@dataclass(frozen=True)
class Resolved:
    """A frame's camera and, per field, the source that set it (``"flag --focus"``, ...)."""

    camera: Any
    sources: dict[str, str]


@dataclass(frozen=True)
class CameraSources:
    """Everything a frame's camera is made from (picklable: it travels to Dask workers)."""

    flags: Mapping[str, Any] = field(default_factory=dict)
    camera_from: Mapping[str, Any] = field(default_factory=dict)
    camera_from_path: str | None = None
    track: Any = None
    """A :class:`clpost.camera_track.CameraTrack` or None."""
    defaults: Mapping[str, Any] = field(default_factory=dict)
    """Defaults replacing the Camera's own (the demo's), lowest priority."""
    use_exr: bool = True
    camera_cls: Any = None

    @property
    def cls(self):
        if self.camera_cls is not None:
            return self.camera_cls
        from .camera import Camera

        return Camera

    def _layers(self, frame: int, attrs: Mapping[str, float]) -> list[tuple[str, dict[str, Any], dict[str, str]]]:
        """(source, values, labels) from highest to lowest priority for one frame."""
        specs = {s.name: s for s in self.cls.param_specs()}
        flag_labels = {k: f"flag {specs[k].meta.flag or k}" for k in self.flags}
        layers = [("flag", dict(self.flags), flag_labels),
                  ("camera-from", dict(self.camera_from),
                   {k: f"camera-from {self.camera_from_path}" for k in self.camera_from})]
        if self.track is not None:
            tv = self.track.values_at(frame)
            layers.append(("track", tv, {k: f"track {self.track.path}" for k in tv}))
        if self.use_exr and attrs:
            above: dict[str, Any] = {}
            for _, vals, _ in reversed(layers):
                above.update(vals)
            ex = exr_values(attrs, {**{k: specs[k].default for k in ("lens", "transmittance")},
                                    **self.defaults, **above}, self.cls)
            layers.append(("exr", {k: v for k, (v, _) in ex.items()},
                           {k: f"EXR {name}" for k, (_, name) in ex.items()}))
        return layers

    def resolve(self, frame: int, attrs: Mapping[str, float] | None = None) -> Resolved:
        """The camera of frame number ``frame`` whose input has standard attributes ``attrs``."""
        layers = self._layers(frame, attrs or {})
        chosen: dict[str, Any] = {}
        labels: dict[str, str] = {}
        taken: set[str] = set()
        for _, values, lab in layers:
            for k, v in values.items():
                if k in taken:
                    continue
                group = next((g for g in _LINKED if k in g), {k})
                for g in group:  # this source owns the whole linked group
                    taken.add(g)
                    if g in values:
                        chosen[g] = values[g]
                        labels[g] = lab[g]
                for stored, alias in (("shutter_s", "shutter_angle_deg"), ("focus_distance_m", "focus_scale_m")):
                    if alias in group and alias in values and stored not in values:
                        labels[stored] = lab[alias]  # the stored field is named by the source that set it
        given = {k: v for k, v in chosen.items() if k in self.flags}
        lower = {**self.defaults, **{k: v for k, v in chosen.items() if k not in self.flags}}
        try:
            cam = self.cls.from_options(given, lower)
        except InputError as e:
            if not (set(chosen) - set(self.flags)):
                raise
            raise InputError(f"frame {frame}: {e} (values from "
                             f"{', '.join(sorted(set(labels[k] for k in chosen if k not in self.flags)))})") from None
        for s in self.cls.param_specs():
            if not s.meta.input_only and s.name not in labels:
                labels[s.name] = "default" if s.name not in self.defaults else "default (demo)"
        return Resolved(cam, labels)


def explain_sources(resolved: list[tuple[int, Resolved]]) -> list[str]:
    """``--explain`` lines: per parameter, its value (or range over the frames) and its source(s)."""
    if not resolved:
        return []
    cls = type(resolved[0][1].camera)
    lines = []

    def shown(s, v) -> str:
        # a value left out of the header at its default (e.g. plate_fov "focused") is still a value
        text = s.header_text(v)
        return text if text is not None else ("none" if v is None else str(v))

    for s in cls.param_specs():
        if s.meta.input_only:
            continue
        values = [getattr(r.camera, s.name) for _, r in resolved]
        srcs = []
        for _, r in resolved:
            if r.sources[s.name] not in srcs:
                srcs.append(r.sources[s.name])
        text = shown(s, values[0])
        distinct = []
        for v in values:
            if v not in distinct:
                distinct.append(v)
        if len(distinct) > 1:
            nums = [v for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)]
            if len(nums) == len(values):
                first, last = resolved[0][0], resolved[-1][0]
                text = (f"{min(nums):g} … {max(nums):g} (varies over frames {first}–{last}: "
                        f"{len(distinct)} values)")
            else:
                text = f"{len(distinct)} values over the frames ({', '.join(shown(s, v) for v in distinct[:4])}{', …' if len(distinct) > 4 else ''})"
            if not s.meta.scalar:
                text += f"; structural: {len(distinct)} plans"
        unit = f" {s.meta.unit}" if s.meta.unit in ("m", "seconds", "mm", "degrees") and text != "none" else ""
        lines.append(f"{s.name:<26} {text}{unit}  [{' / '.join(srcs)}]")
    return lines
