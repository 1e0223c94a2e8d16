r"""Long exposure, exact: accumulate frames weighted by how long the shutter saw each of them.

A rendered frame n of a sequence at F frames per second stands for the scene during
:math:`I_n = [n/F, (n+1)/F)` (piecewise-constant in time, as the renderer produced it). A shutter
open during :math:`[T_0, T_1]` (anywhere, not only on frame boundaries) collects

.. math::

    H = \int_{T_0}^{T_1} E(t)\,dt = \sum_n w_n E_n, \qquad
    w_n = \big|I_n \cap [T_0, T_1]\big| = \max\!\big(0, \min(T_1, \tfrac{n+1}{F}) - \max(T_0, \tfrac{n}{F})\big)

which is *exact* for piecewise-constant input. Weights are computed in rational arithmetic
(:class:`fractions.Fraction`), so :math:`\sum_n w_n = T_1 - T_0` exactly. The output of
:func:`expose` is the time-averaged input :math:`\bar E = H / (T_1 - T_0)` (same units as a
frame: feed it to ``clpost process --shutter T1-T0`` and the exposure stage applies
:math:`H = \bar E\,t`); :attr:`ExposurePartial.seconds` is the exact open time.

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


def frame_interval(n: int, fps) -> tuple[Fraction, Fraction]:
    """The time interval [n/F, (n+1)/F) that frame ``n`` stands for (seconds, exact)."""
    f = as_rate(fps)
    if f <= 0:
        raise InputError(f"--fps {fps!r} must be > 0 frames per second, e.g. 24")
    return Fraction(n) / f, Fraction(n + 1) / f


def overlap(a0: Fraction, a1: Fraction, b0: Fraction, b1: Fraction) -> Fraction:
    """Length of [a0, a1] ∩ [b0, b1] (0 when they do not meet)."""
    return max(Fraction(0), min(a1, b1) - max(a0, b0))


def exposure_weights(frames, fps, t_open, t_close) -> dict[int, Fraction]:
    """Seconds of the shutter interval [t_open, t_close] that fall in each frame's interval;
    frames the shutter never sees are left out."""
    t0, t1 = as_time(t_open, "--open"), as_time(t_close, "--close")
    if not t1 > t0:
        raise InputError(f"--close {t_close} must be later than --open {t_open} (seconds)")
    out = {}
    for n in frames:
        a, b = frame_interval(int(n), fps)
        w = overlap(a, b, t0, t1)
        if w > 0:
            out[int(n)] = w
    return out


def frames_needed(fps, t_open, t_close) -> range:
    """Frame numbers whose intervals meet [t_open, t_close]."""
    f = as_rate(fps)
    t0, t1 = as_time(t_open, "--open"), as_time(t_close, "--close")
    first = math.floor(t0 * f)
    last = math.ceil(t1 * f) - 1
    return range(first, max(last, first) + 1)


@dataclass
class ExposurePartial:
    r"""A partial exposure: ``sum`` = :math:`\sum_k \tilde w_k E_k` (H×W×3 float64, weights in
    frames as applied in float32), ``applied`` = :math:`\sum_k \tilde w_k` (exact), ``seconds`` =
    the exact shutter time these frames cover, ``count`` frames."""

    sum: np.ndarray
    applied: Fraction
    seconds: Fraction
    count: int = 0

    def combine(self, other: "ExposurePartial") -> "ExposurePartial":
        """The partial of both sets of frames (associative and exact in the weights)."""
        if self.sum.shape != other.sum.shape:
            raise InputError(f"cannot combine exposures of shapes {self.sum.shape} and {other.sum.shape}")
        return ExposurePartial(self.sum + other.sum, self.applied + other.applied,
                               self.seconds + other.seconds, self.count + other.count)

    __add__ = combine

    def mean(self) -> np.ndarray:
        r"""Time-averaged input :math:`\bar E = H/(T_1-T_0)` (H×W×3 float32)."""
        if self.applied <= 0:
            raise InputError("the exposure received no frame inside the shutter interval; "
                             "check --open/--close against the frames' times (frame n spans [n/fps, (n+1)/fps))")
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


def exposure_plan(frames, fps, t_open, t_close) -> list[tuple[int, Fraction]]:
    """(frame, seconds) for every frame the shutter sees, in frame order.

    A frame of the interval missing from ``frames`` is an error (the exposure would silently be
    too dark otherwise).
    """
    frames = [int(n) for n in frames]
    weights = exposure_weights(frames, fps, t_open, t_close)
    t0, t1 = as_time(t_open, "--open"), as_time(t_close, "--close")
    needed = [n for n in frames_needed(fps, t_open, t_close) if overlap(*frame_interval(n, fps), t0, t1) > 0]
    missing = [n for n in needed if n not in weights]
    if missing:
        raise InputError(f"frames {missing[0]}…{missing[-1]} lie inside the shutter interval but are not in "
                         f"the sequence ({len(missing)} missing); render them or move --open/--close")
    return sorted(weights.items())


def expose(read, frames, fps, t_open, t_close, device: str | None = None,
           progress=None) -> ExposurePartial:
    """Accumulate ``read(n)`` (a :class:`~clpost.frame.Frame` or H×W×3 array) over the frames
    that the shutter [t_open, t_close] sees; returns the partial (``.mean()`` is the output).

    Only the frames with a non-zero weight are read; a frame of the interval missing from
    ``frames`` is an error (the exposure would silently be too dark otherwise).
    """
    weights = exposure_plan(frames, fps, t_open, t_close)
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
