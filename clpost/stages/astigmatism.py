r"""astigmatism: field curvature and astigmatism as a per-pixel elliptical gather.

**Focal offsets.** At image height r the lens focuses the sagittal fan (rays spread tangent to
the circle around the centre) at :math:`\delta_s(r)` and the tangential (meridional, radial) fan
at :math:`\delta_t(r)` mm behind the film (+ = behind). Field curvature is their mean, astigmatism
their difference. Sources:

* a traced lens (``camera.lens_curves()``, Coddington foci by finite differences in
  :mod:`clpost.optics.curves`): :math:`\delta(r) = \text{offset}(r) - \text{offset}(0)`. The
  axial value is subtracted because the film sits at the best focus *of the full aperture* on the
  axis (real-ray focusing), where the ±1 % pupil rays of the curve cross 0.05 mm behind it for the
  Planar 50/1.4 — that is spherical aberration, owned by the axial defocus, not by this stage.
* parametric (``Camera.field_curvature_mm`` F, ``Camera.astigmatism_mm`` A at the image corner
  :math:`r_c`; Seidel third order, quadratic in field height):

  .. math::

      \delta_s = (F - A/2)\,(r/r_c)^2, \qquad \delta_t = (F + A/2)\,(r/r_c)^2

**Blur of one pixel.** Thin-lens equivalent of the camera at its focus (:func:`thin_lens`): focal
length f, film at v (for a thin lens its own f and v), entrance pupil diameter :math:`D = f/N`. A surface at planar depth z
(metres, converted to mm) images at :math:`1/g` with :math:`g = 1/f - 1/z`; its sagittal focus
lies at :math:`1/g + \delta_s`. The pencil of a uniform circular pupil cut by the film is an
ellipse whose axes (diameters, mm) along the sagittal and tangential directions are

.. math::

    c(\delta) = D\,\Big|1 - \frac{v\,g}{1 + \delta\,g}\Big|
              = D\,\frac{|(1 - v/f) + v/z + \delta g|}{1 + \delta g}, \qquad
    c_s = c(\delta_s),\ c_t = c(\delta_t),\ c_0 = c(0) = D\,|1 - v g|

(similar triangles; c_0 is the flat-field circle of confusion of depth defocus; the second form
is how it is evaluated, without cancellation in focus). Where :math:`1 + \delta g \le 10^{-6}`
the focus is at infinity or virtual and the blur is taken as the cap.

**What this stage owns (no double counting with dof).** The dof stage blurs with the flat-field
CoC c_0 (a disc); this stage adds the field-dependent rest. Variances of convolved PSFs add
exactly, and a uniform ellipse of axis c has variance c²/16 along it, so this stage gathers over a
uniform ellipse with axes

.. math::

    a_s = \sqrt{\max(c_s^2 - c_0^2, 0)}, \qquad a_t = \sqrt{\max(c_t^2 - c_0^2, 0)}

so dof ∘ astigmatism has the lens's second moments along both axes. For content in the focal
plane (c_0 = 0) this stage alone is the lens's blur (rims *or* spokes of a wheel sharp, not both).
Where c_0 exceeds c_s or c_t (a surface whose depth defocus is partly cancelled by field
curvature), the sum is too blurred along that axis: stages only add blur. Without a dof stage
in the plan, out-of-focus content lacks c_0.

**Gather.** The taps :math:`x + o_k`, :math:`o_k = \tfrac{a_s}{2p}u_{k,x}\,e_s +
\tfrac{a_t}{2p}u_{k,y}\,e_t` cover the output pixel's own ellipse (:math:`u_k` a Vogel spiral of
N points over the unit disc, p the pixel pitch, :math:`e_t` the unit radial vector, :math:`e_s`
its perpendicular; bilinear taps from a copy padded by 16 px, edge repeated). Each tap is
weighted by whether the *source* pixel's own ellipse reaches back to the target
(scatter-as-gather, as DoF gathers do):

.. math::

    w_k = \mathrm{clamp}\Big(\frac{1.5625 - q_k^2}{0.5625},\ 0,\ 1\Big), \quad
    q_k = \Big\| \Big(\frac{\alpha_s u_{k,x}}{\alpha_s^{src} + \frac12},\
                      \frac{\alpha_t u_{k,y}}{\alpha_t^{src} + \frac12}\Big) \Big\|,
    \qquad C'(x) = \frac{\sum_k w_k\,C(x + o_k)}{\sum_k w_k}

with :math:`\alpha = a/2p` the semi-axes in px (the source's at its nearest pixel, +½ px for
its own extent; weight 1 inside, fading to 0 at 1.25 of the source's ellipse, linearly in q²
so the kernel needs no square root). Without it, a sharp highlight beside a strongly blurred
neighbour (a lamp against the sky) is copied into the neighbour's large ellipse: +2.5 % energy
on the demo frame at f/1.4, +0.8 % with it (the rest: pixels whose depth is the sky's but whose
colour is the lamp's, CONVENTIONS "depth from one sample"). A uniform field stays uniform exactly.
Semi-axes are capped at 15 px; below 1e-3 px both, the pixel is copied. Quality sets N: draft
16, preview 32, final 64.

**Tiles (speed).** PoCL vectorises a gather across pixels only when all work-items of a group
read at the same offsets (docs/measurements.md#gather-layouts-on-pocl), so the kernel runs on tiles
of 16 × 8 px (:mod:`clpost.stages._field`) and, per tile, places the N taps on the tile's *bounding*
ellipse: the largest :math:`\alpha_s, \alpha_t` of its pixels, along the tile centre's
:math:`e_s, e_t`.
Each pixel keeps its own ellipse through a second weight, membership

.. math::

    m_k = \mathrm{clamp}\big(9 - 8\,\mu_k^2,\ 0,\ 1\big), \qquad
    \mu_k^2 = \frac{(A_s u_{k,x})^2}{\alpha_s^2 + 10^{-3}} + \frac{(A_t u_{k,y})^2}{\alpha_t^2 + 10^{-3}}

(1 inside the pixel's ellipse, 0 beyond 1.06 of it; A the tile's bound), so the taps of a pixel
are the spiral points inside its ellipse: all N where the tile's ellipses are equal, about
:math:`N\alpha_s\alpha_t/A_sA_t` elsewhere. Two approximations follow, and the tiles where they
would exceed about half a pixel take the per-pixel gather above instead (``tile_plan``; a second
kernel that only those work-groups run): the direction — the tile centre's is off by up to
(half diagonal ≈ 9 px)/r rad, so a tile takes the exact path when :math:`\max(A)\cdot 9/r >
\frac12` px — and undersampling at depth edges, where a pixel's ellipse is smaller than half the
tile's bound along an axis longer than ½ px. On the flagship f/1.4 benchmark frame 1.5 % of the
tiles take the exact path. The reference implements both paths and the same tile plan, decided
on the device's own float32 semi-axes (``semi_axes_px32``: the LUT and float32 arithmetic of the
kernels, bit-equal on PoCL), so every class threshold (exact, copy, tap counts, point classes)
splits the tiles as on the device; its gathers use the float64 semi-axes (exact curves, up to
5e-4 px from the LUT's).

**Tile classes (speed).** Where the ellipses are small, N taps oversample them; each tile's
bounding semi-axis :math:`B = \max(A_s, A_t)` picks its class (``tile_taps``; the device writes
one tile list per class and each class is its own launch, so no branch enters the vector loop):

* :math:`B <` ``COPY_PX`` = 0.02 px: the tile is copied. Bound (``test_copy_threshold_error_bound``):
  the full gather with a 0.02 px ellipse changes a unit step edge by at most 0.86 % and a unit
  point by 1.7 % — invisible beside the edge's own contrast.
* otherwise the fewest taps :math:`n \in \{4, 8, \dots, N\}` with :math:`B/n \le` ``FULL_AT_PX``
  :math:`/N` (``FULL_AT_PX`` = 4 px): a tile is never sampled more sparsely than the quality's N
  samples a 4 px ellipse. The spiral's error on a worst-case edge is about :math:`0.3\,B/n` of the
  step (measured against 64 taps: 4.7 % for B = ½, n = 4; 3.7 % for B = 1, n = 8; 6.3 % for B = 4,
  n = 16), so the rule caps it at about 7.5 % (draft) / 1.9 % (final) — the level the quality
  already has at 4 px.
* tiles flagged for the exact path keep the quality's N.

Draft at 1920×1080 on the benchmark's no_defocus frame: 9 % of the tiles copied, 23 % at 4 or 8
taps; the pad and tiles passes are the fixed rest of the stage's cost. Draft's 99.9th percentile of
|draft − final| there is 5.3 on values 0.08–500 (mean 0.018). Speed and accuracy against one class
for all tiles: docs/benchmarks.md, "astigmatism: tile classes".

**Point taps (speed).** Where every pixel of a (non-exact) tile has both semi-axes ≥ 4 px, a
bilinear tap's four loads per channel buy little: the ellipse is wide and its N taps are sparse
on it. Those tiles take one load per channel from a copy of the colour box-filtered over
``POINT_BOX`` × ``POINT_BOX`` = 4 × 4 pixels, at the tap's floor (:math:`P(p) =
\frac1{16}\sum_{i,j=-1}^{2} C(p + (i, j))`, centred at p + ½, so within ½ px of the tap), and
from 8 px on 32 taps instead of final's 64 (``POINT_CLASSES``: (8 px, 32), (4 px, 64); never more
than the quality's N, so draft takes 16 point taps from 4 px on, where it took 16 bilinear ones).
A tap then spreads over the box's variance :math:`(k^2-1)/12` plus the rounding's
1/12 per axis, :math:`k^2/12` in all, where a bilinear tap spreads over 1/6 on average; the
difference is taken from the ellipse (variances add), so the second moments stay the closed
form's:

.. math::

    a'^2 = a^2 - 4\Big(\frac{k^2}{12} - \frac16\Big) = a^2 - \tfrac{14}{3}\ \mathrm{px}^2

for the tile's bound and every pixel's own ellipse (the reach test keeps the sources' own
semi-axes; a point tile's reach flag compares with its shrunk bound); the factor 4 is a uniform
disc's: semi-axis a, variance a²/4 per axis. Unlike a bilinear tap, a point tap is piecewise
constant in its offset: as a tile's bound moves (a focus pull) its output steps by one tap's share
of the box's difference where a tap crosses a pixel edge. Accuracy and speed against 64 bilinear taps
(``tools/astigmatism_point_check.py``): docs/benchmarks.md, "astigmatism: point classes".
Why not fewer point taps (16 of them bias a lone highlight's axes by up to 8 %: the tile bound seen
through a pattern too sparse for the membership cut, plus the Vogel-16 spiral's unequal ⟨u²⟩):
docs/benchmarks.md, "astigmatism: why 16 point taps bias a highlight's sagittal axis".
The box plane is filled only where point tiles read (``astigmatism_reach`` flags the tiles within
reach of one, ``astigmatism_box`` skips the others).

**Reach test skipped (speed).** A tap's reach weight is 1 when :math:`q^2 \le 1`. The taps of a
tile have :math:`|u_s| \le A_s|v_x|` and :math:`|u_t| \le A_t|v_y|` with :math:`|v| < 1` (a spiral
point), and they land within PAD px of the tile. So if every pixel there has
:math:`\alpha_s' + \frac12 \ge A_s` and :math:`\alpha_t' + \frac12 \ge A_t`, then
:math:`q^2 \le |v|^2 < 1` for every tap: each of its reach weights is 1, and the tile's gather
skips the test (``astigmatism_reach``, per tile). This holds for 98 % of the tiles of the
no_defocus frame, whose ellipses vary by far less than ½ px over 2·PAD px, and for 14 % of the
``worst`` frame's. The result is the same up to rounding: the clamp written with |·| gives
1 ± 1 ulp, so max |old − new| is 1.5e-5 on values up to 500. Fixed passes, per frame: the
padded copy and the axes work on 16 pixels per work-item. Only the ring that border tiles read is
copied, because inner tiles read the source planes. The per-pixel focal offsets (LUT) are
computed once for each camera and frame size.

A frame without depth: not planned (``--explain`` says so).

Domain/range: colour ≥ 0 → convex combination of input colours; depth 0⁺ … +inf (depths below
1 µm are treated as 1 µm); no NaN/Inf for any finite camera, and finite colour up to FLT_MAX
stays finite (the gathers' weights are scaled by 1/N, so no sum exceeds the largest input).

References: W. J. Smith, *Modern Optical Engineering*, 4th ed., §3.6 (astigmatism, field
curvature, Coddington equations); Hecht, *Optics*, 5th ed., §6.3.1.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..params import CORNER_MM, param, parse_fraction
from . import _field as fld
from .base import GatherStage, per_camera


@dataclass(frozen=True)
class AstigmatismParams:
    """Parametric third-order astigmatism (mm on the film at the sensor's half diagonal) for a lens
    without a prescription. None takes it from the traced lens (lens_data) or leaves it out (thin
    lens); a number replaces the traced curve (0 turns the effect off)."""

    field_curvature_mm: float | None = param(
        None, unit="mm", flag="--field-curvature", parse=parse_fraction, check=CORNER_MM,
        header="clpost.field_curvature_mm", scalar=False,
        help="mean sagittal/tangential focal offset at the image corner in mm (+ = behind the film)")
    astigmatism_mm: float | None = param(
        None, unit="mm", flag="--astigmatism", parse=parse_fraction, check=CORNER_MM, header="clpost.astigmatism_mm",
        scalar=False, help="tangential minus sagittal focal offset at the image corner in mm")


TAPS = {"draft": 16, "preview": 32, "final": 64}
# tile classes (module docstring, "Tile classes"): copied below COPY_PX; otherwise the fewest of
# 4, 8, ... TAPS[quality] taps with B <= n * FULL_AT_PX / TAPS[quality]
COPY_PX = 0.02
FULL_AT_PX = 4.0
MIN_TILE_TAPS = 4
# point classes (module docstring, "Point taps"): (smallest semi-axis of the tile's pixels in px, taps),
# largest first; the taps read the colour box-filtered over POINT_BOX × POINT_BOX pixels, on
# ellipses shrunk by POINT_SHRINK_PX2 per axis (a'² = a² − S)
POINT_CLASSES = ((8.0, 32), (4.0, 64))
POINT_BOX = 4
POINT_SHRINK_PX2 = 4.0 * (POINT_BOX * POINT_BOX / 12.0 - 1.0 / 6.0)


def point_classes(taps: int) -> tuple[tuple[float, int], ...]:
    """POINT_CLASSES for a quality of ``taps`` taps: never more than the quality's N (draft 16:
    one class from 4 px on), classes of equal count merged (the lower threshold)."""
    out: list[tuple[float, int]] = []
    for px, n in POINT_CLASSES:
        n = min(n, taps)
        if out and out[-1][1] == n:
            out[-1] = (px, n)
        else:
            out.append((px, n))
    return tuple(out)
MAX_SEMI_PX = fld.PAD - 1
MIN_SEMI_PX = 1e-3
MIN_DEPTH_MM = 1e-3


def focal_offsets(camera):
    """``fn(r_mm) -> (δ_s, δ_t)`` in mm (+ = behind the film), or None (no source)."""
    if camera.field_curvature_mm is not None or camera.astigmatism_mm is not None:
        fc = camera.field_curvature_mm or 0.0
        ast = camera.astigmatism_mm or 0.0
        rc = fld.corner_mm(camera)

        def parametric(r):
            q = (np.asarray(r, np.float64) / rc) ** 2
            return (fc - 0.5 * ast) * q, (fc + 0.5 * ast) * q

        return parametric
    curves = camera.lens_curves()
    if curves is None:
        return None
    s0, t0 = float(curves.sagittal_offset_mm[0]), float(curves.tangential_offset_mm[0])
    return lambda r: (curves.at("sagittal_offset_mm", r) - s0, curves.at("tangential_offset_mm", r) - t0)


def thin_lens(camera) -> tuple[float, float, float]:
    """(D, v, f) in mm: entrance pupil diameter f/N (f the lens's EFL), and the film distance v and
    focal length of the thin lens that images like the camera at its focus depth u (from the
    pinhole, like the depth pass): v = F, the camera's ``render_focal_length_mm``, and
    1/f_eq = 1/F + 1/u — so c_0 = D F |1/z − 1/u| is the dof stage's CoC, zero at the same depth
    for thin and real lenses alike (a thin lens has F = v and f_eq = f exactly)."""
    big_f = camera.render_focal_length_mm
    u = camera.focused_depth_m * 1000.0
    f_eq = big_f if math.isinf(u) else 1.0 / (1.0 / big_f + 1.0 / u)
    return camera.focal_length_mm / camera.f_number, big_f, f_eq


def axes_mm(d_s, d_t, depth_m, aperture, v, f):
    """(c_s, c_t, c_0): ellipse axes and the flat-field CoC (mm, float64) of the module docstring."""
    z = np.maximum(np.asarray(depth_m, np.float64) * 1000.0, MIN_DEPTH_MM)
    inv_z = np.where(np.isinf(z), 0.0, 1.0 / np.where(np.isinf(z), 1.0, z))
    g = 1.0 / f - inv_z
    # 1 - v g written as (1 - v/f) + v/z: no cancellation of two numbers near 1 in focus
    e0 = (1.0 - v / f) + v * inv_z

    def c(d):
        den = 1.0 + d * g
        big = den <= 1e-6  # the astigmatic focus would be at or beyond infinity: huge blur
        return np.where(big, np.inf, aperture * np.abs(e0 + d * g) / np.where(big, 1.0, den))

    return c(d_s), c(d_t), c(0.0)


def residual_semi_px(cx, c0, pitch):
    """Semi-axis in px of this stage's ellipse, √max(c² − c0², 0)/2p, capped at 15 px."""
    with np.errstate(invalid="ignore", over="ignore"):
        a = np.sqrt(np.maximum((cx - c0) * (cx + c0), 0.0)) * (0.5 / pitch)
    return np.minimum(np.nan_to_num(a, nan=MAX_SEMI_PX, posinf=MAX_SEMI_PX), MAX_SEMI_PX)


@lru_cache(maxsize=16)
def _offsets_lut(camera) -> np.ndarray:
    """The focal-offset LUT of a camera (read-only; the planner and the device plan ask for it
    every frame, and a traced lens's curve costs a trace)."""
    lut = fld.sample_lut(focal_offsets(camera), camera, 2)
    lut.setflags(write=False)
    return lut


class Astigmatism(GatherStage):
    name = "astigmatism"
    order = 20.0
    role = "field-dependent directional blur (sagittal/tangential focus)"
    domains = ("render", "render")
    params = AstigmatismParams
    reads = ("depth",)

    @property
    def taps(self) -> int:
        return TAPS[self.quality]

    @per_camera
    def _lut(self, camera) -> np.ndarray:
        return _offsets_lut(camera)

    def skip_reason(self, camera, frame):
        fn = focal_offsets(camera)
        if fn is None:
            return "thin lens without Camera.field_curvature_mm / astigmatism_mm"
        if not np.any(self._lut(camera)):
            return "sagittal and tangential focal offsets are zero over the sensor"
        if frame.depth is None:
            # the blur depends on each pixel's depth; a colour-only frame keeps working without
            # this stage and --explain says why nothing was added
            return "the frame has no depth buffer (the blur depends on each pixel's depth)"
        return None

    def reason_needed(self, camera, frame):
        r = np.linspace(0.0, fld.corner_mm(camera), 256)
        ds, dt = focal_offsets(camera)(r)
        i = int(np.argmax(np.abs(ds - dt)))
        s, t = point_source_axes_px(camera, float(r[i]), camera.focus_distance_m, fld.image_width_px(frame))
        return (f"largest astigmatism at {r[i]:.3g} mm: sagittal {float(ds[i]):+.3g} mm, tangential "
                f"{float(dt[i]):+.3g} mm (in focus: {s:.2g} × {t:.2g} px); {self.taps} taps")

    def tap_classes(self) -> list[int]:
        """Tap counts of the gather classes, fewest first: 4, 8, ... up to the quality's N."""
        n, out = MIN_TILE_TAPS, []
        while n < self.taps:
            out.append(n)
            n *= 2
        return out + [self.taps]

    def defines(self, camera):
        classes = self.tap_classes()
        return {"ASTIGMATISM_TAPS": self.taps, "ASTIGMATISM_PAD": fld.PAD,
                "ASTIGMATISM_LUT_SIZE": fld.LUT_SIZE, "ASTIGMATISM_TILE_W": fld.TILE_W,
                "ASTIGMATISM_TILE_H": fld.TILE_H, "ASTIGMATISM_POINT_BOX": POINT_BOX,
                # copy, one per tap count, one per point class, exact
                "ASTIGMATISM_CLASSES": len(classes) + len(point_classes(self.taps)) + 2,
                "ASTIGMATISM_TAP_CLASSES": len(classes),
                "ASTIGMATISM_COPY_PX": f"{COPY_PX!r}f",
                "ASTIGMATISM_TAPS_PER_PX": f"{FULL_AT_PX / self.taps!r}f",
                "ASTIGMATISM_FULL_TAP0": sum(classes[:-1])}

    @staticmethod
    def inner_tiles(w: int, h: int) -> np.ndarray:
        """(tiles_y, tiles_x) bool: tiles whose every read (pixel ± PAD, + 1 for the bilinear
        neighbour) lies inside the frame; their gathers read the source planes, not the padded copy."""
        ntx, nty = fld.tiles(w, h)
        m = fld.PAD + 1
        x0, y0 = np.arange(ntx) * fld.TILE_W, np.arange(nty) * fld.TILE_H
        ix = (x0 >= m) & (x0 + fld.TILE_W + m <= w)
        iy = (y0 >= m) & (y0 + fld.TILE_H + m <= h)
        return iy[:, None] & ix[None, :]

    @classmethod
    def ring(cls, w: int, h: int) -> tuple[int, int, int, int]:
        """(x0, x1, y0, y1): the source rectangle that only inner tiles read (their union shrunk by
        PAD + 1), so astigmatism_pad skips its colour copy; (0, 0, 0, 0) when there is none."""
        inner = cls.inner_tiles(w, h)
        if not inner.any():
            return 0, 0, 0, 0
        tx, ty = np.flatnonzero(inner.any(0)), np.flatnonzero(inner.any(1))
        m = fld.PAD + 1
        x0, x1 = int(tx[0]) * fld.TILE_W + m, (int(tx[-1]) + 1) * fld.TILE_W - m
        y0, y1 = int(ty[0]) * fld.TILE_H + m, (int(ty[-1]) + 1) * fld.TILE_H - m
        return (x0, x1, y0, y1) if x0 < x1 and y0 < y1 else (0, 0, 0, 0)

    def tile_directions(self, w: int, h: int, cx: float, cy: float) -> np.ndarray:
        """(tiles_y, tiles_x, 4) float32: the tile centre's unit radial vector (e_x, e_y), its
        distance r (px) from the principal point and a zero; the device replaces the last two by
        the tile's largest semi-axes."""
        _, _, r, ex, ey = fld.tile_centres(w, h, cx, cy)
        return np.stack([ex, ey, r, np.zeros_like(ex)], -1).astype(np.float32)

    def enqueue(self, rt, camera, frame, src, dst, aux):
        from .astigmatism_cl import enqueue_astigmatism

        return enqueue_astigmatism(self, rt, camera, frame, src, dst, aux)

    # -- the oracle -------------------------------------------------------------------------
    def semi_axes_px(self, camera, frame):
        """(a_s/2p, a_t/2p, e_x, e_y): per-pixel semi-axes (px) and radial unit vector, float64."""
        w, h = frame.width, frame.height
        k = fld.frame_geometry(camera, frame)
        cx, cy = fld.principal_point_px(camera, w, h, k)
        pitch = fld.pitch_mm(camera, w, k)
        _, _, r, ex, ey = fld.radial_frame(w, h, cx, cy)
        ds, dt = focal_offsets(camera)(r * pitch)
        depth = np.full((h, w), np.inf) if frame.depth is None else frame.depth
        cs, ct, c0 = axes_mm(ds, dt, depth, *thin_lens(camera))
        return residual_semi_px(cs, c0, pitch), residual_semi_px(ct, c0, pitch), ex, ey

    def semi_axes_px32(self, camera, frame):
        """(a_s, a_t): the kernels' float32 semi-axes (px), operation for operation as
        astigmatism_offsets and astigmatism_pad compute them (the LUT of the focal offsets, float32
        arithmetic, no contraction: those kernels turn FP_CONTRACT off). The tile classes are
        decided on these, so the reference classifies a tile as the device does even where the
        float64 semi-axes (exact curves, no LUT; up to 5e-4 px away) lie across a threshold; the
        gathers keep the float64 ones. Bit-equal with PoCL on a CPU (correctly rounded / and
        sqrt); ``tests/test_astigmatism.py::test_device_semi_axes_are_the_emulated_ones``."""
        f4 = np.float32
        w, h = frame.width, frame.height
        k = fld.frame_geometry(camera, frame)
        cx, cy = (f4(v) for v in fld.principal_point_px(camera, w, h, k))
        pitch = f4(fld.pitch_mm(camera, w, k))
        lut_scale = f4((fld.LUT_SIZE - 1) / fld.lut_range_mm(camera))
        lut = self._lut(camera).astype(f4)
        with np.errstate(all="ignore"):
            # astigmatism_offsets: the LUT over image height, linear
            dx = np.arange(w, dtype=f4)[None, :] - cx
            dy = np.arange(h, dtype=f4)[:, None] - cy
            r = np.sqrt(dx * dx + dy * dy)
            t = np.fmin(r * pitch * lut_scale, f4(fld.LUT_SIZE - 1))
            k0 = np.minimum(t.astype(np.int32), fld.LUT_SIZE - 2)
            ft = t - k0.astype(f4)
            d_s, d_t = (lt[k0] + (lt[k0 + 1] - lt[k0]) * ft for lt in lut)
            # astigmatism_pad: thin-lens defocus terms and astigmatism_semi16
            aperture, v, f = thin_lens(camera)
            aperture, v, inv_f = f4(aperture), f4(v), f4(1.0 / f)
            depth = np.full((h, w), np.inf, f4) if frame.depth is None else np.asarray(frame.depth, f4)
            zmm = np.fmax(depth * f4(1000.0), f4(MIN_DEPTH_MM))
            inv_z = np.where(np.isinf(zmm), f4(0.0), f4(1.0) / zmm)
            g = inv_f - inv_z
            e0 = (f4(1.0) - v * inv_f) + v * inv_z
            c0 = aperture * np.abs(e0)
            hip = f4(0.5) / pitch

            def semi(d):
                den = f4(1.0) + d * g
                c = aperture * np.abs(e0 + d * g) / den
                a = np.sqrt(np.fmax((c - c0) * (c + c0), f4(0.0))) * hip
                ok = (den > f4(1e-6)) & np.isfinite(a)
                return np.where(ok, np.fmin(a, f4(MAX_SEMI_PX)), f4(MAX_SEMI_PX)).astype(f4)

            return semi(d_s), semi(d_t)

    EXACT_PX = 0.5
    MIXED = 0.5

    def tile_taps(self, bound) -> np.ndarray:
        """Tap count per tile from its bounding semi-axis B (px): 0 (copy) below COPY_PX, else the
        fewest n of :meth:`tap_classes` with B <= n · FULL_AT_PX / N (the quality's N). Compared
        in float32, as astigmatism_tiles does."""
        f4 = np.float32
        bound = np.asarray(bound, f4)
        out = np.full(bound.shape, self.taps, np.int64)
        for n in self.tap_classes()[-2::-1]:
            out = np.where(bound <= f4(n) * f4(FULL_AT_PX / self.taps), n, out)
        return np.where(bound < f4(COPY_PX), 0, out)

    def _tile_extremes(self, camera, frame):
        """Per tile, float32, from :meth:`semi_axes_px32` (the device's values, so the classes are
        the device's): (hi, lo), each (2, tiles_y, tiles_x), the largest and smallest (a_s, a_t)
        of the tile's pixels."""
        w, h = frame.width, frame.height
        a_s, a_t = self.semi_axes_px32(camera, frame)
        ntx, nty = fld.tiles(w, h)
        big = np.full((2, nty * fld.TILE_H, ntx * fld.TILE_W), np.nan, np.float32)
        big[0, :h, :w], big[1, :h, :w] = a_s, a_t
        blocks = big.reshape(2, nty, fld.TILE_H, ntx, fld.TILE_W)
        return np.nanmax(blocks, axis=(2, 4)), np.nanmin(blocks, axis=(2, 4))

    def tile_plan(self, camera, frame):
        """Per tile: the bounding semi-axes (A_s, A_t; float64), the tile centre's radial
        vector (e_x, e_y), whether it takes the exact per-pixel path (bool), and its tap count
        (0 = copied; exact tiles take the quality's N). The classes (exact path, tap count) are
        decided in float32 on the device's semi-axes (:meth:`semi_axes_px32`), as
        astigmatism_tiles decides them."""
        f4 = np.float32
        w, h = frame.width, frame.height
        a_s, a_t, _, _ = self.semi_axes_px(camera, frame)
        cx, cy = fld.principal_point_px(camera, w, h, fld.frame_geometry(camera, frame))
        _, _, r, tex, tey = fld.tile_centres(w, h, cx, cy)
        ntx, nty = fld.tiles(w, h)
        big = np.full((2, nty * fld.TILE_H, ntx * fld.TILE_W), np.nan)
        big[0, :h, :w], big[1, :h, :w] = a_s, a_t
        hi = np.nanmax(big.reshape(2, nty, fld.TILE_H, ntx, fld.TILE_W), axis=(2, 4))
        hi32, lo32 = self._tile_extremes(camera, frame)
        half_diag = f4(0.5) * np.sqrt(f4(fld.TILE_W * fld.TILE_W + fld.TILE_H * fld.TILE_H))
        bound32 = np.fmax(hi32[0], hi32[1])
        turn = bound32 * half_diag > f4(self.EXACT_PX) * r.astype(f4)
        mixed = np.any((hi32 > f4(self.EXACT_PX)) & (lo32 < f4(self.MIXED) * hi32), axis=0)
        exact = turn | mixed
        taps = np.where(exact, self.taps, self.tile_taps(bound32))
        return hi[0], hi[1], tex, tey, exact, taps

    def point_taps(self, camera, frame, exact=None) -> np.ndarray:
        """Per tile: the point class's tap count (module docstring, "Point taps"), 0 for the tiles
        that take none — the exact ones, and those with a pixel whose smaller semi-axis is below
        the last class's threshold (:func:`point_classes`; on the device's float32 semi-axes,
        :meth:`semi_axes_px32`)."""
        _, lo32 = self._tile_extremes(camera, frame)
        lo = np.fmin(lo32[0], lo32[1])
        out = np.zeros(lo.shape, np.int64)
        for px, n in point_classes(self.taps)[::-1]:
            out = np.where(lo >= np.float32(px), n, out)
        if exact is None:
            exact = self.tile_plan(camera, frame)[4]
        return np.where(exact, 0, out)

    def reference(self, camera, frame, color):
        """float64 numpy implementation of the module docstring (exact offset curves, no LUT):
        the tile model with each tile's tap count, the point classes on their tiles, the
        per-pixel model on the tiles ``tile_plan`` flags, the input on the copied tiles."""
        color = np.asarray(color, np.float64)
        h, w = color.shape[:2]
        a_s, a_t, pex, pey = self.semi_axes_px(camera, frame)
        bound_s, bound_t, tex, tey, exact, taps = self.tile_plan(camera, frame)
        point = self.point_taps(camera, frame, exact)
        bs, bt = fld.per_pixel(bound_s, w, h), fld.per_pixel(bound_t, w, h)
        ex, ey = fld.per_pixel(tex, w, h), fld.per_pixel(tey, w, h)
        taps_px = fld.per_pixel(np.where(exact, -1, np.where(point > 0, -2, taps)), w, h)
        point_px = fld.per_pixel(point, w, h)
        out = color.copy()  # the copied tiles (tap count 0)
        for n in np.unique(taps):
            sel = taps_px == n
            if n > 0 and sel.any():
                out[sel] = self._gather(color, a_s, a_t, bs, bt, ex, ey, own=True, n=int(n))[sel]
        for n in np.unique(point[point > 0]):
            sel = (taps_px == -2) & (point_px == n)
            out[sel] = self._gather(color, a_s, a_t, bs, bt, ex, ey, own=True, n=int(n), box=True)[sel]
        if exact.any():
            sel = taps_px == -1
            out[sel] = self._gather(color, a_s, a_t, a_s, a_t, pex, pey, own=False)[sel]
        # copied pixels: decided on the device's float32 semi-axes like the tile classes (near the
        # centre the LUT's linear first segment puts them ~10 % above the exact curves')
        s32, t32 = self.semi_axes_px32(camera, frame)
        still = (s32 < np.float32(MIN_SEMI_PX)) & (t32 < np.float32(MIN_SEMI_PX))
        out[still] = color[still]
        return out

    def _gather(self, color, a_s, a_t, bs, bt, ex, ey, own: bool, n: int | None = None, box: bool = False):
        """``n`` taps (default: the quality's) over the ellipse (bs, bt) along (e_s, e_t) =
        ((−e_y, e_x), (e_x, e_y)), weighted by the source's reach and (``own``) by membership in
        the pixel's own ellipse (a_s, a_t). ``box``: point taps of the box-filtered colour on the
        shrunk ellipses (module docstring, "Point taps"); the reach test keeps the sources' own
        semi-axes."""
        h, w = color.shape[:2]
        pad = fld.PAD
        src_s, src_t = np.pad(a_s, pad, mode="edge"), np.pad(a_t, pad, mode="edge")
        if box:
            def shrunk(a):
                return np.sqrt(np.maximum(a * a - POINT_SHRINK_PX2, 0.0))

            a_s, a_t, bs, bt = shrunk(a_s), shrunk(a_t), shrunk(bs), shrunk(bt)
            pre = box_filtered(color)
        is2, it2 = 1.0 / (a_s * a_s + 1e-3), 1.0 / (a_t * a_t + 1e-3)
        xs, ys = np.mgrid[0:h, 0:w].astype(np.float64)[::-1]
        acc = np.zeros_like(color)
        wsum = np.zeros((h, w))
        for ux, uy in fld.vogel_disc(n or self.taps).astype(np.float64):
            us, ut = bs * ux, bt * uy
            ox = -ey * us + ex * ut
            oy = ex * us + ey * ut
            # the source pixel's own ellipse (+ half a pixel) must reach back to the target
            ix = np.clip(np.floor(xs + ox + 0.5).astype(np.int64) + pad, 0, w + 2 * pad - 1)
            iy = np.clip(np.floor(ys + oy + 0.5).astype(np.int64) + pad, 0, h + 2 * pad - 1)
            q2 = (us / (src_s[iy, ix] + 0.5)) ** 2 + (ut / (src_t[iy, ix] + 0.5)) ** 2
            wk = np.clip((1.5625 - q2) / 0.5625, 0.0, 1.0)
            if own:  # and the tap must lie inside the target's own ellipse
                wk = wk * np.clip((1.125 - (us * us * is2 + ut * ut * it2)) * 8.0, 0.0, 1.0)
            if box:  # the box's origin at floor(x + o): pre's padding is PAD + 1 before, PAD + 2 after
                jx = np.clip(np.floor(xs + ox).astype(np.int64), -pad, w - 1 + pad) + pad + 1
                jy = np.clip(np.floor(ys + oy).astype(np.int64), -pad, h - 1 + pad) + pad + 1
                acc += pre[jy, jx] * wk[..., None]
            else:
                acc += fld.bilinear_padded(color, xs + ox, ys + oy) * wk[..., None]
            wsum += wk
        return np.where(wsum[..., None] > 0, acc / np.where(wsum > 0, wsum, 1.0)[..., None], color)


def box_filtered(color) -> np.ndarray:
    """The point classes' prefiltered colour (float64): the mean of C(x + i, y + j), i, j = −1 …
    POINT_BOX − 2, of the image continued by its edge values, at x, y from −PAD − 1 to size + PAD
    (index 0 is −PAD − 1; the kernels' pre plane, which starts at −PAD, plus one before)."""
    c = np.asarray(color, np.float64)
    k, pad = POINT_BOX, fld.PAD
    lo = pad + 1 + (k - 1) // 2  # pre's first position is −PAD − 1, its box starts (k−1)//2 before
    hi = pad + 2 + k - 1 - (k - 1) // 2
    big = np.pad(c, ((lo, hi), (lo, hi), (0, 0)), mode="edge")
    h, w = c.shape[0] + 2 * pad + 3, c.shape[1] + 2 * pad + 3
    return sum(big[i:i + h, j:j + w] for i in range(k) for j in range(k)) / (k * k)


def point_source_axes_px(camera, r_mm: float, depth_m: float, width: int) -> tuple[float, float]:
    """Closed form: full axes (sagittal, tangential) in px of this stage's ellipse for a point at
    image height ``r_mm`` and depth ``depth_m`` (for tests and docs)."""
    ds, dt = focal_offsets(camera)(np.array(r_mm))
    cs, ct, c0 = axes_mm(ds, dt, np.array(depth_m), *thin_lens(camera))
    p = fld.pitch_mm(camera, width)
    return (2 * float(residual_semi_px(cs, c0, p)), 2 * float(residual_semi_px(ct, c0, p)))


def splat_axes_px(splat, taps: int) -> tuple[float, float]:
    r"""Measured twin of :func:`point_source_axes_px`: full axes (sagittal, tangential) in px of the
    splat ``splat`` (H × W, one channel) of a point source on the image's horizontal axis (sagittal
    along y, tangential along x) gathered with ``taps`` taps, from its second moments. Taps at
    :math:`a\,u` (:math:`u` the unit spiral, :func:`~clpost.stages._field.vogel_disc`) spread the
    splat over :math:`\sigma^2 = a^2 \langle u^2\rangle + \frac16` per axis — 1/6 from bilinear
    weights at uniform sub-pixel offsets, which the point classes' shrunk ellipses keep (module
    docstring, "Point taps") — so :math:`2a = 2\sqrt{(\sigma^2 - \frac16)/\langle u^2\rangle}`. It reports the
    semi-axis the spiral was scaled by, not the splat's physical size: the two differ by the
    spiral's own :math:`\langle u^2\rangle` against a uniform disc's ¼ (16 points: 0.2295 / 0.2705,
    −4.2 / +4.0 % on the axes; 64: within 0.1 %); ``tools/astigmatism_point_check.py`` prints both."""
    m = np.asarray(splat, np.float64)
    m = m / m.sum()
    ys, xs = np.mgrid[0:m.shape[0], 0:m.shape[1]]
    mx, my = (m * xs).sum(), (m * ys).sum()
    vx, vy = (m * (xs - mx) ** 2).sum(), (m * (ys - my) ** 2).sum()
    u = fld.vogel_disc(taps).astype(np.float64)
    return (2 * math.sqrt(max(vy - 1 / 6, 0) / np.mean(u[:, 0] ** 2)),
            2 * math.sqrt(max(vx - 1 / 6, 0) / np.mean(u[:, 1] ** 2)))


__all__ = ["Astigmatism", "axes_mm", "box_filtered", "focal_offsets", "point_classes", "point_source_axes_px",
           "splat_axes_px", "thin_lens"]
