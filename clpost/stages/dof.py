r"""dof: thin-lens depth of field — signed circle of confusion and a tiled scatter-as-gather with
bladed, textured, cat's-eye bokeh.

Circle of confusion (thin lens, Hecht §5.2; Potmesil & Chakravarty 1981)
-------------------------------------------------------------------------
A lens of focal length f focused at u (film at :math:`v = fu/(u-f)`) images a point at planar
depth S at :math:`v_S = fS/(S-f)`. Its light fills the aperture of diameter :math:`A = f/N` and
meets the film in a disc of diameter :math:`A\,|v - v_S|/v_S`. Signed (far > 0, near < 0):

.. math::

    c(S) = \frac{f^2}{N}\,\frac{1/u - 1/S}{1 - f/u}
         = \frac{f\,v}{N}\Big(\frac1u - \frac1S\Big) \quad [\text{mm on the film}],
    \qquad r_{px} = \frac{c}{2p}

with p the pixel pitch (:meth:`Camera.pixel_pitch_mm`); r is the bokeh *radius* in pixels. The
form in 1/S and 1/u is exact, needs no special case for u = ∞ or S = ∞, and gives the finite
far limit :math:`c_\infty = f v /(N u)`. The talk's :math:`C = v^2|S-u|/(uSN)` equals
:math:`|c|\cdot v/f`: it takes the aperture as :math:`A = v/N` (N as a working f-number at the
image distance); we use the f-number as engraved (:math:`A = f/N`, the entrance pupil of a thin
lens). The two agree for u ≫ f (1.7 % apart at u = 3 m with f = 50 mm).

Depth → 0⁺ gives c → −∞: r is clamped to ±``max_coc_px`` of the quality level (below), which is
also the largest blur the gather supports — larger CoC saturates there (never NaN, never a hole).

Edge pixels whose colour and depth disagree (CONVENTIONS.md: renderers give anti-aliased colour
and one-sample depth — the fringe of a small bright light carries the light's colour and the sky's
depth): the *fringe rule* (:func:`effective_depth`) explains p's luminance as a mix
:math:`Y_p = \alpha Y_n + (1-\alpha) Y_f` of a nearer surface seen in its 3×3 neighbourhood and
p's own surface, and gives p the nearest depth of its 3×3 when that surface covers at least half
of p or brings at least half of its light. A light's fringe then keeps the light's depth (its energy
goes into the light's bokeh instead of a sky-sized halo), a silhouette's half-covered pixels go
with the surface in front (no sharp ghost line of a blurred foreground), and on a smooth far
surface nothing else moves; depths only ever move nearer. Rejected alternative: splitting each
fringe pixel into two sources (foreground and background colour and CoC, Dr.Bokeh-style layers)
doubles the gather's taps; per-pixel energy goes almost wholly to one surface at the fringes that
matter (a light is 100–1000× its background), so one depth per pixel chosen by energy keeps the
single-layer gather.

Gather (scatter-as-gather, one pass, per 16×16 tile, fixed tap budget)
-----------------------------------------------------------------------
Every source pixel q spreads its colour over its bokeh :math:`K_q`; output pixel p sums the
bokehs that cover it. Ideas used, by source:

* Tiles of max |CoC| dilated by the reach of neighbouring tiles (Jimenez 2014, "Next Generation
  Post Processing in Call of Duty", tile max + neighbourhood max): an in-focus tile reads one tap.
  Depth-aware: a neighbour's sources behind every pixel of the tile are clamped to the pixel's own
  radius (the background clamp below), so they do not dilate it (:func:`tile_plan`) — a wall
  beside a farther, blurrier sky keeps the wall's own lattice stride.
* A fixed per-pixel budget scaled to the tile's reach R (Abadie 2018, "A Life of a Bokeh": sample
  count independent of the CoC's area): the tile gathers the unit lattice disc
  :math:`\{o \in \mathbb Z^2 : |o| < R_b + 1\}` (sorted by distance) scaled by the stride
  :math:`s = 2^\ell`, the smallest with :math:`\lceil R/s - \tfrac12\rceil \le R_b`, so at most
  :math:`\approx\pi(R_b+1)^2` taps per pixel at any CoC. Taps read level ℓ of a prefiltered
  pyramid (:func:`prefiltered_levels`): colour filtered by the tent of half-width s — a partition
  of unity over :math:`s\mathbb Z^2`, so a constant-CoC region conserves energy exactly and a point
  light becomes the polygon interpolated between lattice points (deterministic: no noise, no
  post-filter needed) — and CoC by the min over the same window, so a tap straddling an in-focus
  edge counts as in focus and never smears it. Blurs up to R_b px use s = 1: the exact dense gather
  (every integer offset). Price: beyond R_b the bokeh's edge widens by ≈ 1.5 (s − 1) px per side,
  and a pixel whose own CoC is far below its tile's R is blurred at the lattice scale (its centre
  tap blends its own colour toward the level's by :math:`\beta = \min(1, |r_p|/s)`).
* Shape and texture are evaluated per tap, weighted by each sample's own CoC (scatter-as-gather),
  with the coverage ramp half a lattice step wide (at least 1 px):
  :math:`\mathrm{cov} = \mathrm{clamp}((r\rho - |o|)/\max(s/2, 1) + \tfrac12, 0, 1)` — sharper disc
  edges than a ramp of s, at no cost (docs/fidelity.md) — and the cell area :math:`s^2` in the weight.
* Near/far separation by depth order relative to p (Jimenez's scatter-as-gather classification):
  taps nearer than p by more than :data:`FRONT_MARGIN_PX` of CoC form the *front* layer F (their own radius, so a
  blurred foreground spreads over the in-focus background); taps behind p have their radius
  clamped to p's own (far) CoC — Jimenez's background clamp — so background never bleeds onto a
  sharp foreground; same-depth taps use their own radius. Compositing with the front layer's
  coverage α (partial occlusion):

  .. math::

      w_q = \frac{s^2\,\mathrm{cov}_q\, I_q\, B_q}{a_K\, r_q^2}, \quad
      \alpha = \min\!\Big(1, \frac{\sum_F w}{\phi(p)}\Big), \quad
      \text{out} = \alpha\frac{\sum_F w c}{\sum_F w} + (1-\alpha)\frac{\sum_B w c}{\sum_B w}

  Normalising each layer by its own weight makes a defocused flat field exactly flat and removes
  the dark halo around sharp foreground edges; a constant-CoC region conserves energy exactly
  (every pixel's normaliser is the same sum over the same offsets).

Aperture shape :math:`K` (Cycles' convention): an N-gon with corners on the unit circle, blade
rotation 0 putting a corner at the top of a *background* bokeh (rotation turns it
counter-clockwise on screen); ``aperture_roundness`` blends its radius function toward the circle:
:math:`\rho(\phi) = (1-R)\,\frac{\cos(\pi/N)}{\cos(((\phi-\phi_0) \bmod 2\pi/N) - \pi/N)} + R`.
A point in front of the focus plane (c < 0) shows the aperture point-reflected, as a thin lens
does. Coverage is the 1-px ramp :math:`\mathrm{cov} = \mathrm{clamp}(r\rho - |o| + 0.5, 0, 1)`;
:math:`a_K = \tfrac12\oint\rho^2 d\phi` is the unit shape's area; r ≥ 0.5 px.

Spherical aberration texture (parametric): :math:`I(t) = 1 + a\,(2t^2 - 1)`, t the normalised
radius in the bokeh; :math:`\int I = \int 1` for any a, so energy is unchanged. a = +σ in the near
field and −σ in the far field for σ = ``spherical_aberration`` (undercorrected σ > 0: foreground
bokeh with a dark core and bright rim, background bokeh with a bright core fading out; σ < 0 swaps
them). |σ| ≤ 1 keeps I ≥ 0. A tap behind p, whose radius the background clamp sets to p's, takes
p's layer's a (the clamped tap stands in for p's own disc: a near light's own pixel is then
normalised against its own texture, not a far wall's opposite one). At half resolution, whose
working discs are small (r' of a few working px), each tap's textured weight is also multiplied by
:math:`N(r/s; 0)/N(r/s; a)` (:func:`texture_sums`), so the texture keeps the lattice sum of the
untextured disc (on a small disc's lattice the rim's value fills the coverage ramp: the sum moved a
near light's energy in a far wall's unnormalised front layer by up to ±40 %; docs/fidelity.md,
"Lights under the spherical-aberration texture").

Traced texture (a ``lens_data`` lens; σ is then unused): the weight of a tap is multiplied per
channel by the lens's own profile :math:`P_c(t; r_q)` — the pencil map of
:mod:`clpost.optics.pencil`, traced through the prescription per RGB band and signed defocus,
:math:`\int_0^{T} P_c\,2t\,dt = 1` — instead of I(t), with t unclamped up to T =
:data:`clpost.optics.pencil.T_MAX` (the traced disc may exceed the thin-lens disc): coverage ends at
:math:`T r\rho`, the tile plan's reach is T × |CoC|, and the layers' sums are kept per channel,
:math:`\mathrm{out}_c = \alpha_c \frac{\sum_F w_c c}{\sum_F w_c} + (1-\alpha_c)\frac{\sum_B w_c c}{\sum_B w_c}`,
:math:`\alpha_c = \min(1, \sum_F w_c)`, so each colour's disc keeps its own size (axial colour).
Verified against the Kolb-style tracer in docs/bokeh_profile.md.

Optical vignetting (cat's-eye): :class:`PupilModel` — the aperture intersected with a front and
a rear lens-barrel circle of the same radius displaced by :math:`\pm\eta\,h/2` (η =
``optical_vignetting``, h the field position over the half diagonal, so |ηh| ≤ 1): the pupil's
shape per field point, the two-disc lens of one barrel displaced by ηh but centred on the aperture,
so the bokeh's centroid stays on the source (a displaced centroid is a radial magnification of the
blur, by :math:`1 \pm \eta r/(2H)`, that the gather's normalisation turns into energy).
Only the shape changes here; the light it removes belongs to the vignetting stage, so weights are
renormalised by the clipped area :math:`\phi = (2\arccos(d/2) - \tfrac d2\sqrt{4-d^2})/\pi`
(d = η|h|, the two-disc lens area) for the coverage α. Tap weights are symmetric,
w(p, q) = w(q, p): the shape at the midpoint field position of p and q and the mean of their
1/φ, so a point light's energy :math:`\sum_p w(p,q)/W(p)` stays 1 where W (the same-depth weight
sum) is smooth; the cone of |h| at the image centre still leaves a dip of W there, and a point
light at the centre keeps 0.973 (draft) … 0.985 (final) of its energy at η = 1, 0.987 at η = 0.5
(a corner: 1 ± 0.3 %; tests/test_dof.py).

Quality levels (``max_coc_px`` at the output resolution; R_b the lattice budget; taps per pixel
at most, at any CoC; in-focus tiles: 1; error vs the accumulation reference in docs/benchmarks.md)
=========  =================  ================  ===  =====================================================
level      working res        max CoC radius    R_b  taps per pixel (max)
=========  =================  ================  ===  =====================================================
draft      half (2×2 box)     32 px (16 work)   3    45 (dense up to 3 work px, then stride 2, 4, 8)
preview    half               64 px (32 work)   5    109 (dense up to 5 work px, then stride 2, 4, 8)
final      mixed (below)      64 px             8    249 (dense up to 8 px, stride 2 up to 17 px; beyond: half res)
=========  =================  ================  ===  =====================================================
Half-resolution levels composite with a full-resolution 3×3 blur of the image by
:math:`\mathrm{lerp}(c_{3\times3}, \mathrm{up}(c_{blur}), \max(b(r), \mathrm{up}(\alpha)))`
(depth-aware bilinear upsampling, :func:`_upsample`), so in-focus pixels stay at full resolution.
The path itself blurs: the 2×2 box and the bilinear upsampling add 1 px² of variance per axis and
the working-resolution coverage ramp 1/3 px², so it gathers with the variance-matched radius
:math:`r' = \sqrt{r^2 - 16/3}` (:func:`half_radius`). Below r = 2 px, where even r' = 0 is too
wide, the disc's variance :math:`v = r^2/4` is made at full resolution: a separable
[a, 1 − 2a, a] scatter-as-gather, a = min(v, ½)/2 per source with the gather's near/far rule
(:func:`local_blur`), alone up to v = ½ (r = √2 px) and mixed by variance with the path's
narrowest blur up to v = 1 (r = 2 px), :math:`b = \mathrm{clamp}(2v - 1, 0, 1)`
(:func:`half_blend`); effect on the Cycles truths: docs/fidelity.md, "The half-resolution path".
Small bright lights (:func:`narrow_sources`) are taken out of the half-resolution input and of the
composite's 3×3 blur, and spread at full resolution instead (:func:`narrow_layer`): the path's ≈ 3 px soft disc edge saturates
around a 100× lamp; an in-focus one's excess leaves the input too and stays with the 3×3 blur
(:data:`NARROW_FOCUS_PX`: the levels' tent spread it over the blurred background beside it)
(docs/fidelity.md, "The narrow-source layer").

Mixed resolution (final, :data:`MIXED`): a working tile (16×16 at half resolution = 32×32 px) is
*big* when its half-resolution plan (max CoC 32 working px, R_b = 8) needs lattice level ≥ 1
(reach > 8.5 working px = 17 px), or when one of its 16×16 full-resolution tiles would need
stride ≥ 4 at full resolution. Big tiles take the half-resolution composite above (the draft
path with final's budget), the others the full-resolution gather, which then needs only strides
1 and 2 (:data:`MIXED_FULL_LEVELS`):

.. math::

    \mathrm{out} = \begin{cases}\mathrm{lerp}(c, \mathrm{up}(c^{1/2}_{blur}), b) & \text{big tile}\\
                   \text{full-resolution gather} & \text{else}\end{cases}

Why it loses little: at reach > 17 px the full-resolution gather already used stride ≥ 4 over a
tent-prefiltered level, i.e. it sampled the scene at ≤ ¼ of its pixels. PSNR/FLIP against the
accumulation reference and the speed-up: docs/benchmarks.md, "dof: final at mixed resolution".

Domain/range: colour ≥ 0 finite (HDR, nothing clipped); depth > 0 or +inf; output finite ≥ 0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import InputError
from ..optics import pencil
from ..optics.coc import coc_mm  # noqa: F401  (the stage's CoC; tests and tools use dof.coc_mm)
from ..params import boolean, finite, in_range, param, parse_fraction, parse_on_off
from . import _field as fld
from .base import GatherStage


def _check_blades(name, value):
    try:
        ok = int(value) == value and value >= 0 and value not in (1, 2)
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise InputError(f"Camera.{name}={value!r} must be 0 (round) or an integer >= 3")
    return int(value)


@dataclass(frozen=True)
class DofParams:
    """dof: the thin lens's defocus and the aperture's shape; defaults keep the pinhole image."""

    depth_of_field: bool = param(False, unit="on/off", flag="--depth-of-field", parse=parse_on_off,
                                 check=boolean, header="clpost.depthOfField", scalar=False,
                                 help="thin-lens defocus from the depth buffer: on/off (off: pinhole)")
    blades: int = param(0, unit="blades", flag="--blades", parse=int, check=_check_blades, header="clpost.blades",
                        scalar=False, help="aperture blades (0 = round)")
    blade_rotation_deg: float = param(0.0, unit="degrees", flag="--blade-rotation", parse=parse_fraction,
                                      check=finite("degrees", "e.g. 0"), header="clpost.bladeRotation_deg",
                                      scalar=True, help="aperture blade rotation in degrees")
    aperture_roundness: float = param(0.0, unit="unitless", flag="--roundness", parse=float,
                                      check=in_range(0.0, 1.0, "unitless", "0 (polygon) … 1 (circle)"),
                                      header="clpost.apertureRoundness", scalar=True,
                                      help="aperture blade roundness 0 (polygon) … 1 (circle); corners stay on "
                                           "the f/N circle")
    spherical_aberration: float = param(0.0, unit="unitless", flag="--spherical-aberration", parse=float,
                                        check=in_range(-1.0, 1.0, "unitless", "0.5 (undercorrected) or -0.5"),
                                        header="clpost.sphericalAberration", scalar=False,
                                        help="bokeh texture -1 … 1 (> 0: undercorrected; near: bright rim, far: "
                                             "bright core)")
    optical_vignetting: float = param(0.0, unit="unitless", flag="--cats-eye", parse=float,
                                      check=in_range(0.0, 1.0, "unitless", "0.5 for visible cat's-eye bokeh"),
                                      header="clpost.opticalVignetting", scalar=False,
                                      help="optical vignetting (cat's-eye bokeh) strength 0 … 1: barrel-clip "
                                           "displacement in aperture radii at the corner")


TILE = 16
"""Work-group / tile edge in working pixels."""

QUALITY = {
    # name: (working-resolution divisor, max CoC radius in working px, lattice budget R_b)
    "draft": (2, 16, 3),
    "preview": (2, 32, 5),
    "final": (1, 64, 8),
}

MIXED = {
    # name: (working-resolution divisor, max CoC radius in working px, R_b) of the half-resolution
    # gather that final uses for its large-reach tiles (see "Mixed resolution" in the docstring)
    "final": (2, 32, 8),
}
MIXED_LEVEL = 1
"""A tile of the half-resolution plan whose lattice level is ≥ this (reach > R_b + ½ = 8.5
working px, i.e. > 17 px) is gathered at half resolution at final."""
MIXED_FULL_LEVELS = 1
"""Levels final builds at full resolution (strides 1, 2): a working tile with a full-resolution
child tile that would need a coarser level is gathered at half resolution as well."""

def luma_weights(camera=None) -> np.ndarray:
    """Relative-luminance weights of the camera's working space (colour-science), for the
    highlight test below (Rec. 709 without a camera)."""
    from ..colorspace import WORKING_SPACES, luminance_weights

    return luminance_weights(WORKING_SPACES[getattr(camera, "working_space", "rec709")])


MIXED_SAME_DEPTH = 0.8
"""Neighbours nearer than this × a pixel's depth are another surface (the fringe rule)."""
FRONT_MARGIN_PX = 0.25
r"""Taps whose signed CoC is below p's by more than this (working px) are p's front layer, above it
by more than this its background; within it, p's own surface. The front layer adds unnormalised
(each source's own bokeh weight, so its light is conserved); the own-surface pool is normalised by
its summed weight, which loses a smaller-CoC source's light when it is pooled with a larger-CoC
surround, so the margin is narrow: a small source a pixel of CoC nearer than the sky is its own
front layer (docs/fidelity.md, "Emitter energy", measures the choice)."""


def lattice_stride(r_px: float, budget: int) -> int:
    r"""Lattice stride s = 2^ℓ the tile plan picks for a tile whose dilated max CoC is ``r_px``
    (working px): the smallest with :math:`\lceil r/s - \tfrac12\rceil \le R_b`."""
    lv = 0
    while math.ceil(r_px / 2 ** lv - 0.5) > budget:
        lv += 1
    return 2 ** lv


def max_coc_px(quality: str) -> float:
    """Largest CoC radius (output pixels) the gather supports at ``quality``."""
    s, r, _ = QUALITY[quality]
    return float(s * r)


# ---------------------------------------------------------------------------------------------
# Circle of confusion
# ---------------------------------------------------------------------------------------------


def coc_coefficients(camera, width_px: int) -> tuple[float, float]:
    r"""``(k, inv_u)`` with :math:`r_{px} = k\,(1/u - 1/S)` for S and u in metres:
    :math:`k = \frac{f F}{2 N p}\cdot 10^{-3}` (f, F, p in mm; 1/m → 1/mm; F below :func:`coc_mm`)."""
    f = camera.focal_length_mm
    v = camera.render_focal_length_mm
    p = camera.pixel_pitch_mm(width_px)
    k = f * v / (2.0 * camera.f_number * p) * 1e-3
    u = camera.focused_depth_m
    return k, (0.0 if math.isinf(u) else 1.0 / u)


def coc_px(camera, depth_m, width_px: int, limit_px: float = math.inf) -> np.ndarray:
    """Signed CoC radius in pixels at image width ``width_px``, clamped to ±``limit_px``."""
    k, inv_u = coc_coefficients(camera, width_px)
    s = np.asarray(depth_m, dtype=np.float64)
    with np.errstate(divide="ignore"):
        inv_s = np.where(np.isinf(s), 0.0, 1.0 / s)
    return np.clip(k * (inv_u - inv_s), -limit_px, limit_px)


def _neighbourhood(a: np.ndarray):
    """The 9 edge-clamped 3×3 shifts of an H×W array (centre first)."""
    p = np.pad(a, 1, mode="edge")
    h, w = a.shape
    offs = [(0, 0)] + [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)]
    return [p[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dy, dx in offs]


SPECKLE_MAX_SAME = 3
"""A pixel with at most this many of its 8 neighbours at its own depth (within 0.8×) is a speckle
candidate (:func:`despeckle_depth`)."""
SAME_SOURCE = 1.5
"""Two pixels within this luminance ratio of each other, both far above their surround, are one
source (CONVENTIONS.md's 1.5× of a light; :func:`despeckle_depth`)."""
FRINGE_STEP = 0.95
"""Luminance steps under 1 − this (5 %) are no evidence (render noise, the pixel filter's spread):
the fringe rule's near surface must be brighter (darker) than every other pixel of p's own surface
by more (:func:`effective_depth`), and a speckle's luminance may lie that far outside its
other-depth neighbours' range (:func:`despeckle_depth`)."""
LIGHT_FRINGE = 0.25
"""The fringe rule's *light* clause (:func:`effective_depth`) takes p for a light's fringe only when
the light covers at most this share of it (α ≤ ¼, half the coverage test's ½): a 1-px lamp's fringe
is 0.10–0.15 of it (held-out h_lamps' lamp01), a grey texel (0.3) beside a white object (1.0) on a
near-black wall 0.29–0.31 (docs/fidelity.md, "The twin on a black wall")."""


def _same_depth(dq, d):
    return (dq >= MIXED_SAME_DEPTH * d) & (d >= MIXED_SAME_DEPTH * dq)


_RING = (0, 1, 2, 4, 7, 6, 5, 3)
"""The 8 neighbours of :func:`_neighbourhood` (after the centre) in ring order, clockwise from the
top left."""


def speckle_candidates(depth: np.ndarray, lines: bool = True) -> np.ndarray:
    """Pixels with at most :data:`SPECKLE_MAX_SAME` of their 8 neighbours at their own depth class,
    except those with exactly that many forming one arc of the ring: an object's convex corner (an
    L of 3), whose depth is right, not a speckle's (:func:`despeckle_depth`). ``lines=False`` also
    leaves out pixels with two opposite same-depth neighbours (on a one-pixel line: a wire, a pole)."""
    d = np.asarray(depth, dtype=np.float64)
    s = [_same_depth(q, d) for q in _neighbourhood(d)[1:]]
    same = sum(x.astype(int) for x in s)
    ring = [s[k] for k in _RING]
    arcs = sum((ring[i] != ring[(i + 1) % 8]).astype(int) for i in range(8))
    out = (same <= SPECKLE_MAX_SAME) & ~((same == SPECKLE_MAX_SAME) & (arcs == 2))
    if not lines:
        for i in range(4):
            out &= ~(ring[i] & ring[i + 4])
    return out


def despeckle_depth(color: np.ndarray, depth: np.ndarray, luma: np.ndarray | None = None) -> np.ndarray:
    r"""Depth with stochastic-transparency speckle removed: a renderer's depth pass under a
    semi-transparent surface flips per pixel between the surface and what is behind it while the
    colour stays smooth. A *candidate* is a pixel whose depth class (neighbours within 0.8× of
    :math:`d_p` either way) has at most :data:`SPECKLE_MAX_SAME` of its 8 neighbours, not in one
    arc (:func:`speckle_candidates`: an object's corner is not a speckle).

    * A candidate whose luminance lies within the *robust* range of its other-depth neighbours'
      (between the second-darkest and the second-brightest of them, up to :data:`FRINGE_STEP`'s
      5 % outside it: its colour is explained without its own surface) takes the median depth of
      its 3×3. A candidate has at least 5 other-depth neighbours. A speckle under a smooth
      semi-transparent surface is inside that range; a 1-px lamp straddling two pixels, whose depth
      sample hit the lamp in one, is not: its bright twin is the only other-depth neighbour as
      bright as it, and one neighbour cannot explain it (docs/fidelity.md, "Held-out scenes").
    * A light seen through such a surface: a candidate not on a one-pixel line (a wire's pixels
      keep their depth) brighter than every other-depth neighbour, but by less than
      :data:`SAME_SOURCE`× the brightest of them (that neighbour is the same source) and by more
      than that the dimmest (a source above its surround), whose depth class is also seen on a
      candidate of its 5×5 dimmer than :math:`Y_p`/:data:`SAME_SOURCE`, no brighter than
      :data:`SAME_SOURCE`× that dimmest neighbour and not on a one-pixel line (a speckle of it
      showing the surround: the stochastic depth of a surface in front — a pane's — not the
      source's own; a lamp's own dimmer pixel is far above its surround), takes that brightest
      neighbour's depth. A lamp's own pixels keep theirs: their depth
      class is seen only on the lamp, or on a fixture at its depth (a pole, a wall: not a speckle).

    A wire, a lamp or a silhouette pixel brighter or darker than everything around it keeps its
    depth. Applied before the fringe rule (:func:`effective_depth`); docs/fidelity.md,
    "Transparent: stochastic depth"."""
    d = np.asarray(depth, dtype=np.float64)
    lum = np.asarray(color, dtype=np.float64)[..., :3] @ (luma_weights() if luma is None else luma)
    dn, ln = _neighbourhood(d), _neighbourhood(lum)
    lo, hi, hi_d = np.full_like(d, np.inf), np.full_like(d, -np.inf), d.copy()
    lo2, hi2 = lo.copy(), hi.copy()
    for dq, lq in zip(dn[1:], ln[1:]):
        s = _same_depth(dq, d)
        lo2 = np.where(s, lo2, np.minimum(lo2, np.maximum(lo, lq)))
        hi2 = np.where(s, hi2, np.maximum(hi2, np.minimum(hi, lq)))
        lo = np.where(s, lo, np.minimum(lo, lq))
        up = ~s & (lq > hi)
        hi_d, hi = np.where(up, dq, hi_d), np.where(up, lq, hi)
    cand = speckle_candidates(d)
    speckle = cand & (lum >= FRINGE_STEP * lo2) & (FRINGE_STEP * lum <= hi2)
    speck = speckle_candidates(d, lines=False)
    source = speck & (lum > hi) & (lum <= SAME_SOURCE * hi) & (lum > SAME_SOURCE * lo)
    h, w = d.shape
    pd, pl, pc = (np.pad(a, 2, mode="edge") for a in (d, lum, speck))
    dim = np.zeros(d.shape, bool)
    for b in range(5):
        for a in range(5):
            lq = pl[b:b + h, a:a + w]
            dim |= _same_depth(pd[b:b + h, a:a + w], d) & (SAME_SOURCE * lq < lum) & (lq <= SAME_SOURCE * lo) \
                & pc[b:b + h, a:a + w]
    out = np.where(speckle, np.median(np.stack(dn), axis=0), d)
    return np.where(source & dim, hi_d, out)


def effective_depth(color: np.ndarray, depth: np.ndarray, luma: np.ndarray | None = None) -> np.ndarray:
    r"""Depth with the colour/depth disagreement of anti-aliased edges resolved (the fringe rule of
    the module docstring); ``luma``: the working space's luminance weights (:func:`luma_weights`).

    In the 3×3 neighbourhood of p, the *near* pixels are those with :math:`d_q <` 0.8 :math:`d_p`
    and p's own surface those with :math:`d_q \ge` 0.8 :math:`d_p` (p included). p is a mix
    :math:`Y_p = \alpha Y_n + (1-\alpha) Y_f` of a near and a far surface; two hypotheses:

    * bright near (a light over the sky): :math:`Y_n` the brightest near pixel, :math:`Y_f` the
      darkest of p's surface; the near surface explains p when it covers at least half of it
      (:math:`\alpha \ge \tfrac12`) or brings at least half of its light
      (:math:`\alpha Y_n \ge \tfrac12 Y_p`) — the energy test is what catches a light's faint
      fringe, whose same-depth neighbours are equally bright fringe;
    * dark near (a pole over the sky): :math:`Y_n` the darkest near pixel, :math:`Y_f` the
      brightest of p's surface; it explains p when :math:`\alpha \ge \tfrac12`.

    Either needs a near surface that differs from p's own: brighter (darker) than every *other*
    pixel of p's surface by more than 1 − :data:`FRINGE_STEP` — a pane's depth speckle next to sky
    of the same colour, or a lamp's pixel next to the pane speckle in front of it (α > 1), is not a
    mix — or, for the bright one, a *light* far above p (:math:`Y_n >` :data:`SAME_SOURCE`
    :math:`\cdot Y_p`) whose 5 % (1 − :data:`FRINGE_STEP`) outshines the darkest pixel of p's
    surface (clamped to 0) and that covers at most :data:`LIGHT_FRINGE` (¼) of p
    (:math:`\alpha \le \tfrac14`: p is a faint fringe of it): a pixel of p's surface as bright as
    it is then the light's *twin* (a light straddling two pixels whose point-sampled depth hit it in
    one; the twin takes the near depth itself by the coverage test), not a surface that explains p.
    A white texel beside a white object's silhouette still is: on a grey wall the object's 5 % is
    below the wall, on a black one a grey texel between them is more than ¼ of the object. When either
    holds p takes the nearest depth of its 3×3. The depth is first despeckled
    (:func:`despeckle_depth`). With :math:`\alpha = (Y_p - Y_f)/(Y_n - Y_f)` both tests are
    written without a division. A depth only ever moves nearer; a pixel with no near neighbour
    keeps its own.

    The light's *tail*: a pixel left at its own depth takes the nearest depth of its 3×3 *after*
    the rule's bright hypothesis (a dark near surface is no light: a pixel it moved counts at its
    own depth) when the brightest neighbour that is near after it (:math:`Y_n`; :math:`Y_f`
    the darkest of the rest and p) is a light for p by the light clause (:math:`Y_n >`
    :data:`SAME_SOURCE` :math:`Y_p`, its 5 % above :math:`\max(Y_f, 0)`, :math:`\alpha \le`
    :data:`LIGHT_FRINGE`), brings at least half of p's light (:math:`\alpha Y_n \ge \tfrac12
    Y_p`), and p is more than :data:`SAME_SOURCE`× the third-brightest other pixel of its own
    surface (a light's tail sample, with at most two beside it along the light's edge; a texel of
    a textured surface has more as bright). The reach, two pixels past a depth sample, is the pixel filter's: Cycles' default
    Blackman–Harris of width 1.5 px samples offsets up to ±1.5 px (its table spans twice the width),
    so a lamp's light lands up to 2 pixels from any pixel it covers — as single samples
    (docs/fidelity.md, "In-focus halos"). Without a neighbour moved by the bright hypothesis the test is the
    light clause on the raw depths, which p failed: only pixels next to moved ones can change
    (the kernel skips the rest on per-group flags)."""
    d = despeckle_depth(color, depth, luma)
    lum = np.asarray(color, dtype=np.float64)[..., :3] @ (luma_weights() if luma is None else luma)
    dn, ln = _neighbourhood(d), _neighbourhood(lum)
    nearest = np.minimum.reduce(dn)
    bright_n, dark_n = np.full_like(d, -np.inf), np.full_like(d, np.inf)  # near pixels' extremes
    other_min, other_max = np.full_like(d, np.inf), np.full_like(d, -np.inf)  # p's own surface, p excluded
    for dq, lq in zip(dn[1:], ln[1:]):
        near = dq < MIXED_SAME_DEPTH * d
        bright_n = np.where(near, np.maximum(bright_n, lq), bright_n)
        dark_n = np.where(near, np.minimum(dark_n, lq), dark_n)
        other_min = np.where(near, other_min, np.minimum(other_min, lq))
        other_max = np.where(near, other_max, np.maximum(other_max, lq))
    own_min, own_max = np.minimum(other_min, lum), np.maximum(other_max, lum)
    with np.errstate(invalid="ignore"):
        span, part = bright_n - own_min, lum - own_min
        light = (bright_n > SAME_SOURCE * lum) & ((1 - FRINGE_STEP) * bright_n > np.maximum(own_min, 0)) \
            & (part <= LIGHT_FRINGE * span)
        bright = (span > 0) & ((2 * part >= span) | (2 * part * bright_n >= lum * span)) \
            & ((FRINGE_STEP * bright_n > other_max) | light)
        span, part = own_max - dark_n, own_max - lum
        dark = (span > 0) & (2 * part >= span) & (dark_n < FRINGE_STEP * other_min)
    first = np.where(bright | dark, nearest, d)
    # the light's tail (docstring): the light clause on the 3×3's depths after the rule's bright hypothesis
    en = _neighbourhood(np.where(bright, nearest, d))
    bright_n, own_min = np.full_like(d, -np.inf), lum.copy()
    hi, hi2, hi3 = (np.full_like(d, -np.inf) for _ in range(3))  # p's own surface, p excluded
    for eq, lq in zip(en[1:], ln[1:]):
        near = eq < MIXED_SAME_DEPTH * d
        bright_n = np.where(near, np.maximum(bright_n, lq), bright_n)
        own_min = np.where(near, own_min, np.minimum(own_min, lq))
        hi3 = np.where(near, hi3, np.maximum(hi3, np.minimum(hi2, lq)))
        hi2 = np.where(near, hi2, np.maximum(hi2, np.minimum(hi, lq)))
        hi = np.where(near, hi, np.maximum(hi, lq))
    with np.errstate(invalid="ignore"):
        span, part = bright_n - own_min, lum - own_min
        tail = ~(bright | dark) & (span > 0) & (2 * part * bright_n >= lum * span) \
            & (bright_n > SAME_SOURCE * lum) & ((1 - FRINGE_STEP) * bright_n > np.maximum(own_min, 0)) \
            & (part <= LIGHT_FRINGE * span) & (lum > SAME_SOURCE * hi3)
    return np.where(tail, np.minimum.reduce(en), first)


# ---------------------------------------------------------------------------------------------
# Aperture shape, texture and pupil (cat's-eye)
# ---------------------------------------------------------------------------------------------


def aperture_radius(phi: np.ndarray, blades: int, rotation_deg: float, roundness: float) -> np.ndarray:
    r"""Radius ρ(φ) of the unit aperture in screen direction φ (atan2(y, x), y down)."""
    phi = np.asarray(phi, dtype=np.float64)
    if blades == 0:
        return np.ones_like(phi)
    seg = 2 * math.pi / blades
    phi0 = -math.pi / 2 - math.radians(rotation_deg)  # corner at the top; + turns counter-clockwise
    t = np.mod(phi - phi0, seg) - seg / 2
    poly = math.cos(math.pi / blades) / np.cos(t)
    return (1.0 - roundness) * poly + roundness


def aperture_area(blades: int, rotation_deg: float, roundness: float) -> float:
    r""":math:`a_K = \frac12\oint\rho^2\,d\phi` (π for a circle, :math:`\frac N2\sin\frac{2\pi}N` for an N-gon)."""
    phi = (np.arange(8192) + 0.5) * (2 * math.pi / 8192)
    return float(0.5 * np.mean(aperture_radius(phi, blades, rotation_deg, roundness) ** 2) * 2 * math.pi)


@dataclass(frozen=True)
class PupilModel:
    """The pupil's shape at a field point, as the gather uses it: the aperture polygon intersected
    with a barrel circle (same radius) displaced by ``strength · h`` aperture radii.

    A lens tracer can replace this with its exit-pupil outline per field height; the gather only
    needs ``inside(a, h)`` (coverage of aperture point a at field position h) and ``area_fraction``.
    """

    strength: float = 0.0

    def barrel_centre(self, h: np.ndarray) -> np.ndarray:
        """Centre of the front barrel circle (the rear one mirrors it): ``strength · h / 2``."""
        return 0.5 * self.strength * np.asarray(h, dtype=np.float64)

    def area_fraction(self, h_norm: np.ndarray) -> np.ndarray:
        r"""Area of unit disc ∩ unit disc at distance d = η·min(|h|, 1), over π (≥ 0.39 as η ≤ 1;
        padding beyond the corners counts as the corner)."""
        d = self.strength * np.minimum(np.asarray(h_norm, dtype=np.float64), 1.0)
        return (2 * np.arccos(d / 2) - d / 2 * np.sqrt(4 - d * d)) / math.pi


def field_position(x: np.ndarray, y: np.ndarray, w: int, h: int) -> tuple[np.ndarray, np.ndarray]:
    """Field position (x, y) over the half diagonal from the image centre (|h| = 1 at a corner)."""
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    half = math.hypot(w / 2.0, h / 2.0)
    return (x - cx) / half, (y - cy) / half


@lru_cache(maxsize=32)
def tap_table(rmax: int, blades: int, rotation_deg: float, roundness: float):
    """All integer offsets o = q − p with |o| < rmax + 1, sorted by |o|; per tap
    ``(dx, dy, |o|, ρ_far, ρ_near)`` (ρ in the aperture direction of p − q for a far source,
    q − p for a near one) and ``ntaps[k]`` = number of taps with |o| < k + 1."""
    r = rmax + 1
    dy, dx = np.mgrid[-r:r + 1, -r:r + 1]
    dx, dy = dx.ravel(), dy.ravel()
    dist = np.hypot(dx, dy)
    keep = dist < rmax + 1
    dx, dy, dist = dx[keep], dy[keep], dist[keep]
    order = np.lexsort((dx, dy, dist))
    dx, dy, dist = dx[order], dy[order], dist[order]
    rho_far = aperture_radius(np.arctan2(-dy, -dx), blades, rotation_deg, roundness)
    rho_near = aperture_radius(np.arctan2(dy, dx), blades, rotation_deg, roundness)
    ntaps = np.array([np.count_nonzero(dist < k + 1) for k in range(rmax + 1)], np.int32)
    return dx.astype(np.int32), dy.astype(np.int32), dist, rho_far, rho_near, ntaps


LIGHT_LUMA = 8.0
"""A stride-1 tap whose colour's Rec. 709 luma (:data:`LIGHT_LUMA_WEIGHTS`) exceeds this (13× the
test scenes' diffuse white) is a *light*: its disc edge takes the :data:`LIGHT_RAMP_PX` ramp. The
input is already pixel-filtered, so the 1-px ramp on a small bright source widens its disc by a
visible pixel (emitters lamp09 1.235× the truth's area); the threshold is not critical (2-16 swept,
docs/fidelity.md, "Small lights and the layer's coverage ramp", `rl2`)."""
LIGHT_LUMA_WEIGHTS = (0.2126, 0.7152, 0.0722)
LIGHT_RAMP_PX = 0.25
"""Width (px) of a light tap's disc-edge coverage ramp (every other tap: max(s/2, 1) px). In the
colour sums a light's weight is rescaled by N₁(r)/N_¼(r) (:func:`light_sums`), so its disc holds
the lattice sum of the 1-px ramp's; the normalising sums keep every tap's 1-px weight, so a light
keeps its energy and a constant field of lights stays flat. A light in p's front layer (added
unnormalised) takes 1/N_¼(r): exactly its energy. In final's full-resolution gather only (draft's
and preview's lights take the narrow layer, whose ramp is the same), and only where the narrow
layer splits lights (:func:`narrow_split`: no cat's-eye bokeh, no traced profile): N₁/N_¼ are the
sums of the unclipped parametric disc (its texture included), a cat's-eye disc's (cut by a second,
1-px edge) and a traced profile's (a per-channel radial texture) differ — with the rescale a
corner point light kept 0.985 of its energy (η = 1). The kernel runs this only in level-0 tiles
with a light within one tile (dof_tile_max, dof_tile_dilate): as a test in every tap it cost
final 25–45 % (docs/fidelity.md, "Final's lights: the ¼-px ramp")."""
LIGHT_RMAX_PX = 8.0
"""Lights with bokeh radius r at or above this keep the 1-px ramp (in front: divided by N₁(r))."""
LIGHT_SMALL_PX = (1.0, math.sqrt(2.0))
r"""A light whose bokeh radius r lies in [lo, hi) spreads with the 3×3's separable weight
:math:`w(o_x)\,w(o_y)`, w(0) = 1 − 2a, w(±1) = a, a = :func:`local_weight` of r, instead of a disc
(in the colour sums, × N₁(r) behind p's front layer; exactly its energy in front: the weights sum
to 1): the rule of the half-resolution path's small layer over the same range
(:data:`NARROW_SPREAD_PX` … :data:`NARROW_FOCUS_PX`, :func:`small_layer`), so every quality spreads
such a light alike. The disc's ¼-px ramp is wrong there: a disc under √2 px is smaller than the
pixel it spreads, whose light also reaches the diagonal neighbours — a 2×2-px square emitter at
60× blurred by the hexagon of r = 1.2 px saturates 16 pixels (continuous convolution, box or
Blackman–Harris pixel filter), the 3×3 16, the ¼-px disc 12 (diagonals out of reach). Below lo
the ¼-px disc reaches no neighbour at all, as the small layer adds none below
:data:`NARROW_SPREAD_PX` (an in-focus light keeps its light on its own pixels)."""
LIGHT_TABLE_R = (0.5, 17.0, 1651)
"""r grid (first, last, count; step 0.01 px) of :func:`light_sums`; beyond it the ends hold."""


def _disc_lattice_sums(blades: int, rotation_deg: float, roundness: float, sa: float, ramps):
    """The lattice sums :func:`light_sums` and :func:`texture_sums` are built from: r on
    :data:`LIGHT_TABLE_R`, and per layer (far: a = −σ, then near: a = +σ; ρ as :func:`tap_table`)
    and per ramp of ``ramps``, (Σ_o cov(o), Σ_o cov(o) (1 + a(2t² − 1))), cov(o) = clip((r ρ(o) −
    |o|)/ramp + ½, 0, 1), t = min(|o|/(r ρ), 1), over every integer offset o."""
    r0, r1, n = LIGHT_TABLE_R
    rs = np.linspace(r0, r1, n)
    _, _, dists, rf, rn, _ = tap_table(int(math.ceil(r1)) + 1, blades, rotation_deg, roundness)
    sums = []
    for rho, a in ((rf, -sa), (rn, sa)):
        rr = rs[:, None] * rho[None, :]
        t = np.minimum(dists[None, :] / rr, 1.0)
        tex = 1.0 + a * (2.0 * t * t - 1.0)
        for ramp in ramps:
            cov = np.clip((rr - dists[None, :]) / ramp + 0.5, 0.0, 1.0)
            sums.append((cov.sum(axis=1), (cov * tex).sum(axis=1)))
    return rs, sums


def light_sums(blades: int, rotation_deg: float, roundness: float, sa: float = 0.0) -> np.ndarray:
    """(4, n) lattice sums of a light's disc, r on :data:`LIGHT_TABLE_R` (linear in between): rows
    N₁(r), N_¼(r) of a far light, then of a near one, N(r) = Σ_o clip((r ρ(o) − |o|)/ramp + ½, 0, 1)
    (1 + a(2t² − 1)) / (a_K r²) over every integer offset o, for the 1-px and :data:`LIGHT_RAMP_PX`
    ramps, with the gather's texture (a = −σ far, +σ near, t = min(|o|/(r ρ), 1); ρ of the far or
    near layer's direction, as :func:`tap_table`). N is not 1 at small r (6 blades, σ = 0: 1.05 at
    r = 1, 1.10 at 1.2, 1.07 at 2.11) and differs between the ramps; without the texture in it the
    rescale N₁/N_¼ cost a light 2–10 % of its energy at σ = ±0.6."""
    rs, sums = _disc_lattice_sums(blades, rotation_deg, roundness, sa, (1.0, LIGHT_RAMP_PX))
    area = aperture_area(blades, rotation_deg, roundness)
    return np.stack([na / (area * rs * rs) for _, na in sums])


def texture_sums(blades: int, rotation_deg: float, roundness: float, sa: float) -> np.ndarray:
    r"""(4, n) texture rescale of the half-resolution gather, r/s (lattice units) on
    :data:`LIGHT_TABLE_R`, laid out as :func:`light_sums` (rows far ramp 1, far ramp ½, near ramp 1,
    near ramp ½; :func:`light_sum_at` reads it): :math:`N(r; 0)/N(r; a)`, N(r; a) = Σ_o cov(o)
    (1 + a(2t² − 1)) over every integer offset (a = −σ far, +σ near, t = min(|o|/(rρ), 1)) with
    the 1-px ramp (stride 1) or the ramp of half a lattice step (stride ≥ 2). ∫ I = ∫ 1, but on the
    lattice of a small disc the texture's rim value fills the whole coverage ramp beyond the edge:
    at r = 0.96 px (6 blades) N = 1.225 at a = +0.6, 1.081 at 0, 0.937 at −0.6 — a near light
    in a far wall's front layer (added unnormalised) kept that much more or less of its light
    (docs/fidelity.md, "Lights under the spherical-aberration texture"). 1 where N(r; a) ≤ 0
    (|σ| = 1)."""
    _, sums = _disc_lattice_sums(blades, rotation_deg, roundness, sa, (1.0, 0.5))
    return np.stack([np.where(na > 0, n0 / np.where(na > 0, na, 1.0), 1.0) for n0, na in sums])


def light_sum_at(table: np.ndarray, r: np.ndarray, far: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N₁(r), N_¼(r)) of :func:`light_sums`' ``table`` for a far (``far``) or near light, linear in
    r, ends clamped."""
    r0, r1, n = LIGHT_TABLE_R
    f = np.clip((r - r0) * ((n - 1) / (r1 - r0)), 0.0, n - 1)
    i0 = np.minimum(np.floor(f).astype(int), n - 2)
    a = f - i0
    return tuple(np.where(far, t[i0] + (t[i0 + 1] - t[i0]) * a, u[i0] + (u[i0 + 1] - u[i0]) * a)
                 for t, u in ((table[0], table[2]), (table[1], table[3])))


# ---------------------------------------------------------------------------------------------
# The float64 reference of the whole stage
# ---------------------------------------------------------------------------------------------


def _working(color: np.ndarray, coc: np.ndarray, scale: int):
    """Working-resolution colour (s×s box mean) and CoC (nearest = min signed, in working px);
    odd sizes replicate the last row/column."""
    if scale == 1:
        return color, coc
    h, w = coc.shape
    hw, ww = -(-h // scale), -(-w // scale)
    pc = np.pad(color, ((0, hw * scale - h), (0, ww * scale - w), (0, 0)), mode="edge")
    pr = np.pad(coc, ((0, hw * scale - h), (0, ww * scale - w)), mode="edge")
    cw = pc.reshape(hw, scale, ww, scale, 3).mean(axis=(1, 3))
    rw = pr.reshape(hw, scale, ww, scale).min(axis=(1, 3)) / scale
    return cw, rw


def levels_for(rmax: int, budget: int) -> int:
    r"""Number of prefiltered levels above level 0: strides 1, 2, …, 2^L with
    :math:`\lceil r_{max}/2^L - \tfrac12\rceil \le` ``budget``."""
    lv = 0
    while math.ceil(rmax / 2 ** lv - 0.5) > budget:
        lv += 1
    return lv


def gather_pad(rmax: int, budget: int) -> int:
    """Border (working px) the padded buffers need: the farthest lattice tap, s (R_b + 1)."""
    return 2 ** levels_for(rmax, budget) * (budget + 1) + 1


def tent_weights(s: int) -> np.ndarray:
    """1-D tent of half-width s, :math:`w_j = (s-|j|)/s^2`, |j| < s (sums to 1; its 2-D product
    is a partition of unity over the lattice sZ², which is what makes the lattice gather conserve
    energy)."""
    j = np.arange(-(s - 1), s)
    return (s - np.abs(j)) / float(s * s)


def _shift_clamped(a: np.ndarray, off: int, axis: int) -> np.ndarray:
    """a[i + off] along ``axis`` with the index clamped to the array (edge replicated)."""
    n = a.shape[axis]
    idx = np.clip(np.arange(n) + off, 0, n - 1)
    return np.take(a, idx, axis=axis)


def prefiltered_levels(pc: np.ndarray, pr: np.ndarray, nlevels: int):
    r"""Level ℓ (stride s = 2^ℓ) of the padded working buffers: colour filtered by the separable
    tent of half-width s (:func:`tent_weights`), CoC by the min (nearest, signed) over the same
    (2s−1)² window, so a tap that straddles an in-focus edge counts as in focus and never spreads
    the edge's colour.

    Built recursively, 3 taps per pass per level: :math:`\mathrm{tent}_{2s} = \mathrm{tent}_s *
    	frac14(\delta_{-s} + 2\delta_0 + \delta_s)` (a tent is a box convolved with itself, and
    :math:`\mathrm{box}_{2s} = \mathrm{box}_s * 	frac12(\delta_0 + \delta_s)`); the min window
    of width 4s−1 is the union of the three windows of width 2s−1 at −s, 0, s. Reads beyond the
    padded buffer are clamped, exactly as the kernel does."""
    cols, cocs = [pc], [pr]
    for lv in range(nlevels):
        s = 2 ** lv
        c, r = cols[-1], cocs[-1]
        for ax in (1, 0):
            c = 0.25 * (_shift_clamped(c, -s, ax) + 2.0 * c + _shift_clamped(c, s, ax))
            r = np.minimum(np.minimum(_shift_clamped(r, -s, ax), r), _shift_clamped(r, s, ax))
        cols.append(c)
        cocs.append(r)
    return cols, cocs


def reach_rmax(rmax: int, reach: float) -> int:
    """Largest tap reach (working px) of a gather whose bokeh reaches ``reach`` × its CoC radius
    (a traced profile: :data:`clpost.optics.pencil.T_MAX`; else 1)."""
    return int(math.ceil(rmax * reach))


TRIM_LATTICE = 0.515625
"""The tile plan's tap count keeps the taps nearer than R/s + this (lattice units; dof_tile_dilate):
a source of reach R covers out to R + ramp/2 px (ramp max(s/2, 1) px), i.e. R/s + 1/2 at stride
1 and R/s + 1/4 above, so the taps beyond have coverage exactly 0; 1/64 (exact in binary) more
keeps the float rounding of the coverage's ramp on the safe side."""


def tile_plan(coc: np.ndarray, rmax: int, budget: int, reach: float = 1.0,
              route: bool = False) -> tuple[np.ndarray, np.ndarray]:
    r"""Per tile (Jimenez 2014: tile max, dilated by the reach of the neighbouring tiles) the
    lattice level ℓ and tap count: R = the largest reach (``reach`` × |CoC|) that can reach a
    pixel of the tile, ℓ the smallest level with :math:`k = \lceil R/2^\ell - \tfrac12\rceil \le R_b`,
    taps = ntaps[k] of the unit lattice table. Returns per-pixel (level, count) arrays.

    Depth-aware dilation: a source behind every pixel of the tile (signed CoC above the tile's
    largest, :math:`r_{hi}`, by more than :data:`FRONT_MARGIN_PX`) is clamped to the pixel's own
    radius by the gather (the background clamp), so it never reaches farther than the tile's own
    CoC. A neighbouring tile with signed CoC range :math:`[r^N_{lo}, r^N_{hi}]` therefore
    dilates by :math:`\max(|r^N_{lo}|, |\min(r^N_{hi}, r_{hi} + m)|)`, and not at all when
    :math:`r^N_{lo} > r_{hi} + m` — a wall tile beside a farther, blurrier sky keeps the wall's
    own stride (docs/fidelity.md, "The lattice's own blur"). ``route``: the levels of the same
    rule with every neighbour's |CoC| (depth order ignored), by which final's mixed resolution
    routes tiles (:func:`mixed_mask`; the depth-aware levels would send more tiles to the 4×
    costlier full-resolution gather). Float32 as the kernel (``dof_tile_dilate``)."""
    h, w = coc.shape
    tw, th = -(-w // TILE), -(-h // TILE)
    rmax = reach_rmax(rmax, reach)
    f32 = np.float32
    a = np.pad(np.asarray(coc).astype(f32), ((0, th * TILE - h), (0, tw * TILE - w)), mode="edge")
    blocks = a.reshape(th, TILE, tw, TILE)
    lo, hi = blocks.min(axis=(1, 3)), blocks.max(axis=(1, 3))
    table = tap_table(budget, 0, 0.0, 0.0)
    ntaps, tap_dist = table[5], table[2].astype(f32)
    reach_t = (rmax + TILE) // TILE
    lvl = np.zeros((th, tw), int)
    cnt = np.zeros((th, tw), int)
    for ty in range(th):
        for tx in range(tw):
            r = 0.5
            top = f32(hi[ty, tx] + f32(FRONT_MARGIN_PX))
            for ny in range(max(ty - reach_t, 0), min(ty + reach_t, th - 1) + 1):
                for nx in range(max(tx - reach_t, 0), min(tx + reach_t, tw - 1) + 1):
                    if lo[ny, nx] > top and not route:
                        continue  # behind every pixel of the tile: clamped to their own radius
                    gx = max(0, abs(nx - tx) * TILE - (TILE - 1))
                    gy = max(0, abs(ny - ty) * TILE - (TILE - 1))
                    near = hi[ny, nx] if route else min(hi[ny, nx], top)
                    m = f32(max(abs(lo[ny, nx]), abs(near)) * f32(reach))
                    if f32(m + f32(0.5)) > f32(math.sqrt(gx * gx + gy * gy)):
                        r = max(r, float(m))
            lv = 0
            while math.ceil(r / 2 ** lv - 0.5) > budget:
                lv += 1
            lvl[ty, tx] = lv
            n = ntaps[min(max(math.ceil(r / 2 ** lv - 0.5), 0), budget)]
            # only the taps nearer than R/s + 1/2 + 1/64 (the ring out to k + 1 has coverage 0 for
            # every source that dilated the tile), never fewer than the 3x3 (LIGHT_SMALL_PX's weight)
            bound = f32(f32(f32(r) / f32(2 ** lv)) + f32(TRIM_LATTICE))
            cnt[ty, tx] = n if n <= 9 else max(int(np.count_nonzero(tap_dist[:n] < bound)), 9)
    expand = np.ones((TILE, TILE), int)
    return np.kron(lvl, expand)[:h, :w], np.kron(cnt, expand)[:h, :w]


def gather_reference(color: np.ndarray, coc: np.ndarray, rmax: int, budget: int, blades: int,
                     rotation_deg: float, roundness: float, sa: float,
                     vignetting: float, profile=None, lights: bool = True,
                     split=None) -> tuple[np.ndarray, np.ndarray]:
    """The lattice gather in float64 (see the module docstring), tile plan included. ``profile``:
    ``(PencilMap, scale)`` of a traced lens (the traced texture, per channel; ``sa`` unused) or
    None. ``lights``: the full-resolution gather's lights (:data:`LIGHT_RAMP_PX`; not at half
    resolution, whose working pixels are 2×2 box means — a second pixel footprint, so the ¼-px
    ramp's premise does not hold there — and whose lights the narrow layer spreads). ``split``:
    None, or per pixel ``(D, O, b, r_o)`` (H×W×3, H×W×3, H×W, H×W): each source pixel q becomes two
    sources, its own layer's colour D_q with share 1 − b_q at its own CoC and another layer's
    colour O_q with share b_q at CoC r_o (an anti-aliased edge pixel's two surfaces), at stride 1
    and in the centre tap; b = 0 everywhere is the one-source gather to the bit. Only the
    measurement of docs/fidelity.md, "Splitting the edge pixels into two layers"
    (tools/dof_edge_split.py), passes it; the kernels have no such input. Returns
    (colour, front coverage α of green)."""
    h, w = coc.shape
    lights_arg = lights
    if split is not None:
        sp_d, sp_o, sp_b, sp_r = split
    reach = pencil.T_MAX if profile is not None else 1.0
    dxs, dys, dists, rf, rn, _ = tap_table(budget, blades, rotation_deg, roundness)
    area = aperture_area(blades, rotation_deg, roundness)
    lsum = light_sums(blades, rotation_deg, roundness, sa)
    lights = lights and profile is None and vignetting <= 0  # narrow_split's rule (LIGHT_RAMP_PX)
    tsum = (texture_sums(blades, rotation_deg, roundness, sa)
            if not lights_arg and profile is None and sa != 0 else None)
    nlev = levels_for(reach_rmax(rmax, reach), budget)
    pad = gather_pad(reach_rmax(rmax, reach), budget)
    pc = np.pad(color, ((pad, pad), (pad, pad), (0, 0)), mode="edge")
    pr = np.pad(coc, pad, mode="edge")
    cols, cocs = prefiltered_levels(pc, pr, nlev)
    lvl, cnt = tile_plan(coc, rmax, budget, reach)
    s = (2 ** lvl).astype(np.float64)
    ys, xs = np.mgrid[0:h, 0:w]
    pupil = PupilModel(vignetting)
    rp = coc
    # centre tap: own colour blended toward the level's prefiltered colour as p's own bokeh grows
    # past the lattice spacing (a point light's centre must not stay a one-pixel spike)
    beta = np.clip(np.abs(rp) / s, 0.0, 1.0)
    own = pc[pad:pad + h, pad:pad + w]
    lvl_c = np.stack(cols)[lvl, ys + pad, xs + pad]
    F = np.zeros((h, w, 3)); Wf = np.zeros((h, w, 3))  # per channel: a traced profile differs
    B = np.zeros((h, w, 3)); Wb = np.zeros((h, w, 3))  # per colour (axial colour)
    col_stack, coc_stack = np.stack(cols), np.stack(cocs)
    # the background hidden behind p (HIDDEN_BG): the behind taps' colour estimate and weights
    H = np.zeros((h, w, 3)); Hk = np.zeros((h, w)); Wh = np.zeros((h, w, 3))
    dmin = np.full((h, w), np.inf)
    ramp = np.maximum(s / 2, 1.0)
    for k in range(int(cnt.max())):
        live = k < cnt
        dx = (s * dxs[k]).astype(int)
        dy = (s * dys[k]).astype(int)
        dist = s * dists[k]
        if k == 0:
            rq = rp
            cq = own + (lvl_c - own) * beta[..., None]
        else:
            rq = coc_stack[lvl, ys + pad + dy, xs + pad + dx]
            cq = col_stack[lvl, ys + pad + dy, xs + pad + dx]
        if split is None:
            srcs = ((cq, rq, None),)
        elif k == 0:
            bo = np.clip(np.abs(sp_r) / s, 0.0, 1.0)[..., None]
            srcs = ((sp_d + (lvl_c - sp_d) * beta[..., None], rq, 1.0 - sp_b),
                    (sp_o + (lvl_c - sp_o) * bo, sp_r, sp_b))
        else:
            yq, xq = np.clip(ys + dy, 0, h - 1), np.clip(xs + dx, 0, w - 1)
            one = s == 1
            bq = np.where(one, sp_b[yq, xq], 0.0)
            srcs = ((np.where(one[..., None], sp_d[yq, xq], cq), rq, 1.0 - bq),
                    (sp_o[yq, xq], np.where(one, sp_r[yq, xq], rq), bq))
        for cq, rq, share in srcs:
            front = rq < rp - FRONT_MARGIN_PX
            behind = rq > rp + FRONT_MARGIN_PX
            r = np.where(behind, np.maximum(np.abs(rp), 0.5), np.maximum(np.abs(rq), 0.5))
            far = rq >= 0
            # a tap behind p, clamped to p's radius, takes p's layer's texture (a far wall's taps behind
            # a near light: the light's own pixel is normalised against its own disc's texture)
            texfar = np.where(behind, rp >= 0, far)
            # the texture at half resolution: its lattice sum kept the untextured one's (texture_sums)
            tscale = 1.0
            if tsum is not None:
                t1, th = light_sum_at(tsum, r / s, texfar)
                tscale = np.where(s >= 2, th, t1)
            rho = np.where(far, rf[k], rn[k])
            rr = r * rho
            cov = np.clip((rr * reach - dist) / ramp + 0.5, 0.0, 1.0)
            # a light (LIGHT_LUMA): the LIGHT_RAMP_PX ramp in the colour sums, rescaled by its lattice
            # sums; `cov` (1-px ramp) stays the normalising weight
            bright = (s == 1) & lights & (cq @ np.array(LIGHT_LUMA_WEIGHTS) > LIGHT_LUMA)
            n1, n4 = light_sum_at(lsum, r, far)
            # (a texture of |σ| = 1 can zero a small disc's sums: such a light keeps the 1-px ramp)
            light = bright & (r < LIGHT_RMAX_PX) & (n4 > 0)
            n1s, n4s = np.where(n1 > 0, n1, 1.0), np.where(n4 > 0, n4, 1.0)
            ramp_l = np.clip((rr * reach - dist) / LIGHT_RAMP_PX + 0.5, 0.0, 1.0)
            cov_c = np.where(light, ramp_l * np.where(front, 1.0, n1) / n4s,
                             np.where(front & bright, cov / n1s, cov))
            # a small light (LIGHT_SMALL_PX): the 3×3's separable weight, texture-free, as the whole
            # colour weight (lights: no profile, no vignetting, s = 1)
            small = light & (r >= LIGHT_SMALL_PX[0]) & (r < LIGHT_SMALL_PX[1])
            aw = local_weight(r)
            near3 = (np.abs(dx) <= 1) & (np.abs(dy) <= 1)
            sep = np.where(near3, np.where(dx != 0, aw, 1.0 - 2.0 * aw) * np.where(dy != 0, aw, 1.0 - 2.0 * aw), 0.0)
            w_small = sep * np.where(front, 1.0, n1)
            if profile is None:
                t = np.minimum(dist / rr, 1.0)
                a = np.where(texfar, -sa, sa)
                g = (1.0 + a * (2 * t * t - 1.0)) * tscale * s * s / (area * r * r)
                prof = np.ones(3)
            else:
                g = s * s / (area * r * r)
                prof = profile_weight(profile, rq, dist / rr)
            if vignetting > 0:
                # the pupil at the midpoint of p and q, and the mean of their 1/φ: w(p, q) = w(q, p),
                # so a point light keeps its energy through the normalisation (module docstring)
                hqx, hqy = field_position(xs + dx, ys + dy, w, h)
                hx, hy = field_position(xs + 0.5 * dx, ys + 0.5 * dy, w, h)
                sgn = np.where(far, 1.0, -1.0)
                ax, ay = -dx / (r * sgn), -dy / (r * sgn)
                bx, by = pupil.barrel_centre(hx), pupil.barrel_centre(hy)
                e = np.maximum(np.hypot(ax - bx, ay - by), np.hypot(ax + bx, ay + by))
                inv_phi = 0.5 * (1.0 / pupil.area_fraction(np.hypot(*field_position(xs, ys, w, h)))
                                 + 1.0 / pupil.area_fraction(np.hypot(hqx, hqy)))
                g = g * np.clip((1.0 - e) * r + 0.5, 0.0, 1.0) * inv_phi
            g = np.where(live, g if share is None else g * share, 0.0)[..., None] * prof
            wgt = np.where(small[..., None], np.where(live, w_small if share is None else w_small * share, 0.0)[..., None], g * cov_c[..., None])
            wf = np.where(front[..., None], wgt, 0.0)
            F += wf * cq; Wf += wf
            hid = behind & live & (np.abs(rq) < np.abs(rp) - HIDDEN_MARGIN_PX)
            if share is not None:
                hid = hid & (share > 0)
            wh = np.where(hid[..., None], wgt, 0.0)
            Wh += wh
            B += (wgt - wf - wh) * cq; Wb += np.where(front[..., None], 0.0, g * cov[..., None])
            # the estimate's kernel: the background's own radius (at most p's), widened to the
            # nearest behind tap (taps come in distance order): the hidden surface's colour at p
            dmin = np.where(hid & np.isinf(dmin), dist, dmin)
            rh = np.maximum(np.maximum(np.abs(rq), 0.5), dmin + 0.5 * ramp)
            kh = np.where(hid, np.clip((rh - dist) / ramp + 0.5, 0.0, 1.0), 0.0)
            if share is not None:
                kh = kh * share
            H += kh[..., None] * cq; Hk += kh
    B += Wh * np.where(Hk[..., None] > 0, H / np.where(Hk > 0, Hk, 1.0)[..., None], 0.0)
    alpha = np.minimum(1.0, Wf)
    fr = np.where(Wf > 0, F / np.where(Wf > 0, Wf, 1.0), 0.0)
    # no background weight at all (a strong spherical-aberration texture zeroes the centre tap
    # and every other tap is in front): the background is the pixel's own colour, never 0/0
    bg = np.where(Wb > 0, B / np.where(Wb > 0, Wb, 1.0), own)
    out = alpha * fr + (1 - alpha) * bg
    return out, alpha[..., 1]


HIDDEN_MARGIN_PX = 1.0

PROFILE_RMAX_PX = 64.0
"""Signed CoC radius (output px) of the pencil map's outermost rows: the largest max_coc_px of
any quality, so one map serves them all."""


def traced_profile(camera, width_px: int, quality: str | None = None):
    """The :class:`clpost.optics.pencil.PencilMap` of ``camera``'s traced lens at its focus and
    f-number, rows in output pixels up to ±:data:`PROFILE_RMAX_PX` (the gather looks rows up with
    the tap's CoC × the working-resolution divisor), or None for a thin lens (the parametric
    texture ``spherical_aberration`` then). Built once per (lens, f-number, sensor, width) and
    focus within :data:`PROFILE_FOCUS_TOLERANCE`, for every quality, and kept (cost:
    docs/bokeh_profile.md)."""
    entry = traced_profile_entry(camera, width_px)
    return None if entry is None else entry[1]


def traced_profile_entry(camera, width_px: int):
    """(key, PencilMap) of :func:`traced_profile`: the key names the table's content (lens,
    f-number, sensor, width, the focus it was traced at) for device caches; None for a thin lens."""
    if camera.optics is None:
        return None
    focus = float(camera.focus_distance_m)
    near = [k for k in _PROFILES if k[:4] == (camera.lens, camera.f_number, camera.sensor_mm, int(width_px))
            and _same_focus(k[4], focus)]
    if near:  # a focus pull: a table within PROFILE_FOCUS_TOLERANCE of this focus serves it
        key = min(near, key=lambda k: abs(math.log(k[4] / focus)) if math.isfinite(k[4] * focus) else 0.0)
        _PROFILES[key] = _PROFILES.pop(key)  # most recently used last
        return key, _PROFILES[key]
    key = (camera.lens, camera.f_number, camera.sensor_mm, int(width_px), focus)
    if len(_PROFILES) >= 32:
        _PROFILES.pop(next(iter(_PROFILES)))
    _PROFILES[key] = pencil.build_pencil_map(camera, camera.pixel_pitch_mm(width_px), PROFILE_RMAX_PX)
    return key, _PROFILES[key]


PROFILE_FOCUS_TOLERANCE = 0.01
"""A traced profile built at focus s serves focus distances within ±1 % of s (a focus pull builds a
table per 2 % of focus travel, not per frame): the Planar 1.4/50's table at 2.02 m differs from the
one at 2 m by ≤ 3.1 % of its peak in its worst bin, 0.05 % RMS (docs/bokeh_profile.md)."""

_PROFILES: dict = {}


def _same_focus(a: float, b: float) -> bool:
    if not (math.isfinite(a) and math.isfinite(b)):
        return a == b
    return abs(math.log(a / b)) <= math.log1p(PROFILE_FOCUS_TOLERANCE)


def profile_weight(profile, rq: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(…, 3) traced texture of a tap: ``profile`` = (PencilMap, working-resolution divisor), ``rq``
    the source's signed CoC (working px), ``t`` its distance over its bokeh radius."""
    pm, scale = profile
    return pencil.profile_at(pm, rq * scale, t)


UPSAMPLE_COC_TOL_PX2 = 0.125
"""τ (px²) of the depth-aware upsampling's CoC similarity 1/(τ + Δr²) (:func:`_upsample`): a
working corner 2.2 px of CoC away weighs 1/40 of a same-CoC one, which an HDR lamp next to a
slightly blurred surface needs (the choice of τ measured in docs/fidelity.md, "The upsampling's
CoC comparison")."""


UPSAMPLE_SAME_PX = 1.0
"""A working corner whose CoC differs from the pixel's by more than this (px) is another surface:
when one corner with a bilinear weight is within it, the others get weight 0 (:func:`_upsample`)."""


def _upsample(img: np.ndarray, alpha: np.ndarray, coc_w: np.ndarray, coc: np.ndarray, scale: int):
    r"""Depth-aware bilinear upsampling of the working-resolution blur and α: bilinear weights
    times :math:`g_i = 1/(\tau + (r - s\,r_i)^2)` (τ = :data:`UPSAMPLE_COC_TOL_PX2`, r the full-resolution CoC, :math:`r_i` the
    working CoC of corner i: the min of r over its block, in working px), so a blurred background
    next to a sharp edge is not mixed with the working pixels that straddle the edge (which carry
    the nearer CoC); when a corner with a bilinear weight lies within :data:`UPSAMPLE_SAME_PX` of
    r (p's own surface is there), the corners farther than that get none — a sharp HDR lamp's
    working corner 2 px of CoC away still weighed 1/32 of the surface's own and put a ring of its
    light on it. Edges are clamped.

    ``coc_w`` is the block min of the *original* CoC, not of the variance-matched one the gather
    used (:func:`half_radius` maps every |r| < 2.31 px to 0, so an in-focus lamp and a wall at
    r = 2.2 px looked alike, and the wall's pixels took the lamp's blurred light on top of the lamp
    keeping its own: +12 % of an in-focus lamp's energy at draft; docs/fidelity.md)."""
    h, w = coc.shape
    corners = [(ys, xs, b, np.abs(coc - scale * coc_w[ys][:, xs]))
               for ys, xs, b in fld.upsample_corners(h, w, *coc_w.shape, scale)]
    same = np.zeros((h, w), bool)
    for _, _, b, dr in corners:
        same |= (b > 0) & (dr <= UPSAMPLE_SAME_PX)
    acc = np.zeros((h, w, 3)); acc_a = np.zeros((h, w)); wsum = np.zeros((h, w))
    for ys, xs, b, dr in corners:
        g = np.where(same & (dr > UPSAMPLE_SAME_PX), 0.0, b / (UPSAMPLE_COC_TOL_PX2 + dr ** 2))
        acc += g[..., None] * img[ys][:, xs]
        acc_a += g * alpha[ys][:, xs]
        wsum += g
    return acc / wsum[..., None], acc_a / wsum


HALF_PATH_VAR_PX2 = 1.0
r"""Variance (px², per axis) the half-resolution path adds to any gather: the 2×2 box mean (1/4)
plus the bilinear upsampling at phases ¼, ¾ (¾·½² + ¼·(3/2)² = 3/4)."""
HALF_RAMP_VAR_PX2 = 1.0 / 3.0
r"""Variance (px², per axis) of the gather's one-working-pixel coverage ramp: a box of width 2 px,
4/12 (measured on the lattice disc: within 0.01 working px² of r²/4 + 1/12 for r ≥ 1)."""


def half_radius(coc: np.ndarray) -> np.ndarray:
    r"""Radius the half-resolution path gathers with for a CoC r (px, signed):
    :math:`\operatorname{sgn}(r)\sqrt{\max(r^2 - 4(V_{path} + V_{ramp}), 0)}` (module docstring).
    Monotone in r, so depth order and the nearest-CoC min commute with it."""
    c = np.asarray(coc, dtype=np.float64)
    return np.sign(c) * np.sqrt(np.maximum(c * c - 4.0 * (HALF_PATH_VAR_PX2 + HALF_RAMP_VAR_PX2), 0.0))


LOCAL_VAR_PX2 = 0.5
r"""Largest variance (px², per axis) of the half-resolution path's full-resolution 3×3 blur
(:func:`local_blur`): the binomial [¼, ½, ¼]."""
LOCAL_MIN_PX = 0.5
"""A pixel whose own |CoC| and every nearer neighbour's are below this keeps its colour in the
full-resolution blur: every side weight it would use is then under a = r²/8 = 1/32 (a neighbour not
nearer weighs at most p's own)."""


def half_blend(coc: np.ndarray) -> np.ndarray:
    r"""Weight of the half-resolution blur against the full-resolution 3×3 blur
    (:func:`local_blur`): 0 while the disc's variance :math:`v = r^2/4` fits the 3×3
    (:math:`v \le V_3` = :data:`LOCAL_VAR_PX2`), then the mix of the two whose variance is v,
    :math:`(v - V_3)/(V_{path} - V_3)`, 1 from :math:`v = V_{path}` (r = 2 px) on (module docstring)."""
    c = np.asarray(coc, dtype=np.float64)
    v = c * c / 4.0
    return np.clip((v - LOCAL_VAR_PX2) / (HALF_PATH_VAR_PX2 - LOCAL_VAR_PX2), 0.0, 1.0)


def local_weight(coc: np.ndarray) -> np.ndarray:
    r"""Side weight a of the 3×3 separable blur [a, 1 − 2a, a] per axis (variance 2a) for a CoC r:
    :math:`a = \min(r^2/4, V_3)/2` — the disc's variance, capped at the binomial's."""
    c = np.asarray(coc, dtype=np.float64)
    return np.minimum(c * c / 4.0, LOCAL_VAR_PX2) / 2.0


def local_blur(color: np.ndarray, coc: np.ndarray) -> np.ndarray:
    r"""Full-resolution 3×3 scatter-as-gather for the small CoCs the half-resolution path cannot
    make (its box and upsampling alone are 1 px² per axis; a disc of r < 2 px has less): each
    neighbour q spreads with the separable weight :math:`w_q = w(o_x)\,w(o_y)`, w(0) = 1 − 2a,
    w(±1) = a, a = :func:`local_weight` of q's own CoC when q is nearer than p by more than
    :data:`FRONT_MARGIN_PX`, else of min(|r_q|, |r_p|) (the gather's background clamp: a blurred
    background never bleeds onto a sharper pixel), normalised by the summed weight. Edges clamped.
    A pixel whose own |r| and every nearer neighbour's are < :data:`LOCAL_MIN_PX` keeps its colour
    (side weights < 1/32: the kernel skips the taps there)."""
    c = np.asarray(coc, dtype=np.float64)
    h, w = c.shape
    a_p = local_weight(c)
    pc = np.pad(np.asarray(color, dtype=np.float64), ((1, 1), (1, 1), (0, 0)), mode="edge")
    pr = np.pad(c, 1, mode="edge")
    acc = np.zeros((h, w, 3)); wsum = np.zeros((h, w))
    need = np.abs(c) >= LOCAL_MIN_PX
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            rq = pr[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
            aq = local_weight(rq)
            front = rq < c - FRONT_MARGIN_PX
            need |= front & (np.abs(rq) >= LOCAL_MIN_PX)
            aq = np.where(front, aq, np.minimum(aq, a_p))
            wq = (aq if dy else 1.0 - 2.0 * aq) * (aq if dx else 1.0 - 2.0 * aq)
            acc += wq[..., None] * pc[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
            wsum += wq
    return np.where(need[..., None], acc / wsum[..., None], np.asarray(color, dtype=np.float64))


def _half_composite(camera, color, coc, scale, rmax, budget, pm=None, narrow=False):
    """The half-resolution path (draft, preview, and final's large-reach tiles): gather at the
    working resolution with the variance-matched radius (:func:`half_radius`), depth-aware
    upsampling, composite with the full-resolution colour (:func:`half_blend`, or the front
    layer's coverage). ``pm``: the traced profile (:func:`traced_profile`) or None. ``narrow``:
    narrow sources (:func:`narrow_sources`) go through the full-resolution layer
    (:func:`narrow_layer`) instead. Returns (output, working CoC)."""
    hr = half_radius(coc)
    src = None
    if narrow:
        src, gathered, small = narrow_sources(color, coc, scale, luma_weights(camera), small=True)
    else:
        gathered = color
    cw, rw = _working(gathered, hr, scale)
    out, alpha = gather_reference(cw, rw, rmax, budget, camera.blades, camera.blade_rotation_deg,
                                  camera.aperture_roundness, camera.spherical_aberration,
                                  camera.optical_vignetting, None if pm is None else (pm, scale), lights=False)
    _, rw_orig = _working(color, coc, scale)
    up, up_alpha = _upsample(out, alpha, rw_orig, coc, scale)
    b = np.maximum(half_blend(coc), up_alpha)
    if src is not None and len(src):
        # the 3×3 blur reads the colour without the sources' excess: the layer spreads all of it
        # (a sharp wall pixel beside a near light took its 3×3 share on top of it)
        base = color.copy()
        for x, y, _, *e in src:
            base[int(y), int(x)] -= e
    else:
        base = color
    near = local_blur(base, coc)
    out = np.where(b[..., None] < 1.0, near + (up - near) * b[..., None], up)
    if src is not None and len(src):
        out = out + narrow_layer(src, coc, up_alpha, camera.blades, camera.blade_rotation_deg,
                                 camera.aperture_roundness, camera.spherical_aberration)
    if src is not None and len(small):
        out = out + small_layer(small, coc, up_alpha)
    return out, rw


SMALL_LO_PX, SMALL_HI_PX = 1.0, math.sqrt(2.0)
"""|CoC| (px) below which final's full-resolution gather is replaced by the 3×3 blur, and above
which it is kept (a linear ramp between; :func:`_full_small`)."""


def _full_small(color, coc, out, alpha, one_tap=None):
    r"""Final's small CoCs: the full-resolution lattice disc with its 1-px coverage ramp has too
    much variance below r ≈ 1.4 px (r = 0.9: 0.31 px² per axis for the disc's 0.20; r ≤ 0.5:
    none), so there the disc's variance is made by the 3×3 blur (:func:`local_blur`, exact up to
    r = √2): :math:`\mathrm{lerp}(c_{3\times3}, c_{gather}, b)`, b = 0 for |r| ≤
    :data:`SMALL_LO_PX`, 1 from :data:`SMALL_HI_PX` on, and 1 wherever the gather has a front
    layer (α > 0: a blurred foreground over the pixel, or a sloped surface's nearer taps, keep
    the gather). ``one_tap``: pixels of one-tap tiles (every |r| in reach ≤ ½ px: the 3×3 blur
    would change only exact ½ px CoCs; the kernel skips it there, for speed), kept as gathered.
    Measured per CoC band on the Cycles truths: docs/fidelity.md, "Held-out scenes"."""
    b = np.where(alpha > 0.0, 1.0, np.clip((np.abs(coc) - SMALL_LO_PX) / (SMALL_HI_PX - SMALL_LO_PX), 0.0, 1.0))
    if one_tap is not None:
        b = np.where(one_tap, 1.0, b)
    near = local_blur(color, coc)
    return np.where(b[..., None] < 1.0, near + (out - near) * b[..., None], out)


def mixed_mask(rw: np.ndarray, coc: np.ndarray, quality: str, reach: float = 1.0) -> np.ndarray:
    r"""Full-resolution pixels that ``quality`` takes from the half-resolution path: those in a
    working tile whose half-resolution plan (:func:`tile_plan`'s routing levels) has level ≥
    :data:`MIXED_LEVEL`, or one of whose full-resolution child tiles has a routing level above
    :data:`MIXED_FULL_LEVELS` in the full-resolution plan (so the full-resolution gather never
    reads a level it did not build: its depth-aware level is at most the routing level)."""
    scale, rmax, budget = MIXED[quality]
    _, full_rmax, full_budget = QUALITY[quality]
    h, w = coc.shape
    hw, ww = rw.shape
    lvl, _ = tile_plan(rw, rmax, budget, reach, route=True)
    lvl_full, _ = tile_plan(coc, full_rmax, full_budget, reach, route=True)
    big = np.zeros((hw * scale, ww * scale), bool)
    big[:h, :w] = lvl_full > MIXED_FULL_LEVELS
    big = big.reshape(hw, scale, ww, scale).any(axis=(1, 3))  # per working pixel
    th, tw = -(-hw // TILE), -(-ww // TILE)
    tiles = np.zeros((th * TILE, tw * TILE), bool)
    tiles[:hw, :ww] = big | (lvl >= MIXED_LEVEL)
    tiles = tiles.reshape(th, TILE, tw, TILE).any(axis=(1, 3))
    return np.kron(tiles, np.ones((scale * TILE, scale * TILE), bool))[:h, :w]


def dof_reference(camera, color: np.ndarray, depth: np.ndarray, quality: str = "final",
                  width_px: int | None = None) -> np.ndarray:
    """float64 numpy implementation of the whole stage (the oracle of the OpenCL kernels);
    ``width_px``: the pixels across the sensor (:func:`clpost.stages._field.image_width_px`; the
    array's width when None)."""
    scale, rmax, budget = QUALITY[quality]
    color = np.asarray(color, dtype=np.float64)
    h, w = depth.shape
    coc = coc_px(camera, effective_depth(color, depth, luma_weights(camera)), width_px or w, limit_px=scale * rmax)
    pm = traced_profile(camera, width_px or w, quality)
    if scale > 1:
        return _half_composite(camera, color, coc, scale, rmax, budget, pm, narrow_split(camera, pm))[0]
    out, alpha = gather_reference(color, coc, rmax, budget, camera.blades, camera.blade_rotation_deg,
                                  camera.aperture_roundness, camera.spherical_aberration,
                                  camera.optical_vignetting, None if pm is None else (pm, 1))
    one_tap = tile_plan(coc, rmax, budget, 1.0 if pm is None else pencil.T_MAX)[1] == 1
    out = _full_small(color, coc, out, alpha, one_tap)
    if quality not in MIXED:
        return out
    half, rw = _half_composite(camera, color, coc, *MIXED[quality], pm)
    return np.where(mixed_mask(rw, coc, quality, 1.0 if pm is None else pencil.T_MAX)[..., None], half, out)


# ---------------------------------------------------------------------------------------------
# The stage
# ---------------------------------------------------------------------------------------------


class Dof(GatherStage):
    name = "dof"
    order = 10.0
    role = "defocus: depends on scene depth, in the undistorted render's image space"
    domains = ("render", "render")
    params = DofParams
    reads = ("depth",)
    turn_off = "turn depth of field off with --depth-of-field off"

    def skip_reason(self, camera, frame):
        if not camera.depth_of_field:
            return "Camera.depth_of_field is off (pinhole: everything in focus)"
        if frame.depth is None:
            return None  # the planner then asks for the depth buffer
        k, inv_u = coc_coefficients(camera, fld.image_width_px(frame))
        near, far, sky = frame.depth_range
        inv = [0.0] if sky else []
        if math.isfinite(far):
            inv += [1.0 / near, 1.0 / far]
        worst = max(abs(k * (inv_u - i)) for i in inv)
        if worst <= 0.5:
            return f"all pixels in focus (largest CoC radius {worst:.3g} px <= 0.5 px)"
        return None

    def reason_needed(self, camera, frame):
        coc = coc_px(camera, frame.depth, fld.image_width_px(frame))
        texture = (f"bokeh texture traced from {camera.lens} per channel (pencil map, "
                   f"{pencil.N_DEFOCUS}×{pencil.N_RADIUS} per channel)" if camera.optics is not None
                   else f"parametric spherical aberration {camera.spherical_aberration:g}")
        return (f"CoC radius {np.min(coc):.3g} … {np.max(coc):.3g} px (max {max_coc_px(self.quality):g} px, "
                f"{self.quality}), {camera.blades or 'round'} blades, {texture}")

    def defines(self, camera):
        scale, rmax, budget = QUALITY[self.quality]
        traced = camera.optics is not None
        reach = pencil.T_MAX if traced else 1.0
        prof = {"DOF_PROF_ND": pencil.N_DEFOCUS, "DOF_PROF_NR": pencil.N_RADIUS,
                "DOF_PROF_TMAX": f"{pencil.T_MAX!r}f",
                "DOF_PROF_RK": f"{1.0 / PROFILE_RMAX_PX!r}f"} if traced else {}
        return {"DOF_SCALE": scale, "DOF_RMAX": reach_rmax(rmax, reach), "DOF_TILE": TILE, "DOF_BUDGET": budget,
                "DOF_LEVELS": levels_for(reach_rmax(rmax, reach), budget),
                "DOF_VIGNETTING": int(camera.optical_vignetting > 0),
                "DOF_TEXTURE": int(camera.spherical_aberration != 0 and not traced),
                "DOF_PROFILE": int(traced), "DOF_REACH": f"{reach!r}f", **prof,
                "DOF_HALF_SHRINK": f"{4.0 * (HALF_PATH_VAR_PX2 + HALF_RAMP_VAR_PX2)!r}f",
                "DOF_HALF_BLEND": f"{1.0 / (HALF_PATH_VAR_PX2 - LOCAL_VAR_PX2)!r}f",
                "DOF_LOCAL_VAR": f"{LOCAL_VAR_PX2!r}f", "DOF_LOCAL_MIN": f"{LOCAL_MIN_PX!r}f",
                "DOF_SMALL_LO": f"{SMALL_LO_PX!r}f", "DOF_SMALL_K": f"{1.0 / (SMALL_HI_PX - SMALL_LO_PX)!r}f",
                "DOF_FRONT_MARGIN": f"{FRONT_MARGIN_PX!r}f", "DOF_TRIM": f"{TRIM_LATTICE!r}f", "DOF_HIDDEN_MARGIN": f"{HIDDEN_MARGIN_PX!r}f", "DOF_FRINGE_STEP": f"{FRINGE_STEP!r}f",
                "DOF_LIGHTS": int(not traced and camera.optical_vignetting == 0),
                "DOF_LIGHT_SMALL_LO": f"{LIGHT_SMALL_PX[0]!r}f", "DOF_LIGHT_SMALL_HI": f"{LIGHT_SMALL_PX[1]!r}f",
                "DOF_LIGHT_LUMA": f"{LIGHT_LUMA!r}f", "DOF_LIGHT_RMAX": f"{LIGHT_RMAX_PX!r}f",
                "DOF_LIGHT_INV_RAMP": f"{1.0 / LIGHT_RAMP_PX!r}f", "DOF_LIGHT_N": LIGHT_TABLE_R[2],
                "DOF_LIGHT_R0": f"{LIGHT_TABLE_R[0]!r}f",
                "DOF_LIGHT_K": f"{(LIGHT_TABLE_R[2] - 1) / (LIGHT_TABLE_R[1] - LIGHT_TABLE_R[0])!r}f",
                **{f"DOF_LIGHT_Y{i}": f"{v!r}f" for i, v in enumerate(LIGHT_LUMA_WEIGHTS)},
                "DOF_UP_SAME": f"{UPSAMPLE_SAME_PX!r}f",
                "DOF_NARROW": int(scale > 1 and not traced and camera.optical_vignetting == 0),
                "DOF_NARROW_RATIO": f"{NARROW_RATIO!r}f", "DOF_NARROW_CONTRAST": f"{NARROW_CONTRAST!r}f",
                "DOF_NARROW_MIN": f"{NARROW_MIN_PX!r}f", "DOF_NARROW_CELL": NARROW_CELL,
                "DOF_NARROW_SUM": f"{NARROW_SUM_PX!r}f", "DOF_NARROW_EDGE": f"{NARROW_EDGE_PX!r}f",
                "DOF_NARROW_MAX": NARROW_MAX, "DOF_NARROW_FOCUS": f"{NARROW_FOCUS_PX!r}f",
                "DOF_NARROW_FRONT_MAX": NARROW_FRONT_MAX, "DOF_NARROW_SPREAD": f"{NARROW_SPREAD_PX!r}f",
                "DOF_NARROW_RAMP": f"{NARROW_RAMP_PX!r}f",
                "DOF_SAME_SOURCE": f"{SAME_SOURCE!r}f", "DOF_LIGHT_FRINGE": f"{LIGHT_FRINGE!r}f",
                "DOF_UP_TOL": f"{UPSAMPLE_COC_TOL_PX2!r}f",
                "DOF_MIXED": 0, "DOF_MIX_LEVEL": MIXED_LEVEL, "DOF_MIX_FULL_LEVELS": MIXED_FULL_LEVELS,
                **{f"DOF_LUMA_{c}": f"{float(v)!r}f" for c, v in zip("RGB", luma_weights(camera))}}

    def reference(self, camera, frame, color):
        return dof_reference(camera, color, frame.depth, self.quality, fld.image_width_px(frame))

    def enqueue(self, rt, camera, frame, src, dst, aux):
        from .dof_cl import enqueue_dof

        return enqueue_dof(self, rt, camera, frame, src, dst, aux)


# ---------------------------------------------------------------------------------------------
# The half-resolution path's narrow-source layer
# ---------------------------------------------------------------------------------------------

NARROW_RATIO = 4.0
"""A working pixel (2×2 block) brighter than this × the third brightest of its 8 working
neighbours at distance 2 (3–5 px away) holds a *narrow source* candidate: a light a few pixels
wide, a peak on nearly every side — two of the 8 may be bright (its own fringe, a lamp beside
it), while the edge or corner of a bright surface has at least three (:func:`narrow_sources`)."""
NARROW_CONTRAST = 0.125
r"""A candidate pixel is split off when its excess luminance spread over its disc,
:math:`Y_e/(\pi r^2)`, is above this × the surround's :math:`Y_{bg}`: a disc that stands out of
its surround, whose edge the half-resolution path would soften (a dimmer one's soft edge is not
seen, and it stays in the cheaper path)."""
NARROW_EDGE_PX = 8.0
r"""Above this |CoC| (px) the contrast a source needs grows with r (:data:`NARROW_CONTRAST` ×
r / this): the path's soft edge is ≈ 3 px whatever r, a smaller part of a larger disc, while the
layer's cost per source grows as r². A defocused frame sprinkled with hot pixels (`clpost bench`'s
worst case: 414 of them at 500× on 1080p, r = 32 px) otherwise put a full-resolution disc on
nearly every pixel (42 of them are split now; docs/fidelity.md, "The narrow-source layer")."""
NARROW_MIN_PX = 2.0
"""A candidate pixel with |CoC| above :data:`NARROW_FOCUS_PX` is split off unless one of its 3×3
is nearer than it (by more than :data:`FRONT_MARGIN_PX`) with |CoC| below this (:func:`half_blend`
< 1): a light seen through a sharper foreground's gap, whose light the gather's background clamp
keeps in the gap (final) and the layer would spread as a disc of the gap's radius, losing most of
it (a 2×2 light at 4 px behind an in-focus wall: 0.10 of its light); it stays in the working image.
A sharp pixel *behind* a source, or beside it on its surface, takes the composite's 3×3 share of
the colour without the source's excess (:func:`_half_composite`), so it needs no such test: before,
every |CoC| of the 3×3 had to be ≥ this, and a near light over a wall sharper than 2 px stayed in
the working image, where the composite's per-pixel mix of the two blurs kept 0.62–0.96 of its light
(docs/fidelity.md, "Near lights over sharp walls at draft")."""
NARROW_FOCUS_PX = math.sqrt(4.0 * LOCAL_VAR_PX2)
"""A candidate pixel with |CoC| ≤ this (px) — in focus: the composite takes it whole from the
full-resolution 3×3 blur (:func:`half_blend` = 0), which reads its original colour — has its
excess taken out of the working image too, and is not listed (it needs no layer), when nothing
of the 5×5 working pixels around its block is in front of it (by more than
:data:`FRONT_MARGIN_PX`): an in-focus light before a blurred background keeps its light at full
resolution. In the working image the prefiltered levels' tent spread it over the background
beside it through the gather's centre tap (a halo of 68 px around h_lamps' in-focus lamp00 at
draft). A blurred foreground beside it needs it — there it is the background seen through the
foreground's soft edge (the occluder scene's sharp corners behind the blurred bar lost 0.14 dB
without the test; docs/fidelity.md, "The narrow-source layer")."""
NARROW_FRONT_MAX = 10
"""Most pixels nearer than an in-focus light (by :data:`FRONT_MARGIN_PX`) among the 10×10 around its
block (:data:`NARROW_FOCUS_PX`) for its excess to leave the working image: a transparent surface's
stochastic depth puts a few scattered nearer pixels around a light behind it (the transparent
scene's lamp behind the pane: 2–6 of 100), a blurred foreground whose soft edge covers the light
many (the occluder scene's corners behind the bar: 33–53; a light 2 px beside a bar: 20)."""
NARROW_SPREAD_PX = 1.0
"""From this |CoC| (px) on, an in-focus light's share of the 3×3 blur that its neighbours take from
the half-resolution blur instead is added back (:func:`small_layer`); below, none (the transparent
scene's lamp at r = 0.69 px over the sky: with it, an 11 px halo Cycles does not have, and +1 %
of its light)."""
NARROW_CELL = 64
"""Edge (px) of the cells the sources are listed by (the upsampling reads the lists of the cells
within the largest CoC of its pixels)."""
NARROW_MAX = 64
"""Most sources (pixels) a cell lists, its in-focus lights (:data:`NARROW_FOCUS_PX`) counted with
them; a cell with more splits none (its lights stay in the half-resolution path: a bounded cost
per pixel whatever the input)."""

NARROW_RING = ((-2, -2), (-2, 0), (-2, 2), (0, -2), (0, 2), (2, -2), (2, 0), (2, 2))
"""The working neighbours (dy, dx) a candidate block is compared with, in the kernel's order
(of equal ones the first ranks brighter)."""


def narrow_split(camera, pm=None) -> bool:
    """Whether the half-resolution levels split narrow sources off: not with a traced profile or
    cat's-eye bokeh (the layer has neither; those keep the half-resolution path for every light)."""
    return pm is None and camera.optical_vignetting == 0


def narrow_sources(color: np.ndarray, coc: np.ndarray, scale: int, luma: np.ndarray | None = None,
                   small: bool = False):
    r"""The narrow sources of the half-resolution path (draft, preview): pixels of small bright
    lights whose light is taken out of the working image and spread at full resolution instead
    (:func:`narrow_layer`). The half-resolution path's discs have soft edges — the 2×2 box, the
    working coverage ramp and the bilinear upsampling, ≈ 3 px of ramp whatever the variance match
    does — and a 100× lamp saturates its whole soft edge: discs 1.2–1.8× Cycles' area, with light
    spread beyond (docs/fidelity.md, "The narrow-source layer").

    A working pixel P (not within 2 of the working image's edge) is a candidate block when its
    luminance is above :data:`NARROW_RATIO` × that of the third brightest of its working
    neighbours at distance 2 (:data:`NARROW_RING`; its colour is the surround's, bg). Each
    full-resolution pixel q of the block with :math:`|r_q| >` :data:`NARROW_FOCUS_PX` and no pixel
    of its 3×3 nearer than it by more than :data:`FRONT_MARGIN_PX` with |CoC| <
    :data:`NARROW_MIN_PX` has the excess :math:`e_q = \max(c_q - bg, 0)` (per channel) and is a source when
    :math:`Y(e_q) > ` :data:`NARROW_CONTRAST` · Y(bg) · π r_q² · max(1, |r_q| / :data:`NARROW_EDGE_PX`).
    Sources are listed per :data:`NARROW_CELL` cell in scan order (working rows, then the block's
    rows); a cell with more than :data:`NARROW_MAX` lists none. A pixel of a candidate block with
    |r_q| ≤ :data:`NARROW_FOCUS_PX` instead, the same contrast test, and at most
    :data:`NARROW_FRONT_MAX` pixels nearer than r_q − :data:`FRONT_MARGIN_PX` among the
    full-resolution pixels of the 5×5 working pixels around its block is an *in-focus light*: its
    excess leaves the base too, but it is not in ``sources`` (counted in its cell's cap, though).

    Returns (sources, base), or with ``small`` (sources, base, small): sources an (n, 6) array of
    (x, y, r, e_R, e_G, e_B) (r the signed CoC in px), base the colour with each source's and
    in-focus light's excess taken out (c − e), small the in-focus lights with
    |r| ≥ :data:`NARROW_SPREAD_PX` in the same form (:func:`small_layer`)."""
    color = np.asarray(color, dtype=np.float64)
    c = np.asarray(coc, dtype=np.float64)
    lw = luma_weights() if luma is None else luma
    h, w = c.shape
    cw, _ = _working(color, c, scale)
    yw = cw @ lw
    hw, ww = yw.shape
    base = color.copy()
    if hw < 5 or ww < 5:
        return (np.zeros((0, 6)), base) + ((np.zeros((0, 6)),) if small else ())
    pc = np.pad(c, 1, mode="edge")
    c3 = np.stack([pc[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dy in (-1, 0, 1) for dx in (-1, 0, 1)], axis=-1)
    ring = np.stack([yw[2 + dy:hw - 2 + dy, 2 + dx:ww - 2 + dx] for dy, dx in NARROW_RING])
    k3 = np.argsort(-ring, axis=0, kind="stable")[2]  # the third brightest (ties: the first), as the kernel
    bg_ys = np.take_along_axis(ring, k3[None], 0)[0]
    cells: dict = {}
    for py, px in zip(*np.nonzero(yw[2:hw - 2, 2:ww - 2] > NARROW_RATIO * bg_ys)):
        k, bg_y = k3[py, px], bg_ys[py, px]
        py, px = py + 2, px + 2
        bg = cw[py + NARROW_RING[k][0], px + NARROW_RING[k][1]]
        for b in range(scale):
            for a in range(scale):
                y, x = scale * py + b, scale * px + a
                e = np.maximum(color[y, x] - bg, 0.0)
                ar = abs(c[y, x])
                split = ar > NARROW_FOCUS_PX and not np.any(
                    (np.abs(c3[y, x]) < NARROW_MIN_PX) & (c3[y, x] < c[y, x] - FRONT_MARGIN_PX))
                # an in-focus light is kept at full resolution only with (almost) nothing in
                # front of it among the full-resolution pixels of the 5×5 working pixels around
                # its block (rows/columns past the image, at an odd height or width, count none)
                kept = ar <= NARROW_FOCUS_PX and np.count_nonzero(
                    c[scale * (py - 2):min(scale * (py + 3), h), scale * (px - 2):min(scale * (px + 3), w)]
                    < c[y, x] - FRONT_MARGIN_PX) <= NARROW_FRONT_MAX
                if (split or kept) and e @ lw > NARROW_CONTRAST * bg_y * math.pi * ar * ar * max(
                        1.0, ar / NARROW_EDGE_PX):
                    cells.setdefault((y // NARROW_CELL, x // NARROW_CELL), []).append((x, y, c[y, x], split, *e))
    rows, kept = [], []
    for key in sorted(cells):
        if len(cells[key]) <= NARROW_MAX:
            rows += [(x, y, r, *e) for x, y, r, split, *e in cells[key] if split]
            kept += [(x, y, r, *e) for x, y, r, split, *e in cells[key] if not split]
    src = np.array(rows, dtype=np.float64).reshape(-1, 6)
    kept = np.array(kept, dtype=np.float64).reshape(-1, 6)
    for x, y, _, *e in list(src) + list(kept):
        base[int(y), int(x)] -= e
    if small:
        return src, base, kept[np.abs(kept[:, 2]) >= NARROW_SPREAD_PX]
    return src, base


def narrow_weight(dx, dy, rq: float, r, blades: int, rotation_deg: float, roundness: float, sa: float,
                  area: float):
    r"""Weight of a source of signed CoC ``rq`` at offset o = (dx, dy) = q − p spread with radius r:
    the full-resolution gather's :math:`\mathrm{cov}\,I(t)/(a_K r^2)` (the aperture in the direction
    p − q for a far source, q − p for a near one), with a coverage ramp :data:`NARROW_RAMP_PX` wide
    instead of the gather's 1 px below :data:`NARROW_SUM_PX` (from there on the weights are taken
    to sum to 1, which the 1-px ramp's do within 0.6 % and a narrower one's only within 2 %)."""
    far = rq >= 0
    rho = aperture_radius(np.arctan2(-dy, -dx) if far else np.arctan2(dy, dx), blades, rotation_deg, roundness)
    rr = r * rho
    dist = np.hypot(dx, dy)
    ramp = NARROW_RAMP_PX if max(abs(rq), 0.5) < NARROW_SUM_PX else 1.0
    cov = np.clip((rr - dist) / ramp + 0.5, 0.0, 1.0)
    t = np.minimum(dist / rr, 1.0)
    a = -sa if far else sa
    return cov * (1.0 + a * (2 * t * t - 1.0)) / (area * r * r)


def small_layer(small: np.ndarray, coc: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    r"""The part of the in-focus lights' light (:func:`narrow_sources`' ``small``) that the
    composite's 3×3 blur (:func:`local_blur`) would have spread onto pixels that take the
    half-resolution blur instead: their excess left the working image, and a neighbour p with
    :func:`half_blend` b_p > 0 takes only 1 − b_p of its 3×3 — over a sky of r ≥ 2 px, none
    (the transparent scene's lamp behind the pane, r = 1.16 px, lost 6 % of its light that way and
    kept 1.46× Cycles' disc when its light stayed in the working image instead). Each such light q
    scatters its excess with the 3×3's separable weight :math:`w(o_x)\,w(o_y)`, w(0) = 1 − 2a,
    w(±1) = a, a = :func:`local_weight` of r_q where q is nearer than p by more than
    :data:`FRONT_MARGIN_PX`, else of min(|r_q|, |r_p|) (the 3×3's rule), times
    :math:`\max(b_p - \alpha_p, 0)` (b_p − α_p: the share the composite takes from the
    half-resolution blur for p's CoC, the front layer's coverage α_p left out — a blurred
    foreground over p hides that much of the light)."""
    h, w = coc.shape
    rp = np.asarray(coc, dtype=np.float64)
    k = np.maximum(half_blend(rp) - alpha, 0.0)
    out = np.zeros((h, w, 3))
    for x, y, rq, *e in small:
        x, y = int(x), int(y)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                py, px = y + dy, x + dx
                if 0 <= py < h and 0 <= px < w:
                    front = rq < rp[py, px] - FRONT_MARGIN_PX
                    a = float(local_weight(rq if front else min(abs(rq), abs(rp[py, px]))))
                    out[py, px] += (a if dy else 1 - 2 * a) * (a if dx else 1 - 2 * a) * k[py, px] * np.asarray(e)
    return out


NARROW_RAMP_PX = 0.25
r"""Width (px) of a narrow source's coverage ramp (:func:`narrow_weight`): the input's pixels are
already the renderer's pixel-filtered samples (Cycles: Blackman–Harris, 1.5 px), so its disc needs
no further pixel footprint, only enough of a ramp that the sampled polygon's edge does not alias.
With the full-resolution gather's 1-px ramp every split lamp's saturated disc came out up to
1.24× Cycles' (the emitters scene's lamp09, r = 2.1 px: the ramp's outer half pixel is still above
white at 100× white). From :data:`NARROW_SUM_PX` on, 1 px (:func:`narrow_weight`); docs/fidelity.md,
"The narrow layer's coverage ramp"."""
NARROW_SUM_PX = 8.0
"""From this |CoC| (px) on, a narrow source's weights are taken to sum to 1 (:func:`narrow_norm`):
the lattice's coverage sum is then within 0.6 % of a_K r² (6 blades, round, 5 rounded blades;
1–5 % at r = 2–4 px), and summing a disc of r = 32 px per source cost more than the layer."""


def narrow_norm(rq: float, blades: int, rotation_deg: float, roundness: float, sa: float, area: float) -> float:
    """1 / the sum of a source's weights over its whole disc at its own radius (:func:`narrow_weight`):
    the lattice's coverage sum differs from a_K r² by a few % at r ≈ 2 px, and the layer is not
    normalised per pixel, so each source below :data:`NARROW_SUM_PX` is normalised once (its light
    is conserved exactly where nothing hides it); larger ones by their disc's integral, 1."""
    r = max(abs(rq), 0.5)
    if r >= NARROW_SUM_PX:
        return 1.0
    k = int(math.ceil(r)) + 1
    dy, dx = np.mgrid[-k:k + 1, -k:k + 1].astype(np.float64)
    return 1.0 / float(np.sum(narrow_weight(dx, dy, rq, r, blades, rotation_deg, roundness, sa, area)))


def narrow_layer(sources: np.ndarray, coc: np.ndarray, alpha: np.ndarray, blades: int, rotation_deg: float,
                 roundness: float, sa: float) -> np.ndarray:
    r"""The narrow sources spread at full resolution, added to the half-resolution composite:
    scatter-as-gather of each source q onto p with the full-resolution gather's weight
    (:func:`narrow_weight`), *unnormalised* per pixel (a sparse layer: each source's light is its
    own; :func:`narrow_norm` makes its weights sum to 1): q nearer than p, or on p's surface
    (within :data:`FRONT_MARGIN_PX`), spreads over p with its own radius; q behind p with the
    smaller of its own radius and p's (a sharper p in front of it is the background clamp of the
    gather; a blurred foreground does not widen it), times 1 − α_p, the upsampled front-layer
    coverage (a blurred foreground over p hides that much of what is behind it). A source on p's
    surface is not attenuated: the front coverage around a light is mostly its own block's (its
    CoC is nearer than the sky's fringe pixels around it), whose colour the split left as the
    surround's — attenuating by it lost h_lamps' lamp05 4 % of its light at draft."""
    h, w = coc.shape
    area = aperture_area(blades, rotation_deg, roundness)
    out = np.zeros((h, w, 3))
    ys, xs = np.mgrid[0:h, 0:w]
    rp = np.asarray(coc, dtype=np.float64)
    for x, y, rq, *e in sources:
        behind = rq > rp + FRONT_MARGIN_PX
        rs = max(abs(rq), 0.5)
        r = np.where(behind, np.minimum(np.maximum(np.abs(rp), 0.5), rs), rs)
        wgt = narrow_weight(x - xs, y - ys, rq, r, blades, rotation_deg, roundness, sa, area)
        wgt = np.where(behind, wgt * (1.0 - alpha), wgt) * narrow_norm(rq, blades, rotation_deg, roundness, sa, area)
        out += wgt[..., None] * np.asarray(e)
    return out
