"""The viewer's model, without any web framework: frames, the camera being edited, one
:class:`~clpost.pipeline.Pipeline` per quality, and what the page shows (the display image, the
A/B split, exposure tools, the plan with its timings, the command line and the camera track).

Per frame it calls only the public API: ``Pipeline.camera_for`` → ``Pipeline.plan_for`` →
``Plan.run``. A change of a ``scalar=True`` parameter (f-number, focus, shutter, EV …) reuses the
plan (no kernel is built); a structural one (lens, blades, film …) makes a new plan, which the
status line says with its build time.
"""
from __future__ import annotations

import base64
import functools
import io
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import Camera
from ..errors import InputError
from ..frame import Frame
from ..pipeline import Pipeline

DRAFT = "draft"

FALSE_COLOUR_STOPS = ((-np.inf, -6.5, (80, 0, 120)), (-6.5, -4.5, (0, 60, 200)), (-4.5, -2.5, (0, 150, 220)),
                      (-2.5, -0.5, (60, 170, 60)), (-0.5, 0.5, (150, 150, 150)), (0.5, 1.5, (230, 150, 200)),
                      (1.5, 2.5, (240, 240, 60)), (2.5, 3.5, (255, 140, 0)), (3.5, np.inf, (230, 20, 20)))
"""False colour bands by stops from 18 % grey of the camera's output (relative luminance): purple
crushed, blues under, green ≈ −1.5 stop skin shadows, grey = mid-grey ± ½ stop, pink ≈ +1 stop
(Caucasian skin), yellow/orange near clipping, red ≥ +3.5 stops = clipped for a display white
of 1.0 (0.18 · 2^3.5 ≈ 2.0 > 1). The layout is ARRI's false-colour convention, coarsened."""

ZEBRA_LEVEL = 0.95
"""Zebra stripes where any display channel is at or above 95 % (242/255), as cameras' 95 % zebras."""


@dataclass
class Rendered:
    """One processed frame for the page."""

    display: np.ndarray  # (H, W, 3) uint8, the camera's output display-encoded
    linear: np.ndarray  # (H, W, 3) float32, the camera's output
    quality: str
    camera: Camera  # resolved (metered)
    stages: list[str]
    timings: dict[str, float]  # device ms per kernel
    total_ms: float  # wall time of camera_for + plan_for + run + display encoding
    built: bool  # a new plan was made for this frame
    build_ms: float = 0.0


@dataclass
class ViewSession:
    """The viewer's state and work. ``frames``: a callable ``i -> Frame`` and the frame numbers."""

    frame_numbers: list[int]
    load: Any
    camera: Camera
    input_label: str
    final_quality: str = "final"
    device: str | None = None
    display: str = "srgb"
    keys: dict[int, dict[str, str]] = field(default_factory=dict)
    _pipes: dict = field(default_factory=dict)
    _cache: dict = field(default_factory=dict)
    _plans_seen: set = field(default_factory=set)

    # -- inputs --------------------------------------------------------------------------------
    def frame(self, i: int) -> Frame:
        """The i-th frame (index into :attr:`frame_numbers`), cached (a sequence is scrubbed back and forth)."""
        if i not in self._cache:
            if len(self._cache) >= 8:
                self._cache.pop(next(iter(self._cache)))
            self._cache[i] = self.load(i)
        return self._cache[i]

    def pipeline(self, quality: str) -> Pipeline:
        pipe = self._pipes.get(quality)
        if pipe is None:
            pipe = self._pipes[quality] = Pipeline(self.camera, quality=quality, device=self.device)
        return pipe

    # -- the camera ------------------------------------------------------------------------------
    def with_values(self, values: dict[str, Any]) -> Camera:
        """A camera from the current one with ``values`` (field → value); InputError as the CLI's."""
        return Camera(**{**{s.name: getattr(self.camera, s.name) for s in Camera.param_specs()
                            if not s.meta.input_only}, **values})

    def set_camera(self, camera: Camera) -> None:
        self.camera = camera

    # -- processing ------------------------------------------------------------------------------
    def render(self, index: int, quality: str) -> Rendered:
        """Process frame ``index`` with the current camera at ``quality``."""
        frame = self.frame(index)
        t0 = time.perf_counter()
        pipe = self.pipeline(quality)
        cam = pipe.camera_for(pipe.plate(frame, self.camera), self.camera)
        n_before = len(self._plans_seen)
        tb = time.perf_counter()
        plan = pipe.plan_for(pipe.plate(frame, self.camera), cam)
        self._plans_seen.add(id(plan))
        built = len(self._plans_seen) > n_before
        build_ms = (time.perf_counter() - tb) * 1e3 if built else 0.0
        out = plan.run(pipe.plate(frame, self.camera), cam)
        timings = dict(plan.last_timings)
        disp = fast_display_encode(out.color, cam.working_space, self.display)
        total = (time.perf_counter() - t0) * 1e3
        return Rendered(disp, out.color, quality, cam, plan.stage_names, timings, total, built, build_ms)

    def pinhole(self, index: int, camera: Camera) -> np.ndarray:
        """The input frame display-encoded with the camera's exposure gain (the B side of the A/B
        split): the pinhole image as the same camera would expose it, without lens or film."""
        frame = self.frame(index)
        pipe = Pipeline(camera, quality=DRAFT, stages=["exposure"], device=self.device) \
            if "pinhole" not in self._pipes else self._pipes["pinhole"]
        self._pipes["pinhole"] = pipe
        out = pipe.plan_for(frame, camera).run(frame, camera)
        return fast_display_encode(out.color, camera.working_space, self.display)

    def focus_at(self, index: int, x: float, y: float, radius: int = 3) -> float:
        """Tap to focus: the depth pass's median over a (2r+1)² window at pixel (x, y) of the
        displayed image (the frame's display window), metres (planar, as ``--focus``)."""
        frame = self.frame(index)
        if frame.depth is None:
            raise InputError(f"{self.input_label}: the frame has no depth pass, so a click cannot focus; "
                             "re-render with Z or set --focus")
        ox, oy = frame.windows.display_offset
        cx, cy = int(round(x)) + ox, int(round(y)) + oy
        d = frame.depth[max(cy - radius, 0):cy + radius + 1, max(cx - radius, 0):cx + radius + 1]
        d = d[np.isfinite(d) & (d > 0)]
        if d.size == 0:
            return math.inf
        return float(f"{float(np.median(d)):.4g}")

    # -- outputs: command line and camera track --------------------------------------------------
    def command(self, output: str = "out.####.exr") -> str:
        """The current settings as a ``clpost process`` command line."""
        from ..demo import process_flags

        flags = process_flags(self.camera)
        if flags.startswith("("):
            flags = ""
        q = "" if self.final_quality == "final" else f" --quality {self.final_quality}"
        return f"clpost process {self.input_label} -o {output}{q} {flags}".rstrip()

    def key_values(self) -> dict[str, str]:
        """The current camera as track values: every flag value that differs from Camera()'s, as
        the flag spells it (a track reads them exactly as the flag does)."""
        plain = Camera()
        out = {}
        for s in Camera.param_specs():
            if s.meta.flag is None or s.meta.input_only or s.name == "distortion":
                continue
            v = getattr(self.camera, s.name)
            if v != getattr(plain, s.name):
                out[s.meta.flag.lstrip("-")] = s.help_default(v)
        return out

    def add_key(self, index: int) -> None:
        self.keys[self.frame_numbers[index]] = self.key_values()

    def track_json(self, index: int) -> str:
        """The camera track (docs/camera-tracks.md): the keys added, or the current settings at this frame."""
        keys = self.keys or {self.frame_numbers[index]: self.key_values()}
        rows = [{"frame": f, **v} for f, v in sorted(keys.items())]
        return json.dumps({"comment": f"clpost view of {self.input_label}", "keys": rows}, indent=2) + "\n"

    def save_track(self, path: str | Path, index: int) -> Path:
        """Write the track atomically; refuses to replace a file (one line naming it)."""
        from ..atomic import atomic_path

        p = Path(path)
        if p.suffix.lower() != ".json":
            raise InputError(f"{p}: a camera track from the viewer is JSON; name a .json file")
        if p.exists():
            raise InputError(f"{p} exists; choose another name for the camera track")
        with atomic_path(p) as tmp:
            tmp.write_text(self.track_json(index))
        return p


# -- page pictures -------------------------------------------------------------------------------

LUT_SIZE = 1 << 16
"""Entries of the display-encoding table: steps of 1/65535 in linear light, so the table's 8-bit
codes differ from :func:`clpost.colorspace.display_encode`'s by at most one code value (where an
exact value sits on a rounding boundary; tested)."""


@functools.lru_cache(maxsize=8)
def _encoder(working_space: str, display: str) -> tuple[np.ndarray, np.ndarray]:
    """(3×3 working → display primaries matrix, uint8 table of the display's encoding), both from
    :mod:`clpost.colorspace` (the matrix is its linear map applied to the unit vectors)."""
    from ..colorspace import DISPLAYS, cctf_encode, quantise, working_to_display_linear

    m = np.asarray(working_to_display_linear(np.eye(3), working_space, display), np.float64).T
    lut = quantise(cctf_encode(np.linspace(0.0, 1.0, LUT_SIZE), DISPLAYS[display][1]), 8)
    return m.astype(np.float32), lut


def fast_display_encode(linear: np.ndarray, working_space: str = "rec709", display: str = "srgb") -> np.ndarray:
    """:func:`clpost.colorspace.display_encode` (8 bits) through a table: the page redraws every
    frame a slider moves, and colour-science's exact encoding costs ~0.1 s at 960×540 on the
    2-core box (this: a few ms)."""
    m, lut = _encoder(working_space, display)
    rgb = np.asarray(linear, np.float32)[..., :3]
    if not np.array_equal(m, np.eye(3, dtype=np.float32)):
        rgb = rgb @ m.T
    idx = np.clip(rgb * (LUT_SIZE - 1) + 0.5, 0, LUT_SIZE - 1).astype(np.uint16)
    return lut[idx]


def false_colour(linear: np.ndarray, working_space: str = "rec709") -> np.ndarray:
    """(H, W, 3) uint8 false-colour image of the output's stops from 18 % grey (:data:`FALSE_COLOUR_STOPS`)."""
    from ..colorspace import WORKING_SPACES, luminance

    stops = np.log2(np.maximum(luminance(linear, WORKING_SPACES[working_space]), 1e-9) / 0.18)
    out = np.zeros(linear.shape[:2] + (3,), np.uint8)
    for lo, hi, rgb in FALSE_COLOUR_STOPS:
        out[(stops >= lo) & (stops < hi)] = rgb
    return out


def zebras(display: np.ndarray, level: float = ZEBRA_LEVEL) -> np.ndarray:
    """The display image with diagonal black/white stripes where a channel is >= ``level``."""
    hot = display.max(axis=2) >= round(level * 255)
    h, w = hot.shape
    yy, xx = np.mgrid[0:h, 0:w]
    stripe = ((xx + yy) // 4) % 2 == 0
    out = display.copy()
    out[hot & stripe] = 0
    out[hot & ~stripe] = 255
    return out


def histogram(display: np.ndarray, size=(256, 100)) -> np.ndarray:
    """An RGB histogram picture (W × H uint8) of the display code values, each channel's counts
    scaled by the highest bin's square root (as cameras draw them: shadows stay visible)."""
    w, h = size
    out = np.full((h, w, 3), 24, np.uint8)
    sample = display[::2, ::2]  # every 4th pixel: the shape of the distribution, 4× sooner
    for c in range(3):
        counts = np.bincount(sample[..., c].ravel(), minlength=256).astype(np.float64)
        counts = np.interp(np.linspace(0, 255, w), np.arange(256), counts)
        scale = np.sqrt(counts) / max(np.sqrt(counts).max(), 1e-9)
        tops = (h - np.round(scale * (h - 2))).astype(int)
        rows = np.arange(h)[:, None]
        mask = rows >= tops[None, :]
        out[..., c] = np.where(mask, np.maximum(out[..., c], 200), out[..., c])
    return out


def ab_split(a: np.ndarray, b: np.ndarray, split: float) -> np.ndarray:
    """``a`` left of the split (0…1 of the width), ``b`` right of it, with a 1-px white line."""
    if split >= 1.0 or b.shape != a.shape:
        return a
    x = int(round(split * a.shape[1]))
    out = a.copy()
    out[:, x:] = b[:, x:]
    out[:, min(x, a.shape[1] - 1)] = 255
    return out


def data_url(img: np.ndarray, fmt: str = "JPEG", quality: int = 88) -> str:
    """A data URL of a uint8 image (JPEG for frames: ~5× faster to send than PNG; PNG for small plots)."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format=fmt, **({"quality": quality} if fmt == "JPEG" else {}))
    return f"data:image/{fmt.lower()};base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def lens_datasheet(camera: Camera) -> str | None:
    """The lens's datasheet plot (:func:`clpost.optics.report.plot_lens`) as a PNG data URL;
    None for a thin lens (no prescription) or without matplotlib."""
    if camera.optics is None:
        return None
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return None
    import tempfile

    from ..optics.report import plot_lens

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "lens.png"
        plot_lens(camera.lens, p, sensor_mm=camera.sensor_mm,
                  focus_distance_m=camera.focus_from_film_m)
        return "data:image/png;base64," + base64.b64encode(p.read_bytes()).decode("ascii")


DEMO_SIZE = (960, 540)
DEMO_FRAMES = 5


def open_input(pattern: str | None, camera: Camera, *, size=DEMO_SIZE, n_frames: int = DEMO_FRAMES,
               channels: str | None = None) -> tuple[list[int], Any, str]:
    """(frame numbers, loader ``i -> Frame``, label) of an input pattern or file, checked as
    ``clpost process`` checks it (one line, before anything runs); None: the built-in demo scene
    rendered at ``size`` (the first frame at once, so a broken renderer fails here)."""
    if pattern is None:
        from ..render import render_demo_sequence

        frames = render_demo_sequence(camera, size=size, n_frames=n_frames, camera_motion=True)
        return list(range(1, n_frames + 1)), lambda i: frames[i], "demo/render/demo.####.exr"
    from ..batch import read_input
    from ..outputs import check_input
    from ..sequence import expand, find_frames, has_pattern

    if has_pattern(pattern):
        numbers = find_frames(pattern)
        if not numbers:
            raise InputError(f"{pattern}: no input frames")
        paths = [Path(expand(pattern, n)) for n in numbers]
    else:
        check_input(Path(pattern))
        numbers, paths = [0], [Path(pattern)]
    pipe = Pipeline(camera, quality=DRAFT)

    def load(i: int) -> Frame:
        return read_input(pipe, paths[i], channels)

    load(0)  # a broken first file fails before the server starts
    return numbers, load, pattern
