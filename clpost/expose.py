r"""Long exposure, exact: integrate a sequence over the open shutter, through the camera.

**Temporal model (box filter).** A rendered frame n of a sequence at F frames per second stands
for the scene during its whole interval (piecewise-constant in time, as a renderer's frame
without motion blur does): with :math:`n_0` the sequence's first frame,

.. math::

    I_n = \Big[\frac{n - n_0}{F}, \frac{n - n_0 + 1}{F}\Big)

seconds after the sequence starts (:func:`frame_interval`; ``first`` = :math:`n_0`, 0 in the
library's default absolute timing, the first frame on disk in ``clpost expose``). A shutter open
during :math:`[T_0, T_1]` (anywhere, not only on frame boundaries) collects

.. math::

    H = \int_{T_0}^{T_1} E(t)\,dt = \sum_n w_n E_n, \qquad
    w_n = \big|I_n \cap [T_0, T_1]\big|

which is *exact* for piecewise-constant input: a frame cut by the shutter counts for the
fraction of its interval the shutter saw. Weights are computed in rational arithmetic
(:class:`fractions.Fraction`), so :math:`\sum_n w_n = T_1 - T_0` exactly. Times are seconds, or
frame numbers as timeline positions: ``f1001`` (or ``1001f``) is the *start* of frame 1001,
``f1001.5`` its middle (:func:`parse_instant`), so ``--open f1001 --close f1025`` is frames
1001…1024, 24 frames.

**Through the camera** (:func:`expose_camera_frames`). The exposure is one photograph with
shutter time :math:`t = T_1 - T_0`. The stages that act on light (input domain ``render`` or
``image``, :data:`PER_FRAME_DOMAINS`: DoF, aberrations, distortion, vignetting, white balance,
and the exposure stage's gain with shutter t) form the image at each instant, so they are applied
to each frame with that frame's own depth, and the outputs are averaged with weights
:math:`w_n / t` — exact for every such stage. (Summing first and applying a stage once would be
exact only for a stage additive in light and independent of the frame: vignetting, white balance
and exposure are, but DoF is not — its bright-edge depth fix compares a pixel with its
neighbours — so per frame is the one rule.) The stages that read the signal, densities, raw
values or a print (film, sensor, grain, print) are non-linear and respond to the total exposure
H, so they run **once**, on the accumulated signal — grain and sensor noise are drawn once, as on
a real negative. Hence a static scene exposed over :math:`[T_0, T_1]` is the frame processed with
``--shutter`` :math:`T_1 - T_0`. motion_blur (a velocity-buffer blur within a frame's shutter)
is not used by default: in the box model a frame is constant over its interval, so a light
moving faster than its size per frame leaves a dotted trail. ``motion_blur=True``
(``--motion-blur``) fills the interval from the frame's velocity pass instead: frame n is taken
as the scene at the middle of its interval moving with its velocity, and the motion_blur stage
blurs it over the part of the interval the shutter sees (:math:`w_n F` of a frame, centred on the
frame — exact in extent for whole frames; a frame cut by the shutter is blurred over the right
length but centred, so its streak is off by up to half the uncovered part). The stages up to
motion_blur run with that per-frame shutter (they do not read the shutter); those after it with
the exposure's.

Auto-exposure is metered once, on the first frame the shutter sees, with the exposure's shutter
time. **Alpha** of the result is the time-averaged coverage :math:`\sum_n w_n \alpha_n / t` (what
a camera would record of a matte over the exposure); **depth** is the nearest depth any seen
frame had at the pixel (per-pixel minimum: the surface a z-merge or a later DoF should treat as
present; a static scene keeps its depth). Velocity is dropped (the exposure already integrated
the motion).

Streaming: frames are added one at a time to a device buffer (Neumaier-compensated float32 sum
plus its compensation), so memory does not depend on the number of frames. Partial sums combine
exactly in their weights and to float64 in their sums (:meth:`ExposurePartial.combine`), so a
tree reduction (e.g. Dask) can split a sequence anywhere and get the same exposure.

References: Neumaier, A. (1974), "Rundungsfehleranalyse einiger Verfahren zur Summation endlicher
Summen", ZAMM 54; the accumulation-buffer technique (Haeberli & Akeley 1990, "The Accumulation
Buffer", SIGGRAPH) for motion blur from sub-frames.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from .errors import InputError


def as_time(value, name: str, what: str = "a time in seconds (e.g. 0.5 or 1/48)") -> Fraction:
    """A time in seconds (or, with ``what``, a rate) as an exact fraction (accepts ``'1/48'``,
    ``0.5``, ``Fraction``)."""
    try:
        if isinstance(value, str) and "/" in value:
            num, den = value.split("/", 1)
            t = Fraction(num.strip()) / Fraction(den.strip())
        else:
            t = Fraction(value) if not isinstance(value, float) else Fraction(str(value))
    except (ValueError, ZeroDivisionError, TypeError):
        raise InputError(f"{name}={value!r} is not {what}") from None
    return t


def as_rate(fps) -> Fraction:
    """A frame rate (frames per second) as an exact fraction, e.g. ``24`` or ``'24000/1001'``."""
    return as_time(fps, "--fps", "a frame rate in frames per second (e.g. 24 or 24000/1001)")


def frame_interval(n: int, fps, first: int = 0) -> tuple[Fraction, Fraction]:
    """The time interval [(n - first)/F, (n - first + 1)/F) that frame ``n`` stands for (seconds
    after the start of frame ``first``, exact)."""
    f = as_rate(fps)
    if f <= 0:
        raise InputError(f"--fps {fps!r} must be > 0 frames per second, e.g. 24")
    return Fraction(n - first) / f, Fraction(n - first + 1) / f


def overlap(a0: Fraction, a1: Fraction, b0: Fraction, b1: Fraction) -> Fraction:
    """Length of [a0, a1] ∩ [b0, b1] (0 when they do not meet)."""
    return max(Fraction(0), min(a1, b1) - max(a0, b0))


def exposure_weights(frames, fps, t_open, t_close, first: int = 0) -> dict[int, Fraction]:
    """Seconds of the shutter interval [t_open, t_close] that fall in each frame's interval;
    frames the shutter never sees are left out (``first``: see :func:`frame_interval`)."""
    t0, t1 = as_time(t_open, "--open"), as_time(t_close, "--close")
    if not t1 > t0:
        raise InputError(f"--close {t_close} must be later than --open {t_open} (seconds)")
    out = {}
    for n in frames:
        a, b = frame_interval(int(n), fps, first)
        w = overlap(a, b, t0, t1)
        if w > 0:
            out[int(n)] = w
    return out


def frames_needed(fps, t_open, t_close, first: int = 0) -> range:
    """Frame numbers whose intervals meet [t_open, t_close]."""
    f = as_rate(fps)
    t0, t1 = as_time(t_open, "--open"), as_time(t_close, "--close")
    lo = math.floor(t0 * f)
    hi = math.ceil(t1 * f) - 1
    return range(first + lo, first + max(hi, lo) + 1)


@dataclass
class ExposurePartial:
    r"""A partial exposure: ``sum`` = :math:`\sum_k \tilde w_k E_k` (H×W×3 float64, weights in
    frames as applied in float32), ``applied`` = :math:`\sum_k \tilde w_k` (exact), ``seconds`` =
    the exact shutter time these frames cover, ``count`` frames."""

    sum: np.ndarray
    applied: Fraction
    seconds: Fraction
    count: int = 0
    alpha: np.ndarray | None = None
    """Through the camera: the sum of w_k · alpha_k (seconds × coverage, float64), if the frames have alpha."""
    depth: np.ndarray | None = None
    """Through the camera: the per-pixel minimum depth of these frames, if they have depth."""
    plan: tuple = ()
    """Through the camera: the per-frame stages that ran on the first of these frames."""

    def combine(self, other: "ExposurePartial") -> "ExposurePartial":
        """The partial of both sets of frames (associative and exact in the weights)."""
        if self.sum.shape != other.sum.shape:
            raise InputError(f"cannot combine exposures of shapes {self.sum.shape} and {other.sum.shape}")
        if (self.alpha is None) != (other.alpha is None) or (self.depth is None) != (other.depth is None):
            raise InputError("cannot combine exposures of frames with and without alpha or depth; all frames "
                             "of an exposure need the same passes")
        alpha = None if self.alpha is None else self.alpha + other.alpha
        depth = None if self.depth is None else np.minimum(self.depth, other.depth)
        return ExposurePartial(self.sum + other.sum, self.applied + other.applied,
                               self.seconds + other.seconds, self.count + other.count, alpha, depth,
                               self.plan or other.plan)

    __add__ = combine

    def mean(self) -> np.ndarray:
        r"""Time-averaged input :math:`\bar E = H/(T_1-T_0)` (H×W×3 float32)."""
        if self.applied <= 0:
            raise InputError("the exposure received no frame inside the shutter interval; "
                             "check --open/--close against the frames' times")
        return (self.sum / float(self.applied)).astype(np.float32)

    def exposure(self) -> np.ndarray:
        r""":math:`H = \bar E\,(T_1 - T_0)` in input units × seconds (H×W×3 float32)."""
        return (self.sum / float(self.applied) * float(self.seconds)).astype(np.float32)


class ExposureAccumulator:
    """Device buffers for one long exposure at ``size`` = (width, height); add frames, read a partial."""

    def __init__(self, size: tuple[int, int], fps, device: str | None = None) -> None:
        import pyopencl as cl

        from .runtime import get_runtime, kernel_source

        self.width, self.height = (int(v) for v in size)
        self.fps = as_rate(fps)
        if self.fps <= 0:
            raise InputError(f"--fps {fps!r} must be > 0 frames per second, e.g. 24")
        self.rt = get_runtime(device)
        n3 = self.width * self.height * 3
        self._n3 = n3
        self._src = self.rt.empty((n3,))
        self._sum = self.rt.empty((n3,))
        self._comp = self.rt.empty((n3,))
        zero = np.zeros(n3, np.float32)
        cl.enqueue_copy(self.rt.queue, self._sum, zero)
        cl.enqueue_copy(self.rt.queue, self._comp, zero)
        self._kernel = self.rt.kernel(kernel_source("motion_blur_expose"), "motion_blur_expose")
        self.applied = Fraction(0)
        self.seconds = Fraction(0)
        self.count = 0
        self.events: list = []

    def add(self, color: np.ndarray, seconds) -> None:
        """Add a frame (H×W×3 linear) seen by the shutter for ``seconds`` (exact fraction)."""
        import pyopencl as cl

        c = np.ascontiguousarray(color, dtype=np.float32)
        if c.shape != (self.height, self.width, 3):
            size = f"{c.shape[1]}x{c.shape[0]}" if c.ndim == 3 else str(c.shape)
            raise InputError(f"size {size} differs from the exposure's {self.width}x{self.height} (its first "
                             "frame); all frames of an exposure need one size — re-render this frame at that "
                             "size or leave it out with --frames")
        sec = as_time(seconds, "seconds")
        w = np.float32(float(sec * self.fps))      # weight in frames, in [0, 1] for frame input
        q = self.rt.queue
        cl.enqueue_copy(q, self._src, c)
        self._kernel.set_args(self._src, self._sum, self._comp, w, np.int32(self._n3))
        self.events.append(cl.enqueue_nd_range_kernel(q, self._kernel, (self._n3,), None))
        self.applied += Fraction(float(w))
        self.seconds += sec
        self.count += 1

    def partial(self) -> ExposurePartial:
        import pyopencl as cl

        s = np.empty(self._n3, np.float32)
        c = np.empty(self._n3, np.float32)
        cl.enqueue_copy(self.rt.queue, s, self._sum)
        cl.enqueue_copy(self.rt.queue, c, self._comp, is_blocking=True)
        total = (s.astype(np.float64) + c.astype(np.float64)).reshape(self.height, self.width, 3)
        return ExposurePartial(total, self.applied, self.seconds, self.count)


def exposure_plan(frames, fps, t_open, t_close, first: int = 0) -> list[tuple[int, Fraction]]:
    """(frame, seconds) for every frame the shutter sees, in frame order.

    A frame of the interval missing from ``frames`` is an error (the exposure would silently be
    too dark otherwise).
    """
    frames = [int(n) for n in frames]
    weights = exposure_weights(frames, fps, t_open, t_close, first)
    t0, t1 = as_time(t_open, "--open"), as_time(t_close, "--close")
    needed = [n for n in frames_needed(fps, t_open, t_close, first)
              if overlap(*frame_interval(n, fps, first), t0, t1) > 0]
    missing = [n for n in needed if n not in weights]
    if missing:
        have = f"; the sequence has frames {min(frames)}…{max(frames)}" if frames else ""
        raise InputError(f"frames {missing[0]}…{missing[-1]} lie inside the shutter interval but are not in "
                         f"the sequence ({len(missing)} missing{have}); render them or move --open/--close")
    return sorted(weights.items())


def expose(read, frames, fps, t_open, t_close, device: str | None = None,
           progress=None, first: int = 0) -> ExposurePartial:
    """Accumulate ``read(n)`` (a :class:`~clpost.frame.Frame` or H×W×3 array) over the frames
    that the shutter [t_open, t_close] sees; returns the partial (``.mean()`` is the output).

    Only the frames with a non-zero weight are read; a frame of the interval missing from
    ``frames`` is an error (the exposure would silently be too dark otherwise).
    """
    weights = exposure_plan(frames, fps, t_open, t_close, first)
    acc = None
    for n, w in weights:
        frame = read(n)
        img = getattr(frame, "color", frame)
        if acc is None:
            acc = ExposureAccumulator((img.shape[1], img.shape[0]), fps, device)
        try:
            acc.add(img, w)
        except InputError as exc:
            src = getattr(frame, "metadata", {}).get("path") or f"frame {n}"
            raise InputError(f"{src}: {exc}") from None
        if progress:
            progress(n, w)
    if acc is None:
        raise InputError("no frame lies inside the shutter interval")
    return acc.partial()


# -- times as the command line spells them -------------------------------------------------------

_FRAME_TIME = re.compile(r"^\s*(?:f\s*([+-]?\d+(?:\.\d+)?)|([+-]?\d+(?:\.\d+)?)\s*f)\s*$", re.IGNORECASE)


def parse_instant(text, fps, first: int, name: str) -> Fraction:
    """A shutter time as seconds after the start of frame ``first``: seconds (``0.5``, ``1/48``)
    or a frame number as a timeline position, ``f1001`` / ``1001f`` = the start of frame 1001,
    ``f1001.5`` its middle (exact fractions)."""
    m = _FRAME_TIME.match(str(text))
    if m is None:
        return as_time(text, name, "seconds (e.g. 0.5 or 1/48) or a frame number (e.g. f1001 or 1001f)")
    frame = Fraction(m[1] or m[2])
    return (frame - first) / as_rate(fps)


def capture_rate(path) -> Fraction | None:
    """The OpenEXR standard ``captureRate`` attribute of ``path`` (frames per second), None if absent."""
    import OpenEXR

    try:
        value = OpenEXR.File(str(path), header_only=True).header().get("captureRate")
    except Exception:  # unreadable here: read_frame reports the file's problem in one line later
        return None
    if value is None:
        return None
    try:
        if isinstance(value, Fraction):
            rate = value
        elif np.ndim(value) == 1 and len(value) == 2:          # written as (numerator, denominator)
            rate = Fraction(int(value[0]), int(value[1]))
        else:
            rate = Fraction(str(float(value)))
    except (ValueError, ZeroDivisionError, TypeError):
        return None
    return rate if rate > 0 else None


# -- the exposure through the camera --------------------------------------------------------------

PER_FRAME_DOMAINS = ("render", "image")
"""Input domains (:data:`clpost.stages.DOMAINS`) of the stages applied to each frame before the
sum: scene-linear light, the image formed at each instant. A stage reading any other domain
(signal, density, raw, print) runs once on the accumulated exposure (module docstring)."""


def registry_order() -> dict[str, float]:
    """Each stage's place in the physical order (``Stage.order``)."""
    from .stages import registry

    return {name: cls.order for name, cls in registry().items()}


def split_stages(names) -> tuple[list[str], list[str]]:
    """(per-frame stages, once-on-the-sum stages) of stage ``names`` by their input domain."""
    from .stages import registry

    reg = registry()
    per_frame = [n for n in names if reg[n].domains[0] in PER_FRAME_DOMAINS]
    once = [n for n in names if reg[n].domains[0] not in PER_FRAME_DOMAINS]
    return per_frame, once


def exposure_camera(camera, seconds):
    """The camera of one photograph with the shutter open ``seconds``: its shutter is the open
    interval; no per-frame motion blur (box model, module docstring)."""
    if camera.readout_time_s > 0:
        raise InputError("--readout (rolling shutter) is not modelled by a long exposure; leave it out")
    return camera.with_(shutter_s=float(seconds), frame_rate_fps=None)


@dataclass
class Exposed:
    """A long exposure through the camera: ``frame`` (the camera's output; depth and alpha as in
    the module docstring), ``camera`` (the resolved camera: shutter = the open time), the exact
    open time ``seconds``, the frames seen with their seconds, and the stages run per frame and once."""

    frame: object
    camera: object
    seconds: Fraction
    weights: list
    per_frame: list
    once: list


@dataclass(frozen=True)
class CameraSetup:
    """What every frame of one exposure goes through: the resolved camera (shutter = the open
    time), the stages run per frame (``blurred``: those up to motion_blur, run with the frame's
    seen part of its interval as shutter) and once, quality and device. Picklable (a Dask task
    argument)."""

    camera: object
    fps: Fraction
    per_frame: tuple
    blurred: tuple
    once: tuple
    quality: str = "final"
    device: str | None = None


def prepare(frame0, camera, seconds, fps, *, quality: str = "final", stages=None, device: str | None = None,
            motion_blur: bool = False) -> CameraSetup:
    """Resolve the exposure's camera on its first frame (auto-exposure metered once, with the
    open time as shutter) and split the stages; refuses what ``clpost process`` would refuse."""
    from .pipeline import Pipeline

    cam = exposure_camera(camera, seconds)
    whole = Pipeline(cam, quality=quality, stages=stages, device=device)
    frame0 = whole.plate(frame0, cam)  # --plate-fov infinity: metered as the focused camera sees it
    cam = whole.camera_for(frame0)
    entries = whole.explain(frame0, cam, reasons=False)
    per_frame, once = split_stages([e.stage for e in entries if stages is None or e.stage in stages])
    blurred = []
    if motion_blur:
        src = frame0.metadata.get("path") or "the first frame"
        if "motion_blur" not in per_frame:
            raise InputError("--motion-blur: the motion_blur stage is not selected by --stages; add it")
        if frame0.velocity is None:
            raise InputError(f"{src}: --motion-blur needs a velocity pass and the frame has none; re-render "
                             "with one (Blender: Vector) or leave out --motion-blur")
        order = registry_order()
        blurred = [s for s in per_frame if order[s] <= order["motion_blur"]]
    return CameraSetup(cam, as_rate(fps), tuple(per_frame), tuple(blurred), tuple(once), quality, device)


class CameraAccumulator:
    """The per-frame optics of :class:`CameraSetup` and the accumulation of their outputs (colour
    on the device, alpha and depth on the host) for one exposure or one chunk of it."""

    def __init__(self, setup: CameraSetup) -> None:
        from .pipeline import Pipeline

        self.setup = setup
        q, dev = setup.quality, setup.device
        self._early = Pipeline(setup.camera, quality=q, stages=list(setup.blurred), device=dev)
        self._lin = Pipeline(setup.camera, quality=q, stages=[s for s in setup.per_frame if s not in setup.blurred],
                             device=dev)
        self._acc = self._alpha = self._depth = self._head = None

    def add(self, frame, n: int, seconds: Fraction) -> None:
        """Frame ``n`` (a :class:`~clpost.frame.Frame`) seen by the shutter for ``seconds``."""
        cam, rate = self.setup.camera, self.setup.fps
        src = frame.metadata.get("path") or f"frame {n}"
        frame = frame.replace(metadata=dict(frame.metadata, frame_index=int(n)), validate=False)
        frame = self._lin.plate(frame, cam)  # --plate-fov infinity: magnified as the lens breathes
        plan = []
        if self.setup.blurred:  # the seen part of the interval, w·F of a frame (fps structural, shutter scalar)
            if frame.velocity is None:
                raise InputError(f"{src}: --motion-blur needs a velocity pass and this frame has none; re-render it")
            cam_n = cam.with_(frame_rate_fps=float(rate), shutter_s=float(min(seconds, 1 / rate)))
            frame = self._early.plan_for(frame, cam_n).run(frame, cam_n)
            plan = list(frame.metadata.get("plan", []))
        out = self._lin.plan_for(frame, cam).run(frame, cam)
        if self._acc is None:
            self._acc = ExposureAccumulator(out.size, rate, self.setup.device)
            self._head = (out.alpha is not None, out.depth is not None, tuple(plan + list(out.metadata.get("plan", []))))
        try:
            self._acc.add(out.color, seconds)
        except InputError as exc:
            raise InputError(f"{src}: {exc}") from None
        if (out.alpha is not None, out.depth is not None) != self._head[:2]:
            raise InputError(f"{src}: has {'no ' if out.alpha is None else ''}alpha and "
                             f"{'no ' if out.depth is None else ''}depth unlike the exposure's first frame; "
                             "all frames of an exposure need the same passes — re-render it")
        if out.alpha is not None:
            a = out.alpha.astype(np.float64) * float(seconds)
            self._alpha = a if self._alpha is None else self._alpha + a
        if out.depth is not None:
            self._depth = out.depth.copy() if self._depth is None else np.minimum(self._depth, out.depth)

    def partial(self) -> ExposurePartial:
        if self._acc is None:
            raise InputError("no frame lies inside the shutter interval")
        part = self._acc.partial()
        part.alpha, part.depth, part.plan = self._alpha, self._depth, self._head[2]
        return part


def finish(part: ExposurePartial, setup: CameraSetup, first_seen: int, metadata: dict):
    """The accumulated signal as a Frame (alpha: time-averaged coverage, depth: nearest seen)
    through the stages that run once (film, sensor, grain, print), seeded by ``first_seen``."""
    from .frame import Frame
    from .pipeline import Pipeline

    cam = setup.camera
    alpha = None if part.alpha is None else np.clip(part.alpha / float(part.seconds), 0.0, 1.0).astype(np.float32)
    meta = {k: v for k, v in metadata.items() if k not in ("camera", "plan")}
    summed = Frame(part.mean(), depth=part.depth, alpha=alpha, metadata=dict(meta, frame_index=int(first_seen)))
    if setup.once:
        rest = Pipeline(cam, quality=setup.quality, stages=list(setup.once), device=setup.device,
                        already_applied=setup.per_frame)
        result = rest.plan_for(summed, cam).run(summed, cam)
        later = list(result.metadata.get("plan", []))
    else:
        result, later = summed, []
    return result.replace(metadata=dict(result.metadata, camera=cam.describe(), plan=list(part.plan) + later),
                          validate=False)


def expose_camera_frames(read, frames, fps, t_open, t_close, camera, *, first: int = 0, quality: str = "final",
                         stages=None, device: str | None = None, progress=None,
                         motion_blur: bool = False) -> Exposed:
    """Expose ``read(n)`` (a :class:`~clpost.frame.Frame`) over [t_open, t_close] through
    ``camera`` (its shutter replaced by the open time): the optics per frame, the film/sensor
    once on the accumulated signal (module docstring). ``stages`` restricts the stages as
    ``--stages`` does; ``first`` is the sequence's first frame (time origin); ``motion_blur``
    blurs each frame along its velocity pass over the part of its interval the shutter sees."""
    weights = exposure_plan(frames, fps, t_open, t_close, first)
    if not weights:
        raise InputError("no frame lies inside the shutter interval")
    seconds = sum((w for _, w in weights), Fraction(0))
    first_seen = weights[0][0]
    frame0 = read(first_seen)
    setup = prepare(frame0, camera, seconds, fps, quality=quality, stages=stages, device=device,
                    motion_blur=motion_blur)
    acc = CameraAccumulator(setup)
    for n, w in weights:
        acc.add(frame0 if n == first_seen else read(n), n, w)
        if progress:
            progress(n, w)
    result = finish(acc.partial(), setup, first_seen, frame0.metadata)
    return Exposed(result, setup.camera, seconds, weights, list(setup.per_frame), list(setup.once))
