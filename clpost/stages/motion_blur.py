r"""motion_blur: integration over the shutter from a velocity buffer, and a rolling shutter.

**Shutter fraction.** Velocities are forward motion in px per frame (CONVENTIONS.md). The shutter
is open for :math:`s = t_{shutter} \cdot F` of a frame interval (``Camera.shutter_s`` ×
``Camera.frame_rate_fps``; a shutter angle θ gives :math:`t = \theta / (360° F)`, see
:func:`shutter_from_angle` — 180° at 24 fps is 1/48 s, the same ``shutter_s`` the exposure stage
uses, so blur and brightness always agree). The shutter interval is centred on the frame time, so a
pixel moving with velocity v sweeps the segment :math:`p + v\,\tau`, :math:`\tau \in [-s/2, s/2]`,
whose half-vector is

.. math::

    h = v\,\frac{s}{2}, \qquad |h| \le K

**Reconstruction filter**, a gather after McGuire, Hennessy, Bukowski, Osman 2012 ("A
Reconstruction Filter for Plausible Motion Blur", I3D) with Guertin, McGuire, Nowrouzezahrai 2014
("A Fast and Stable Feature-Aware Motion Blur Filter", HPG: taps along the pixel's own motion as
well) and coverage weights instead of McGuire's cones: the image is cut in K×K tiles; TileMax
holds each tile's longest h (ranked by the unclamped length, first in scan order on ties) and
NeighborMax the longest of its 3×3 tiles, :math:`v_N`, so a fast object blurs over a static
background *and* a static pixel receives the smear of a neighbour.

*Fringe rule* (renderer input): renderers average the vector pass over the pixel filter
but point-sample depth, so an anti-aliased edge pixel carries a fraction of the moving surface's
velocity and often the background's depth. A pixel whose speed exceeds FRINGE = 0.1 × the fastest
of its 3×3 neighbours (edge-clamped, first in scan order on ties) takes that neighbour's velocity
and depth: its colour is (partly) that surface's, and spreads with it.

*Taps.* S taps along two directions: even i along :math:`v_N`, odd i along X's own half-vector
:math:`h_X` (for a still X, :math:`|h_X| \le 0.5`: the neighbourhood's *second direction* where it has
one, else :math:`v_N`), stratified over the whole path, which reaches
FOOT = ½ px beyond the vector — :math:`d_i = \hat v\,(|v| + \tfrac12)` for v = :math:`v_N` or
:math:`h_X` (a surface pixel swept over ±|h| overlaps its neighbours partly up to half a pixel
further: its footprint),

.. math::

    Y_i = \Big\lfloor X + d_i\,t_i + \tfrac12 \Big\rfloor, \quad t_i = -1 + 2\,\frac{i + \tfrac12 + j}{S},
    \quad i \ne \tfrac{S-1}{2}, \qquad S = \min\big(C,\ 2\lceil D\,|v_N| \rceil + 1\big)

with the per-pixel jitter :math:`j = \mathrm{frac}(j_0 + \mathrm{frac}(a_1 x) + \mathrm{frac}(a_2 y)) - \tfrac12`:
:math:`j_0 \in [0, 1)` from a counter-based hash of (seed, frame index) (CONVENTIONS "Randomness"),
:math:`(a_1, a_2)` the R2 lattice (Roberts 2018, "The unreasonable effectiveness of quasirandom
sequences": :math:`1/\varphi_2, 1/\varphi_2^2`, :math:`\varphi_2` the plastic number), so neighbouring pixels
take well-spread strata and the few taps' noise is fine-grained (a per-pixel hash gave clumps of
equal strata); the centre stratum is X itself. C is the frame's cap: the quality's tap count
:math:`S_q` times the share of tiles that run the gather at all (:math:`|v_N| > ½` px), rounded down
to odd, within :math:`[S_q, S_{max}]` — a frame whose motion covers few tiles spends the taps its
still tiles leave on its moving ones, never costing more than a frame moving everywhere at
:math:`S_q` (where every tile moves, C = :math:`S_q`); a slower neighbourhood takes fewer: the S strata of the path :math:`2|v_N|` are
then at most 1/D px apart (D = DENSITY = 1.5), so more taps would only resample the same pixels (a
frame's cost follows its motion; the choice of D: ``docs/motion_blur.md``).

*Second direction* (a still pixel between two movers): TileMax also keeps the inverse depth of
each tile's maximum; NeighborMax the longest of its 3×3 tiles' maxima whose direction differs from
:math:`v_N` (cos < AGREE0, tested as :math:`a\cdot b < 0` or :math:`(a\cdot b)^2 <` DIFFER2
:math:`|a|^2|b|^2`), kept only if
faster than ½ px and its surface is not level with :math:`v_N`'s (inverse depths apart by more than
SOFT_Z/2 relative: another surface moving another way, not one spinning surface). Without it a
still pixel whose tiles' :math:`v_N` belongs to a faster mover never looks along a slower one
(the wall ahead of the Cycles motion scene's cube, next to the ball: docs/motion_blur.md). Both tap
sets then gather the front layer at weight 2 (each estimates what reaches X along its direction;
the own layer as where the sets agree) and the nearer set's front (by the candidates' inverse
depths) is composited over the farther's: :math:`c_F = c_n + (1 - c_n) c_f`,
:math:`c_F F = c_n F_n + (1 - c_n) c_f F_f` (:math:`c_n, c_f` clamped to 1).

*Coverage.* A surface Y moving with half-vector :math:`h_Y` passes over X, |X − Y| = d, for the
fraction :math:`\delta_i / (2|h_Y|)` of the shutter per tap (:math:`\delta_i = 2|d_i|/S` the path
length a tap stands for; cylinder cyl(d, l) = 1 − smoothstep(l − ½, l + ½, d) limits it to Y's
streak, ramping over the swept pixel's footprint; its integral over d stays 2l). With f = "Y in front of X", b = "X in front of Y" by a soft depth test on inverse depth
(ramp over 5 % relative depth, the sky's inverse depth 0) and :math:`a_i = \mathrm{cyl}(d,
|h_Y|)\,\delta_i / (2|h_Y|)`, :math:`o_i = b\,\mathrm{cyl}(d, |h_X|)` ("level with X and on X's
own path"), three layers are gathered:

- in front of X (or level but off X's path, e.g. a light sliding over a wall at its depth):
  :math:`c_F = \sum f(1-o_i)\,\ell_i\,a_i\,g_i^F`, colour F = their weighted mean; a surface in front
  reaches X only along its own motion line, give or take its footprint and a spinning object's
  spread of directions: :math:`\ell_i = \mathrm{clamp}(L + \tfrac12 - |d \times \hat h_Y|, 0, 1)`,
  L = LINE = 2 px (the cylinder alone is isotropic: a fast neighbour's streak would reach X from any
  side, e.g. a sliding cube's smear onto the static wall below it);
- X's own surface along its path: :math:`c_O = w_c + \sum f\,o_i\,a_i\,g_i^O` with X itself at
  :math:`w_c = \max(\bar\delta, 1) / (2|h_X|)` (its footprint: the centre stratum's path, at least
  the pixel; a static pixel is its own surface all the time), colour O = weighted mean (a box for
  uniform motion). Its coverage is the *share* of X's path that X's surface holds,
  :math:`\bar c_O = \min(c_O / A_O, 1)` with :math:`A_O = w_c + \sum \mathrm{cyl}(d, |h_X|)^2\,
  \delta_i / (2|h_X|)\,g_i^O` — what :math:`c_O` would be if every tap were X's own surface (Y = X,
  f = b = 1): a ratio estimator, so the taps' rounding to pixels and the cylinder's steps at the
  path's ends cancel. The absolute sum :math:`\min(c_O, 1)` scatters around 1 inside a surface
  moving as one and let the background through wherever it fell short (docs/motion_blur.md, "The
  own layer's coverage as a share of X's path");
- behind X (revealed as X's surface moves away): weights :math:`b\,\big((1-f) + f\,(1 -
  \mathrm{cyl}(d, |h_Y|))\big)\,\mathrm{cyl}(d, |h_X|) / \max(d, 1)^2` (surfaces behind X, or level
  with it whose streak misses X; inverse-square in the distance: what X hides looks most like the
  background right next to it, not like the mean of its whole path), colour B (X itself at weight
  10⁻³ when there is none);

.. math::

    C'(X) = \bar c_F F + (1 - \bar c_F)\big(\bar c_O O + (1 - \bar c_O) B\big),
    \qquad \bar c_F = \min(c_F, 1)

|h| clamped to ≥ 0.5 px; a tap reads Y's as one word (:func:`tap_records`): :math:`\max(|h_Y|, ½)` as a float
with a 10-bit mantissa (relative step 2⁻¹⁰) and the direction :math:`\hat h_Y` in steps of 1/127 (< 0.2 px
across the 21 px a tap reaches). Where :math:`h_X` leaves :math:`v_N`'s direction (agreement g =
clamp((cos∠ − 0.8)/0.15, 0, 1)) the tap sets split the work: odd taps carry X's own surface
(:math:`g^O = g + 2(1-g)`, :math:`g^F = g`), even taps what is in front (:math:`g^F = g +
2(1-g)`, :math:`g^O = g`). If :math:`|v_N| \le 0.5` px the pixel is left exactly as it is —
hence the stage is *not planned* when no pixel's half-vector reaches 0.5 px (skipped ⇔ identity).

**Quality** sets :math:`S_q` (the most taps per pixel; measured error and cost in
``docs/motion_blur.md``): draft 5, preview 11, final 23, and :math:`S_{max}` (the frame cap's bound)
draft 19, preview 23, final 23. K = 20 px for all levels.

**Clamping.** :math:`|h|` is limited to K = 20 px (a streak of at most 40 px, i.e. 2K) keeping
its direction: faster motion blurs as if it moved 2K px during the exposure, so its streak is
too short and too bright at each end rather than wrong in direction; the colour is still a
weighted mean of input colours (no energy is created). Velocities up to FLT_MAX are safe (the
length is computed after scaling by the inf-norm).

**Rolling shutter** (``Camera.readout_time_s`` = r seconds from the top row to the bottom row):
row y is exposed :math:`\tau_y = rF\,(y/(H-1) - \tfrac12)` frames after the frame time (the
middle row stays in place), so it shows the surface that moved there. After the blur the image is
warped by :math:`q = p - v(q)\,\tau_y` (three fixed-point steps, v at the nearest pixel of q,
bilinear colour, clamped to the image). Exact for rigid translation; occlusions revealed by the
motion are not invented (the reference renders them, see :mod:`clpost.render.motion`).

Domain/range: any finite colour ≥ 0 → convex combinations of input colours (≥ 0, ≤ max input).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import random as rnd
from ..errors import InputError
from ..params import at_least, param, parse_fraction, positive
from .base import GatherStage


@dataclass(frozen=True)
class MotionBlurParams:
    """motion_blur: the frame rate turns px-per-frame velocities into a blur over the shutter
    (fraction shutter_s × fps); None (default) leaves motion blur unmodelled."""

    frame_rate_fps: float | None = param(
        None, unit="frames per second", flag="--fps", parse=parse_fraction, scalar=False, header="clpost.fps",
        check=positive("frames per second", "e.g. 24", optional=True),
        help="frame rate of the sequence (enables motion blur: shutter × fps of a frame)")
    shutter_angle_deg: float | None = param(
        None, unit="degrees", flag="--shutter-angle", parse=parse_fraction, scalar=True, input_only=True,
        help="rotary shutter angle in degrees (needs --fps; sets the shutter: 180° at 24 fps = 1/48 s)")
    readout_time_s: float = param(
        0.0, unit="seconds", flag="--readout", parse=parse_fraction, scalar=True, header="clpost.readout_s",
        check=at_least(0.0, "seconds", "e.g. 0.01 for a 10 ms sensor readout", "0 = global shutter"),
        help="rolling-shutter readout time from the top to the bottom row in seconds (needs --fps; 0: global)")

    @staticmethod
    def validate(camera, inputs):
        fps = camera.frame_rate_fps
        angle = inputs.get("shutter_angle_deg")
        if angle is not None:  # a shutter angle is a shutter time at a frame rate
            if fps is None:
                raise InputError(f"Camera.shutter_angle_deg={angle!r} needs Camera.frame_rate_fps (--fps): "
                                 "the shutter time is angle / (360° × fps)")
            object.__setattr__(camera, "shutter_s", shutter_from_angle(angle, fps))
        if camera.readout_time_s > 0 and fps is None:
            raise InputError("Camera.readout_time_s > 0 needs Camera.frame_rate_fps (--fps) to turn "
                             "px-per-frame velocities into a per-row shift")
        if fps is not None and camera.shutter_s is not None and camera.shutter_s * fps > 1.0 + 1e-9:
            raise InputError(f"Camera.shutter_s={camera.shutter_s:g} s is longer than one frame interval at "
                             f"{fps:g} fps (a 360° shutter is {1 / fps:.4g} s); "
                             "use a shorter --shutter or --shutter-angle <= 360")


TILE = 20
"""K: tile size and the largest blur half-length in px."""
SAMPLES = {"draft": 5, "preview": 11, "final": 23}
"""S per quality level (odd: the centre stratum is the pixel itself); fewer than the 7/15/31 taps
of the filter it replaced, to keep its cost (what each level costs: docs/motion_blur.md)."""
SAMPLES_MAX = {"draft": 19, "preview": 23, "final": 23}
"""The most taps per pixel (odd) when the frame's moving tiles leave budget (module docstring, "Taps")."""
DENSITY = 1.5
"""Taps per px of |v_N|: a pixel takes S = min(S_q, 2⌈DENSITY |v_N|⌉ + 1) taps (module docstring)."""
SEED = 0x6D62  # "mb": the jitter's hash seed, fixed so output is reproducible
SOFT_Z = 0.05
FOOT = 0.5
"""Half a pixel: a surface pixel swept over ±|h| overlaps a pixel partly up to FOOT beyond |h|, so
the tap paths reach |v| + FOOT and the cylinders ramp over |h| ± FOOT (module docstring)."""
FRINGE = 0.1
"""A pixel faster than FRINGE × its fastest 3×3 neighbour takes that neighbour's motion (fringe rule)."""
LINE = 2.0
"""A surface in front of X reaches X only within LINE ± ½ px of its own motion line (module docstring)."""
DIR = 127.0
"""Steps of the unit direction in the record a tap reads of Y (a signed byte per component: :func:`tap_records`)."""
JITTER_R2 = (0.7548776662, 0.5698402910)
"""The R2 lattice's steps per pixel in x and y (Roberts 2018, the plastic number's 1/φ₂, 1/φ₂²)."""
AGREE0, AGREE1 = 0.8, 0.95
"""cos(angle) between v_N and X's own half-vector below which the two tap sets split the work."""
DIFFER2 = AGREE0 * AGREE0
"""A neighbourhood's second direction differs from v_N by more than acos(AGREE0): the test in squares
(:func:`_differs32`; the kernels' MOTION_BLUR_DIFFER2, :func:`_model_defines`)."""


def shutter_from_angle(angle_deg: float, fps: float) -> float:
    r"""Shutter time of a rotary shutter: :math:`t = \theta / (360° \cdot F)` seconds."""
    a, f = float(angle_deg), float(fps)
    if not (math.isfinite(a) and 0 < a <= 360):
        raise InputError(f"--shutter-angle {angle_deg!r} must be in (0, 360] degrees, e.g. 180")
    if not (math.isfinite(f) and f > 0):
        raise InputError(f"--fps {fps!r} must be > 0 frames per second, e.g. 24")
    return a / (360.0 * f)


def shutter_fraction(camera) -> float:
    """Open fraction of a frame interval, s = shutter_s × frame_rate_fps (0 without a frame rate)."""
    if camera.frame_rate_fps is None or camera.shutter_s is None:
        return 0.0
    return float(camera.shutter_s) * float(camera.frame_rate_fps)




def _max_speed_bound(frame) -> float:
    """An upper bound of max |v| (px/frame): √2 × the inf-norm (cheap; never under-estimates)."""
    if frame.velocity is None:
        return math.inf
    return math.sqrt(2.0) * frame.velocity_max


def _blur_needed(camera, frame) -> bool:
    return _max_speed_bound(frame) * shutter_fraction(camera) / 2.0 > 0.5


def _rolling_needed(camera, frame) -> bool:
    return camera.readout_time_s > 0 and frame.height > 1 and _max_speed_bound(frame) > 0


class MotionBlur(GatherStage):
    name = "motion_blur"
    order = 40.0
    role = "integration over the shutter; velocity is in undistorted pixel space"
    domains = ("render", "render")
    params = MotionBlurParams
    example = {"frame_rate_fps": 24.0}  # a non-default value (tests/test_params.py)
    reads = ("velocity", "depth")
    turn_off = "leave out --fps/--shutter-angle/--readout (no motion blur)"

    def __init__(self, quality: str = "final") -> None:
        super().__init__(quality)

    @property
    def samples(self) -> int:
        return SAMPLES[self.quality]

    def skip_reason(self, camera, frame):
        if camera.frame_rate_fps is None:
            return "no frame rate (Camera.frame_rate_fps / --fps): velocities in px per frame need it"
        if frame.velocity is None:
            return None  # needed: the planner asks for the velocity buffer
        if not _blur_needed(camera, frame) and not _rolling_needed(camera, frame):
            return (f"no blur: largest half-length ≤ {_max_speed_bound(frame) * shutter_fraction(camera) / 2:.3g} px "
                    f"(< 0.5 px) at shutter fraction {shutter_fraction(camera):.3g}, global shutter")
        return None

    def reason_needed(self, camera, frame):
        s = shutter_fraction(camera)
        out = (f"shutter {camera.shutter_s:.4g} s at {camera.frame_rate_fps:g} fps = {s:.3g} frame, "
               f"blur up to {min(_max_speed_bound(frame) * s, 2 * TILE):.3g} px, {self.samples} taps")
        if camera.readout_time_s > 0:
            out += f", rolling readout {camera.readout_time_s:g} s"
        return out

    def defines(self, camera):
        return {"MOTION_BLUR_TILE": TILE, "MOTION_BLUR_SAMPLES": self.samples,
                "MOTION_BLUR_SAMPLES_MAX": SAMPLES_MAX[self.quality],
                "MOTION_BLUR_DENSITY": f"{DENSITY!r}f", **_model_defines()}

    def taps_per_pixel(self, camera, frame) -> int:
        """Colour samples per output pixel, all channels: the centre plus at most ``samples`` taps
        (``clpost bench`` taps/s, an upper bound: slow tiles take fewer; each tap also reads the
        tap's half-vector and depth)."""
        return 3 * (self.samples + 1)

    # -- OpenCL -----------------------------------------------------------------------------
    @staticmethod
    def lanes(rt) -> int:
        """Pixels per work-item of the prep and the gather: 16 on a CPU (explicit float16 rows),
        1 on a GPU (:attr:`clpost.runtime.Runtime.wide`; kernels/motion_blur.cl MOTION_BLUR_LANES)."""
        return 16 if rt.wide else 1

    def _kernel(self, rt, camera, name):
        lanes = self.lanes(rt)
        return rt.kernel(_program_source(lanes), name, {**self.defines(camera), "MOTION_BLUR_LANES": lanes},
                         "motion_blur")

    def _row_launch(self, rt, w, h):
        """(global, local) of the per-pixel kernels: 16 pixels of a row per work-item in 8×1 groups
        (CPU), or one pixel per work-item in 32×4 groups (GPU: a warp reads a row's 32 pixels)."""
        if self.lanes(rt) == 16:
            return (-(-w // 16), h), (8, 1)
        return (w, h), (32, 4)

    def _buffers(self, rt, w, h):
        tw, th = -(-w // TILE), -(-h // TILE)
        return dict(hv=rt.scratch(self, "hv", (4, h, w)), iz=rt.scratch(self, "iz", (h, w)),
                    tile=rt.scratch(self, "tile", (4, th, tw)), nmax=rt.scratch(self, "nmax", (5, th, tw)),
                    cap=rt.scratch(self, "cap", (1,), np.int32),
                    tmp=rt.scratch(self, "tmp", (3, h, w)), tw=tw, th=th)

    def replay_key(self, camera, frame):
        # the noise hash takes the frame index; which passes run depends on the frame's velocities
        return (super().replay_key(camera, frame), frame.index, _blur_needed(camera, frame),
                _rolling_needed(camera, frame))

    def enqueue(self, rt, camera, frame, src, dst, aux):
        w, h = frame.width, frame.height
        b = self._buffers(rt, w, h)
        tw, th = b["tw"], b["th"]
        blur, rolling = _blur_needed(camera, frame), _rolling_needed(camera, frame)
        events = []
        blur_dst = b["tmp"] if rolling else dst
        if blur:
            k = self._kernel(rt, camera, "motion_blur_prep")
            k.set_args(aux["velocity"], aux["depth"], b["hv"], b["iz"], np.int32(w), np.int32(h),
                       np.float32(shutter_fraction(camera) / 2.0))
            events.append(rt.launch(k, *self._row_launch(rt, w, h)))
            k = self._kernel(rt, camera, "motion_blur_tilemax")
            k.set_args(b["hv"], b["iz"], b["tile"], np.int32(w), np.int32(h), np.int32(tw), np.int32(th))
            events.append(rt.launch(k, (tw, th)))
            k = self._kernel(rt, camera, "motion_blur_neighbormax")
            k.set_args(b["tile"], b["nmax"], np.int32(tw), np.int32(th))
            events.append(rt.launch(k, (tw, th)))
            k = self._kernel(rt, camera, "motion_blur_budget")
            k.set_args(b["nmax"], b["cap"], np.int32(tw), np.int32(th))
            events.append(rt.launch(k, (1,)))
            k = self._kernel(rt, camera, "motion_blur")
            k.set_args(src, blur_dst, b["hv"], b["iz"], b["nmax"], b["cap"], np.int32(w), np.int32(h),
                       np.int32(tw), np.int32(th), np.uint32(SEED), np.uint32(frame.index))
            events.append(rt.launch(k, *self._row_launch(rt, w, h)))
        if rolling:
            k = self._kernel(rt, camera, "motion_blur_rolling")
            k.set_args(blur_dst if blur else src, dst, aux["velocity"], np.int32(w), np.int32(h),
                       np.float32(camera.readout_time_s * camera.frame_rate_fps))
            events.append(rt.launch(k, (w, h)))
        if not events:  # only reachable when forced past skip_reason (e.g. a test): copy through
            events.append(rt.copy(dst, src))
        return events

    # -- the oracle -------------------------------------------------------------------------
    def reference(self, camera, frame, color):
        """float64 numpy implementation of the module docstring (tap positions in float32,
        rounded exactly as the kernel rounds them)."""
        out = np.asarray(color, dtype=np.float64)
        if frame.velocity is None:
            raise InputError("motion_blur needs the frame's velocity buffer")
        if _blur_needed(camera, frame):
            out = reference_blur(out, frame.velocity, frame.depth, shutter_fraction(camera),
                                 self.samples, frame.index, samples_max=SAMPLES_MAX[self.quality])
        if _rolling_needed(camera, frame):
            out = reference_rolling(out, frame.velocity, camera.readout_time_s * camera.frame_rate_fps)
        return out


def _model_defines() -> dict[str, str]:
    """The filter's constants as the kernels' float literals (kernels/motion_blur_pixels.cl), from
    this module's names only: each literal rounds to the float32 the reference uses."""
    consts = {"SOFT_Z": SOFT_Z, "FOOT": FOOT, "AGREE0": AGREE0, "AGREE1": AGREE1, "DIFFER2": DIFFER2,
              "DIR": DIR, "LINE": LINE, "FRINGE2": FRINGE * FRINGE, "R2X": JITTER_R2[0], "R2Y": JITTER_R2[1]}
    return {f"MOTION_BLUR_{k}": f"{float(v)!r}f" for k, v in consts.items()}


def _program_source(lanes: int) -> str:
    """common.cl and the width-generic libraries, the per-pixel math of kernels/motion_blur_pixels.cl
    at one pixel (plain names) and, for the 16-lane form, at 16 (``_w16``; the one-pixel functions
    do its rows' edge pixels), then kernels/motion_blur.cl: one source of every formula for both forms."""
    from ..codegen import library, library_lanes16
    from ..runtime import kernel_source

    src = library() + kernel_source("motion_blur_pixels")
    if lanes == 16:
        src += library_lanes16() + kernel_source("motion_blur_pixels")
    return src + kernel_source("motion_blur")


# -- numpy reference ---------------------------------------------------------------------------

def jitter(seed: int, frame: int, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Per-pixel jitter j ∈ [−½, ½) — the kernel's ``motion_blur_jitter`` (float32, operation for
    operation): the per-frame hash offset plus the R2 lattice (module docstring, "Taps")."""
    h = rnd.hash4(seed, frame, np.uint32(0), np.uint32(0))
    j0 = (np.uint32(h) >> np.uint32(8)).astype(np.float32) * np.float32(1.0 / 16777216.0)
    a = np.asarray(x).astype(np.float32) * np.float32(JITTER_R2[0])
    b = np.asarray(y).astype(np.float32) * np.float32(JITTER_R2[1])
    v = ((a - np.floor(a)) + (b - np.floor(b))) + j0
    return ((v - np.floor(v)) - np.float32(0.5)).astype(np.float32)


def half_vectors(velocity: np.ndarray, k: float, with_length: bool = False) -> np.ndarray:
    """h = v·k clamped to |h| ≤ K (H×W×2, float64); ``with_length`` appends the unclamped |v·k|
    (the key TileMax ranks by) as a third component."""
    v = np.asarray(velocity, dtype=np.float64)
    m = np.max(np.abs(v), axis=-1, keepdims=True)
    u = np.divide(v, m, out=np.zeros_like(v), where=m > 0)
    ul = np.hypot(u[..., 0], u[..., 1])[..., None]
    length = ul * m * k
    h = np.divide(u * np.minimum(length, TILE), ul, out=np.zeros_like(v), where=ul > 0)
    return np.concatenate([h, length], axis=-1) if with_length else h


def _direction_length32(velocity: np.ndarray, k: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(moving, e, length) of v·k in float32 as ``motion_blur_prep`` computes them: v scaled by its
    inf-norm first (no overflow up to FLT_MAX), the unit direction e = u/|u| and the unclamped
    length |u|·m·k (H×W×1 mask, H×W×2, H×W×1); e and length are 0 where v = 0."""
    v = np.asarray(velocity, dtype=np.float32)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        m = np.max(np.abs(v), axis=-1, keepdims=True)
        u = v / np.where(m > 0, m, np.float32(1))
        lu = np.sqrt(u[..., 0] * u[..., 0] + u[..., 1] * u[..., 1])[..., None]
        length = lu * m * np.float32(k)
        e = u * (np.float32(1) / lu)
    moving = m > 0
    return (moving, np.where(moving, e, np.float32(0)).astype(np.float32),
            np.where(moving, length, np.float32(0)).astype(np.float32))


def half_vectors32(velocity: np.ndarray, k: float) -> np.ndarray:
    """``half_vectors(..., with_length=True)`` in float32, operation for operation as
    ``motion_blur_prep`` computes them (the kernel steps along them: tap positions must round the
    same way): h = e · min(|h|, K), the direction times the clamped length."""
    _, e, length = _direction_length32(velocity, k)
    return np.concatenate([e * np.minimum(length, np.float32(TILE)), length], axis=-1).astype(np.float32)


def tap_records(velocity: np.ndarray, k: float) -> tuple[np.ndarray, np.ndarray]:
    """What a tap reads of Y, as ``motion_blur_prep`` packs it in one word: (l, e) with l = max(|h|,
    ½) as a float with a 10-bit mantissa (the float32 bits from ½ up, rounded half up), e = h's unit
    direction in signed counts of 1/DIR (rounded to nearest even; 0 where v = 0); float32, the same
    operations as the kernel. |h| is the clamped length min(|v·k|, K) of :func:`half_vectors32`."""
    _, e, length = _direction_length32(velocity, k)
    l32 = np.maximum(np.minimum(length, np.float32(TILE)), np.float32(0.5)).astype(np.float32)[..., 0]
    bits = ((l32.view(np.uint32) + np.uint32(0x1000) - np.uint32(0x3F000000)) >> np.uint32(13)) & np.uint32(0xFFFF)
    lq = ((bits << np.uint32(13)) + np.uint32(0x3F000000)).astype(np.uint32).view(np.float32)
    q = np.rint(e * np.float32(DIR)).astype(np.float32)
    return lq, q


def _argmax_len(vecs: np.ndarray) -> np.ndarray:
    """vecs (..., N, 3) → the one of the N with the largest key (component 2; first on ties)."""
    idx = np.argmax(vecs[..., 2], axis=-1)
    return np.take_along_axis(vecs, idx[..., None, None], axis=-2)[..., 0, :]


def tile_max(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(TileMax, NeighborMax) of keyed half-vectors h (H×W×C, C ≥ 3, from ``half_vectors(...,
    with_length=True)``; further channels ride along with their pixel's vector): th×tw×C each."""
    tmax = _tile_maxima(np.asarray(h, np.float64))
    return tmax, _argmax_len(_neighbourhoods(tmax))


def _tile_maxima(h: np.ndarray) -> np.ndarray:
    """Each TILE×TILE tile's pixel with the largest key (channel 2; first in scan order on ties, 0
    beyond the frame): th×tw×C in h's dtype."""
    hh, ww, c = h.shape
    tw, th = -(-ww // TILE), -(-hh // TILE)
    pad = np.zeros((th * TILE, tw * TILE, c), h.dtype)
    pad[:hh, :ww] = h
    return _argmax_len(pad.reshape(th, TILE, tw, TILE, c).transpose(0, 2, 1, 3, 4).reshape(th, tw, TILE * TILE, c))


def _neighbourhoods(tmax: np.ndarray) -> np.ndarray:
    """Each tile's 3×3 tiles (zeros beyond the frame), in scan order: th×tw×9×C."""
    th, tw = tmax.shape[:2]
    tp = np.zeros((th + 2, tw + 2) + tmax.shape[2:], tmax.dtype)
    tp[1:-1, 1:-1] = tmax
    return np.stack([tp[1 + dy:1 + dy + th, 1 + dx:1 + dx + tw] for dy in (-1, 0, 1) for dx in (-1, 0, 1)], axis=2)


def _differs32(ax, ay, bx, by) -> np.ndarray:
    """Direction a differs from b by more than acos(AGREE0): a·b < 0 or (a·b)² < DIFFER2 |a|²|b|²,
    in float32 as the kernel's ``motion_blur_differs`` (a zero vector differs from nothing)."""
    f = np.float32
    ax, ay, bx, by = (np.asarray(q, f) for q in (ax, ay, bx, by))
    d = ax * bx + ay * by
    la, lb = ax * ax + ay * ay, bx * bx + by * by
    return (d < 0) | (d * d < f(DIFFER2) * (la * lb))


def second_directions(hk: np.ndarray, iz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The neighbourhood's second direction per tile (module docstring, "Second direction"; the
    kernels' TileMax and NeighborMax): th×tw×2 float32 (zero where none) and th×tw bool, True where its
    surface is the nearer one. ``hk`` the keyed half-vectors (float32 values), ``iz`` 1/depth."""
    rec = np.concatenate([np.asarray(hk[..., :3], np.float32), np.asarray(iz, np.float32)[..., None]], axis=-1)
    cand = _neighbourhoods(_tile_maxima(rec))                          # th, tw, 9, (x, y, key, 1/z)
    n1 = _argmax_len(cand)                                             # v_N and its 1/z
    dif = _differs32(cand[..., 0], cand[..., 1], n1[..., None, 0], n1[..., None, 1])
    n2 = _argmax_len(np.where(dif[..., None], cand, np.float32(0)))
    sz, bz = n2[..., 3], n1[..., 3]
    other = (n2[..., 2] > np.float32(0.5)) & (
        np.abs(sz - bz) > np.float32(0.5) * np.float32(SOFT_Z) * np.maximum(np.maximum(sz, bz), np.float32(1e-30)))
    return np.where(other[..., None], n2[..., :2], np.float32(0)), other & (sz > bz)


def taps(ln32: np.ndarray, samples: int) -> np.ndarray:
    """S per pixel (module docstring, "Taps"): min(samples, 2⌈DENSITY |v_N|⌉ + 1) from |v_N| in float32
    (``samples``: the frame's cap, :func:`tap_cap`)."""
    return np.minimum(samples, 2 * np.ceil(np.float32(DENSITY) * ln32).astype(np.int64) + 1)


def tap_cap(nmax: np.ndarray, samples: int, samples_max: int) -> int:
    """The frame's cap C (module docstring, "Taps"; the kernel's ``motion_blur_budget``): S_q × tiles /
    moving tiles (|v_N| > 0.5 px, tested in float32), rounded down to odd, within [S_q, S_max]."""
    v = np.asarray(nmax[..., :2], np.float32)
    moving = int(np.count_nonzero(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] > np.float32(0.25)))
    c = samples * v[..., 0].size // moving if moving else samples
    c = min(max(c, samples), samples_max)
    return c - (1 - (c & 1))


def _len32(v32: np.ndarray) -> np.ndarray:
    """|v| of float32 2-vectors as the kernel computes it: sqrt(x·x + y·y) in float32."""
    return np.sqrt(v32[..., 0] * v32[..., 0] + v32[..., 1] * v32[..., 1])


def _cylinder32(dist: np.ndarray, length: np.ndarray) -> np.ndarray:
    """cyl(d, l) = 1 − smoothstep(l − FOOT, l + FOOT, d) in float32 as the kernel rounds it,
    t = d − l + FOOT (a tap just at the edge can carry a huge colour: its weight must round the same way)."""
    d, l = np.asarray(dist, np.float32), np.asarray(length, np.float32)
    t = np.clip((d - l) + np.float32(FOOT), np.float32(0), np.float32(1))
    return (np.float32(1) - t * t * (np.float32(3) - np.float32(2) * t)).astype(np.float64)


def _front(wa, wb):
    m = np.maximum(np.maximum(wa, wb), 1e-30)
    return np.clip(1.0 - (wb - wa) / (SOFT_Z * m), 0.0, 1.0)


def effective_velocity(velocity: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The fringe rule (module docstring): a pixel whose speed exceeds FRINGE × the fastest of its
    3×3 neighbours (edge-clamped; first in scan order on ties) takes that neighbour's velocity and
    depth. Speeds compared as float32 squares, as the kernel compares them."""
    v = np.asarray(velocity, dtype=np.float32)
    z = np.asarray(depth, dtype=np.float64)
    hh, ww = v.shape[:2]
    with np.errstate(over="ignore", invalid="ignore"):
        s2 = v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1]
    ys, xs = np.mgrid[0:hh, 0:ww]
    best, by, bx = s2.copy(), ys.copy(), xs.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            ny, nx = np.clip(ys + dy, 0, hh - 1), np.clip(xs + dx, 0, ww - 1)
            m = s2[ny, nx] > best
            best = np.where(m, s2[ny, nx], best)
            by, bx = np.where(m, ny, by), np.where(m, nx, bx)
    with np.errstate(over="ignore", invalid="ignore"):
        take = (s2 > 0) & (s2 > np.float32(FRINGE * FRINGE) * best)
    by, bx = np.where(take, by, ys), np.where(take, bx, xs)
    return v[by, bx], z[by, bx]


def reference_blur(color: np.ndarray, velocity: np.ndarray, depth: np.ndarray | None, fraction: float,
                   samples: int, frame_index: int = 0, seed: int = SEED, samples_max: int | None = None) -> np.ndarray:
    """The reconstruction filter of the module docstring in float64 (H×W×3 in and out): the three
    layers of :func:`reference_layers`, composited front to back."""
    color = np.asarray(color, dtype=np.float64)
    L = reference_layers(color, velocity, depth, fraction, samples, frame_index, seed, samples_max)
    cf, co = L["cf"], L["co"]
    # two directions (a still X with a second surface moving another way): the nearer set's front over the farther's
    cfe, sfe, cfo, sfo, near2 = cf - L["cfo"], L["sf"] - L["sfo"], L["cfo"], L["sfo"], L["near2"]
    cn, cr = np.where(near2, cfo, cfe), np.where(near2, cfe, cfo)
    sn, sr = np.where(near2[..., None], sfo, sfe), np.where(near2[..., None], sfe, sfo)
    cnc, crc = np.minimum(cn, 1.0), np.minimum(cr, 1.0)
    two = cnc[..., None] * sn / np.maximum(cn, 1e-30)[..., None] + ((1.0 - cnc) * crc)[..., None] * sr / np.maximum(cr, 1e-30)[..., None]
    cf = np.where(L["use2"], cnc + (1.0 - cnc) * crc, cf)
    sf = np.where(L["use2"][..., None], two, L["sf"])
    cfc, coc = np.minimum(cf, 1.0)[..., None], np.minimum(co / L["ca"], 1.0)[..., None]   # the own share of X's path
    own = coc * L["so"] / co[..., None] + (1.0 - coc) * L["sb"] / L["wb"][..., None]
    fr = np.where((cf > 0)[..., None], sf / np.where(cf > 0, cf, 1.0)[..., None], color)
    out = cfc * fr + (1.0 - cfc) * own
    out[L["still"]] = color[L["still"]]
    return out


def reference_layers(color: np.ndarray, velocity: np.ndarray, depth: np.ndarray | None, fraction: float,
                     samples: int, frame_index: int = 0, seed: int = SEED, samples_max: int | None = None) -> dict:
    """The gather's sums per pixel (module docstring, "Coverage"), float64 H×W (colour sums H×W×3):
    ``cf``/``sf`` in front of X, ``co``/``so`` X's own surface, ``ca`` what ``co`` would be if every tap
    were X's own surface, ``wb``/``sb`` the background; ``still`` where the pixel is left as it is."""
    color = np.asarray(color, dtype=np.float64)
    hh, ww = color.shape[:2]
    z = np.full((hh, ww), np.inf) if depth is None else np.asarray(depth, dtype=np.float64)
    velocity, z = effective_velocity(velocity, z)
    hk = half_vectors32(velocity, np.float32(fraction / 2.0))
    h32 = hk[..., :2]
    lrec, erec = tap_records(velocity, np.float32(fraction / 2.0))   # what a tap reads of Y
    _, nmax = tile_max(hk.astype(np.float64))
    ys, xs = np.mgrid[0:hh, 0:ww]
    vn = nmax[ys // TILE, xs // TILE, :2]
    vn32 = vn.astype(np.float32)
    iz = np.where(np.isinf(z), 0.0, 1.0 / np.where(np.isinf(z), 1.0, z))
    iz32 = np.where(np.isinf(z), np.float32(0), np.float32(1) / np.where(np.isinf(z), np.float32(1), z.astype(np.float32)))
    v2, near2 = second_directions(hk, iz32)
    v2, near2 = v2[ys // TILE, xs // TILE], near2[ys // TILE, xs // TILE]
    lhx = _len32(h32)
    lx32 = np.maximum(lhx, np.float32(0.5))
    lx = lx32.astype(np.float64)
    own_dir = lhx > 0.5
    use2 = ~own_dir & (_len32(v2) > 0)        # a still X with a second surface moving another way
    vx32 = np.where(own_dir[..., None], h32, np.where(use2[..., None], v2, vn32))   # odd taps: X's own motion
    ln32, lv32 = _len32(vn32), _len32(vx32)
    ln, lv = ln32.astype(np.float64), lv32.astype(np.float64)
    tiny = np.float32(1e-30)
    rln32 = np.float32(1) / np.maximum(ln32, tiny)
    rlv32 = np.float32(1) / np.maximum(lv32, tiny)
    cosang = (vn32[..., 0] * vx32[..., 0] + vn32[..., 1] * vx32[..., 1]) / np.maximum(ln * lv, 1e-30)
    agree = np.where(use2, 1.0, np.clip((cosang - AGREE0) / (AGREE1 - AGREE0), 0.0, 1.0))
    j = jitter(seed, frame_index, xs, ys)
    samples = tap_cap(nmax, samples, samples if samples_max is None else samples_max)   # the frame's cap
    ns = taps(_len32(vn32), samples)                          # S per pixel
    inv = np.float32(1) / ns.astype(np.float32)
    inv64 = inv.astype(np.float64)
    # tap paths reach FOOT beyond |v|: directions scaled to |v| + FOOT, in float32 as the kernel
    pn32, pv32 = ln32 + np.float32(FOOT), lv32 + np.float32(FOOT)
    dn32 = vn32 * (pn32 * rln32)[..., None]
    dv32 = vx32 * (pv32 * rlv32)[..., None]
    pn, pv = pn32.astype(np.float64), pv32.astype(np.float64)
    wc = np.maximum((pn32 * inv).astype(np.float64) + (np.where(own_dir, pv32, pn32) * inv), 1.0) / (2.0 * lx)   # at least the pixel
    cf, sf = np.zeros((hh, ww)), np.zeros_like(color)          # surfaces in front of X (both sets)
    cfo, sfo = np.zeros((hh, ww)), np.zeros_like(color)        # ... of them, the odd taps'
    wfo, wfe = np.where(use2, 2.0, agree), np.where(use2, 2.0, agree + (1.0 - agree) * 2.0)   # front set weights
    co, so = wc.copy(), color * wc[..., None]                  # X's own surface along its path
    ca = wc.copy()                                              # c_O if every tap were X's own surface
    wb = np.full((hh, ww), 1e-3)
    sb = color * wb[..., None]                                  # the background behind X
    for s in range(samples):
        tap = (s < ns) & (s != ns // 2)          # the centre stratum is X itself
        d32 = dv32 if s % 2 else dn32
        u = (np.float32(s) + np.float32(0.5) + j) * inv
        t = np.float32(2.0) * u - np.float32(1.0)
        ox, oy = d32[..., 0] * t, d32[..., 1] * t
        sx = np.clip(np.floor(xs.astype(np.float32) + ox + np.float32(0.5)).astype(np.int64), 0, ww - 1)
        sy = np.clip(np.floor(ys.astype(np.float32) + oy + np.float32(0.5)).astype(np.int64), 0, hh - 1)
        dx32, dy32 = (sx - xs).astype(np.float32), (sy - ys).astype(np.float32)
        dist = np.sqrt(dx32 * dx32 + dy32 * dy32)
        ly32 = lrec[sy, sx]
        ly = ly32.astype(np.float64)
        wy = iz[sy, sx]
        f, b = _front(wy, iz), _front(iz, wy)
        cly = _cylinder32(dist, ly32)
        a = tap * cly * (pv if s % 2 else pn) * inv64 / ly
        cx = _cylinder32(dist, lx32)
        own = b * cx                             # level with X and on X's own path
        ey = erec[sy, sx].astype(np.float64)
        line = np.clip(LINE + 0.5 - np.abs(dx32 * ey[..., 1] - dy32 * ey[..., 0]) / DIR, 0.0, 1.0)
        af = line * f * (1.0 - own) * a * (wfo if s % 2 else wfe)
        go = agree + (1.0 - agree) * (2.0 if s % 2 else 0.0)
        ao = f * own * a * go
        ca = ca + tap * cx * cx * (pv if s % 2 else pn) * inv64 / lx * go   # Y = X: f = b = 1
        ab = (tap * b * ((1.0 - f) + f * (1.0 - cly)) * cx   # behind, or level and missing X
              / np.maximum(dx32 * dx32 + dy32 * dy32, np.float32(1)))                 # nearest look most like it
        cy = color[sy, sx]
        cf, sf = cf + af, sf + af[..., None] * cy
        if s % 2:
            cfo, sfo = cfo + af, sfo + af[..., None] * cy
        co, so = co + ao, so + ao[..., None] * cy
        wb, sb = wb + ab, sb + ab[..., None] * cy
    still = vn[..., 0] ** 2 + vn[..., 1] ** 2 <= 0.25
    return dict(cf=cf, sf=sf, cfo=cfo, sfo=sfo, use2=use2, near2=near2, co=co, so=so, ca=ca, wb=wb, sb=sb,
                still=still)


def reference_rolling(color: np.ndarray, velocity: np.ndarray, readout_frames: float) -> np.ndarray:
    """Rolling-shutter warp of the module docstring (float64)."""
    hh, ww = color.shape[:2]
    ys, xs = np.mgrid[0:hh, 0:ww].astype(np.float64)
    tau = readout_frames * (ys / (hh - 1) - 0.5) if hh > 1 else np.zeros_like(ys)
    v = np.asarray(velocity, dtype=np.float64)
    qx, qy = xs.copy(), ys.copy()
    for _ in range(3):
        nx = np.clip(np.floor(qx + 0.5), 0, ww - 1).astype(np.int64)
        ny = np.clip(np.floor(qy + 0.5), 0, hh - 1).astype(np.int64)
        qx = np.clip(xs - v[ny, nx, 0] * tau, 0, ww - 1)
        qy = np.clip(ys - v[ny, nx, 1] * tau, 0, hh - 1)
    x0 = np.minimum(np.floor(qx), ww - 1).astype(np.int64)
    y0 = np.minimum(np.floor(qy), hh - 1).astype(np.int64)
    x1, y1 = np.minimum(x0 + 1, ww - 1), np.minimum(y0 + 1, hh - 1)
    fx, fy = (qx - x0)[..., None], (qy - y0)[..., None]
    top = color[y0, x0] * (1 - fx) + color[y0, x1] * fx
    bot = color[y1, x0] * (1 - fx) + color[y1, x1] * fx
    return top * (1 - fy) + bot * fy
