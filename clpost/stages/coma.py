r"""coma: the comet-shaped, field-dependent PSF of third-order coma, as a gather.

**The PSF.** A ray through the normalised pupil point :math:`(p_x, p_y) = \rho(\sin\theta,
\cos\theta)` (y radial, away from the centre) lands, relative to the chief ray, at

.. math::

    \varepsilon_x = C\rho^2\sin 2\theta = 2C\,p_x p_y, \qquad
    \varepsilon_y = C\rho^2(2 + \cos 2\theta) = C\,(p_x^2 + 3p_y^2)

(Seidel coma; Smith, *Modern Optical Engineering*, 4th ed., §3.5; Hecht, *Optics*, 5th ed.,
§6.3.1): each pupil zone ρ draws a circle of radius Cρ² centred 2Cρ² from the chief ray, so the
comet's head sits on the chief ray, its tail reaches :math:`3C` (tangential coma) radially, its
width is :math:`2C` (sagittal coma ×2), inside a 60° wedge, and its centroid is :math:`C` from the
head (⟨ρ²⟩ = ½ for a uniform pupil). C > 0 points the tail away from the centre.

**C(r)** (mm on the film):

* a traced lens: the meridional fan at each field height of the lens curves, traced (unclipped,
  like the curves' astigmatic foci) to the film at the camera's focus and f-number; the
  even part of the transverse ray aberration, :math:`\tfrac12(\varepsilon_y(\rho) +
  \varepsilon_y(-\rho)) = 3C\rho^2` (defocus and spherical aberration are odd in ρ), fitted by
  least squares (pupil-area weight ρ dρ) over ρ ∈ [0.07, 0.7]: the inner half of the pupil's
  area, where the ρ² law of third-order coma holds. At f/1.4 the Planar's rim rays
  (ρ > 0.8) scatter by 0.1–0.3 mm with the steep zonal spherical aberration of a fast double
  Gauss; fitting them would make a comet of ~0.2 mm next to the axis, where the real PSF is a
  sharp core with a faint flare (that flare is spherical aberration, not this stage's);
* parametric: ``Camera.coma_mm`` = the comet length 3C at the image corner :math:`r_c`, linear in
  the field height (Seidel coma ∝ r): :math:`C(r) = \text{coma\_mm}/3 \cdot r/r_c`.

**Gather.** :math:`C'(x) = \frac1N\sum_k J_k(x)\,C_{in}\big(x - \varepsilon_k(x)\big)`, the
pupil sampled by a Vogel spiral :math:`u_k` of N points (uniform weights, so the ray density is
the PSF's), :math:`\varepsilon_k = C(r)\,(t_{k,s}\,e_s + t_{k,r}\,e_r)` with
:math:`t_k = (2p_xp_y,\ p_x^2 + 3p_y^2)` in the pixel's (sagittal, radial) frame, bilinear taps
from a copy padded by 16 px. Because the PSF changes with r, a plain gather would not conserve
energy (the comet of a point at r carries :math:`1 - 2C/r` of it: 4 % for a linear coma of
C/r = 2 %); each tap is weighted by the Jacobian of its map :math:`x \mapsto x - \varepsilon_k(x)`,
in polar coordinates

.. math::

    J_k = \Big(1 - C'\,t_{k,r}\Big)\Big(1 - \frac{C}{r}\,t_{k,r}\Big) + \frac{C}{r}\,C'\,t_{k,s}^2

(C' = dC/dr; C/r → C'(0) on the axis; J clamped at 0 where a comet folds over), so the light of
every source point is conserved (a scatter's property) up to the bilinear resampling's ripple.
A uniform field is therefore *not* left exactly uniform: coma moves the energy centroid outward by
C(r), which dims it by :math:`\langle J\rangle \approx 1 - 2C/r`, as a magnification would. The
comet length is capped at 15 px (C' = 0 where capped). Quality sets N: draft 16, preview 32,
final 64 (on the window tiles; the uniform tiles take 64 at every quality, "Stencils" below).

**Tiles (speed).** PoCL vectorises a gather across pixels only when every work-item of a group
reads at the same offsets (docs/measurements.md#gather-layouts-on-pocl). The comet changes
slowly with field height, so the kernel runs on tiles of 16 × 8 px (:mod:`clpost.stages._field`)
and reads each tap's bilinear sample from a 3 × 3 window whose integer position
:math:`b_k = \mathrm{round}(-\varepsilon_k(T))` is the same for the whole tile (T the tile centre);
inside it, the pixel's own landing point :math:`-\varepsilon_k(x) - b_k` is interpolated with tent
weights — the exact bilinear tap as long as it lies within 1 px of :math:`b_k`, i.e. while the comet
changes by < ½ px across a tile (``shape_error_px``: ≤ 0.2 px for the flagship wide open at 720p and
1080p, 0.42 px for the steepest coefficient in the tests). Beyond, the landing point is clamped to
the window (the reference does the same). Against per-pixel addresses:
docs/measurements.md#kernel-forms-on-pocl.

**Uniform tiles.** Where a bound on the distance between any pixel's landing point and the tile
centre's, :math:`\max_k \| |t_{k,s}|\,m_s + |t_{k,r}|\,m_r \|` (m the largest deviation of the
pixels' :math:`-C e_s, -C e_r` from the centre's, per axis), is at most ``UNIFORM_PX`` = 0.05 px,
every pixel of the tile takes the tile centre's comet, times the pixel's own Jacobian. A linear
coefficient makes the comet field affine, so all tiles deviate alike: the benchmark's ``coma_mm``
0.087 mm at 1080p stays below 0.035 px everywhere; the flagship wide open (0.22 px) keeps the
window kernel. The reference takes the same tile plan (``tile_uniform``).

**Stencils (speed of the uniform tiles).** There every pixel's N bilinear taps land on the same
integer offsets :math:`d`, and the Jacobian is linear in three moments of the tap,

.. math::

    J_k = 1 - a\,t_{k,r} + b\,(t_{k,r}^2 + t_{k,s}^2), \qquad a = C' + C/r,\ b = C'\,C/r,

so the gather regroups exactly into a per-tile stencil (``uniform_stencils``, built on the host
once per camera and frame size):

.. math::

    C'(x) = \sum_d \big(W_0(d) - a(x)\,W_1(d) + b(x)\,W_2(d)\big)\,C_{in}(x + d), \qquad
    W_j(d) = \frac1N\sum_{k:\ \text{corner of } k \text{ at } d} c_k\,m_{j,k}

(:math:`c_k` the bilinear corner weight, :math:`m_k = (1, t_{k,r}, t_{k,r}^2 + t_{k,s}^2)`),
valid where the clamp of J at 0 cannot act — ``tile_uniform`` also requires :math:`1 -
A\max_k t_{k,r} - B\max_k(t_{k,r}^2 + t_{k,s}^2) \ge 0` with A, B the tile's largest |a|, |b|.
It reads 3 values per offset instead of 12 per tap, and the number of offsets follows the comet's
area, not N: at most 4N, 4 for a comet inside one pixel cell (where a copy would save nothing
measurable but would drop the comet and the Jacobian's dimming), 4–24 for the benchmark's
(≤ 4.4 px) comets. Tiles whose reads (|d| ≤ 16 px) stay inside the frame read the source
(``inner_tiles``), so the pad pass only fills the border ring when no window tile runs. One
kernel per stencil size (``STENCIL_SIZES``, zero-weight padding, a compile-time loop). Same
model as the tap-by-tap gather (float32 rounding only); as N does not set the cost there, the
uniform tiles take ``UNIFORM_TAPS`` (64) at every quality (draft has final's accuracy there).
Where all pixels of a uniform tile have the same a and b within ``CONST_JAC_TOL`` (a linear
coefficient: a = 2k, b = k² everywhere), the Jacobian is folded into W0 on the host
(``tile_jacobian``; coma_c<S>: no per-pixel reads of C', C/r, one scalar weight per offset). Speed
and accuracy against the tap-by-tap gather: docs/benchmarks.md, "coma: stencils for the uniform
tiles".

Domain/range: colour ≥ 0 → convex combination of input colours.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params import CORNER_MM, param, parse_fraction
from . import _field as fld
from .base import GatherStage, per_camera


@dataclass(frozen=True)
class ComaParams:
    """Parametric coma at the image corner (None: the traced lens's, or none for a thin lens)."""

    coma_mm: float | None = param(
        None, unit="mm", flag="--coma", parse=parse_fraction, check=CORNER_MM, header="clpost.coma_mm",
        scalar=False,
        help="comet length (tangential coma, 3C) at the image corner in mm (+ = tail away from the centre)")


TAPS = {"draft": 16, "preview": 32, "final": 64}
MAX_TAIL_PX = fld.PAD - 1
UNIFORM_PX = 0.05
UNIFORM_TAPS = TAPS["final"]
"""Pupil samples of the uniform tiles at every quality (their stencil merges the taps)."""
CONST_JAC_TOL = 1e-6
"""Uniform tiles whose pixels' Jacobians all lie within this of the tile's mean one take the mean
(``Coma.tile_jacobian``; coma_c<S>: no per-pixel shape reads, one scalar weight per offset)."""
STENCIL_SIZES = (4, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256)
"""Stencil sizes of the uniform tiles (one kernel each, ``coma_s<S>``): N taps of 4 bilinear
corners each reach at most 4N ≤ 256 integer offsets (fewer where the comet is short)."""
"""Tiles whose pixels' landing points are all within this (px) of the tile centre's take the
tile centre's comet (``Coma.tile_uniform``)."""
def coma_curve(camera):
    """``fn(r_mm) -> C`` in mm (+ = tail away from the centre), or None (no source)."""
    if camera.coma_mm is not None:
        k = camera.coma_mm / 3.0 / fld.corner_mm(camera)
        return lambda r: k * np.asarray(r, np.float64)
    if camera.optics is None:
        return None
    from ..optics.coma_fit import traced_coma

    r, c = traced_coma(camera.lens, camera.focus_from_film_m, camera.lens_curves().f_number)
    return lambda x: np.interp(np.abs(np.asarray(x, np.float64)), r, c)


def comet_offsets(u: np.ndarray) -> np.ndarray:
    """Landing offsets (sagittal, radial) in units of C of pupil points u (..., 2) = (p_x, p_y)."""
    px, py = u[..., 0], u[..., 1]
    return np.stack([2.0 * px * py, px * px + 3.0 * py * py], -1)


class Coma(GatherStage):
    name = "coma"
    order = 25.0
    role = "field-dependent asymmetric PSF"
    domains = ("render", "render")
    params = ComaParams

    def __init__(self, quality: str = "final") -> None:
        super().__init__(quality)
        self._uniform: tuple = (None, None)

    @property
    def taps(self) -> int:
        return TAPS[self.quality]

    @property
    def uniform_taps(self) -> int:
        """Taps of the uniform tiles: always the densest spiral (their stencil's cost follows the
        comet's area, not the tap count: module docstring, "Stencils")."""
        return max(self.taps, UNIFORM_TAPS)

    @per_camera
    def _lut(self, camera) -> np.ndarray:
        fn = coma_curve(camera)
        return fld.sample_lut(lambda r: (fn(r), derivative(fn, r)), camera, 2)

    def skip_reason(self, camera, frame):
        if coma_curve(camera) is None:
            return "thin lens without Camera.coma_mm"
        if not np.any(self._lut(camera)[0]):
            return "coma is zero over the sensor"
        return None

    def reason_needed(self, camera, frame):
        r = np.linspace(0.0, fld.corner_mm(camera), 256)
        c = coma_curve(camera)(r)
        i = int(np.argmax(np.abs(c)))
        g = comet_geometry_px(camera, float(r[i]), fld.image_width_px(frame))
        return f"longest comet at {r[i]:.3g} mm: 3C = {3 * c[i] * 1000:+.3g} µm ({g['length']:+.2g} px); {self.taps} taps"

    def defines(self, camera):
        return {"COMA_TAPS": self.taps, "COMA_PAD": fld.PAD, "COMA_LUT_SIZE": fld.LUT_SIZE,
                "COMA_TILE_W": fld.TILE_W, "COMA_TILE_H": fld.TILE_H}

    def enqueue(self, rt, camera, frame, src, dst, aux):
        from .coma_cl import enqueue_coma

        return enqueue_coma(self, rt, camera, frame, src, dst, aux)

    @staticmethod
    def inner_tiles(w: int, h: int) -> np.ndarray:
        """Per tile: whether every read of a stencil (offsets |d| ≤ PAD) lies inside the frame, so
        the tile reads the source planes rather than the padded copy."""
        ntx, nty = fld.tiles(w, h)
        ty, tx = np.mgrid[0:nty, 0:ntx]
        x0, y0 = tx * fld.TILE_W, ty * fld.TILE_H
        return ((x0 >= fld.PAD) & (x0 + fld.TILE_W + fld.PAD <= w)
                & (y0 >= fld.PAD) & (y0 + fld.TILE_H + fld.PAD <= h))

    def _uniform_key(self, camera, w, h, k=None):
        return (self._lut(camera).tobytes(), w, h, fld.pitch_mm(camera, w, k), self.taps,
                fld.principal_point_px(camera, w, h, k))

    def tile_uniform(self, camera, w: int, h: int, k=None) -> np.ndarray:
        r"""Per tile (tiles_y, tiles_x) bool: a bound on the distance between any pixel's landing
        point and the tile centre's, over its pixels and the taps, is ≤ ``UNIFORM_PX``, and no
        tap's Jacobian can reach its clamp at 0 (:math:`1 - A\max_k t_{k,r} - B\max_k(t_{k,r}^2
        + t_{k,s}^2) \ge 0`, A and B the tile's largest :math:`|C' + C/r|` and :math:`|C'\,C/r|`,
        so the Jacobian is linear in the taps' moments) — those tiles take the tile centre's comet
        for every pixel, as a stencil (memoised)."""
        key = self._uniform_key(camera, w, h, k)
        if self._uniform[0] != key:
            _, dc, q, _, _ = self.c_px(camera, w, h, k)
            ntx, nty = fld.tiles(w, h)
            big = np.zeros((2, nty * fld.TILE_H, ntx * fld.TILE_W))
            big[0, :h, :w], big[1, :h, :w] = np.abs(dc + q), np.abs(dc * q)
            a, b = big.reshape(2, nty, fld.TILE_H, ntx, fld.TILE_W).max(axis=(2, 4))
            t = comet_offsets(fld.vogel_disc(self.uniform_taps).astype(np.float64))
            no_clamp = 1.0 - a * t[:, 1].max() - b * (t * t).sum(1).max() >= 0.0
            self._uniform = (key, (self.uniform_bound_px(camera, w, h, k) <= UNIFORM_PX) & no_clamp)
        return self._uniform[1]

    def uniform_stencils(self, camera, w: int, h: int, k=None) -> list:
        r"""The uniform tiles' taps merged per integer offset, grouped by stencil size: a list of
        (S, constant Jacobian, tile ids, dx, dy, weights) with dx, dy (tiles, S) int offsets and weights (tiles, S, 4)
        float64: per offset the sums over the taps k of the bilinear weight c_k of the tile
        centre's landing point times :math:`(1, t_{k,r}, t_{k,r}^2 + t_{k,s}^2)/N` and a 0, padded
        with zero weights to S, the smallest of ``STENCIL_SIZES`` that holds the tile's offsets.
        A pixel's output is :math:`\sum_s (W_0 - a W_1 + b W_2)\,C_{in}(x + d_s)`, a = C' + C/r,
        b = C' C/r: the tap-by-tap sum of the reference regrouped. On the tiles ``tile_jacobian``
        gives one Jacobian, W0 holds :math:`W_0 - \bar a W_1 + \bar b W_2` and W1 = W2 = 0."""
        uni = self.tile_uniform(camera, w, h, k).ravel()
        ids = np.flatnonzero(uni)
        if not ids.size:
            return []
        ax = self.tile_axes_px(camera, w, h, k).reshape(-1, 4)[ids]
        t = comet_offsets(fld.vogel_disc(self.uniform_taps).astype(np.float64))
        lx = ax[:, 0:1] * t[:, 0] + ax[:, 2:3] * t[:, 1]  # (tiles, taps): the tile's landing points
        ly = ax[:, 1:2] * t[:, 0] + ax[:, 3:4] * t[:, 1]
        ix, iy = np.floor(lx), np.floor(ly)
        fx, fy = lx - ix, ly - iy
        mom = np.stack([np.ones(len(t)), t[:, 1], (t * t).sum(1)], -1) / len(t)  # (taps, 3)
        g = 2 * fld.PAD + 2  # offsets lie in [-PAD, PAD]: a key per (tile, dy, dx)
        keys, wsum = [], []
        for ox, oy, c in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
            keys.append((np.arange(ids.size)[:, None] * g + (iy + oy + fld.PAD)) * g + (ix + ox + fld.PAD))
            wsum.append(c[..., None] * mom)
        keys = np.concatenate(keys, 1).astype(np.int64).ravel()
        wsum = np.concatenate(wsum, 1).reshape(-1, 3)
        uniq, inv = np.unique(keys, return_inverse=True)
        wts = np.stack([np.bincount(inv, weights=wsum[:, j], minlength=uniq.size) for j in range(3)], -1)
        keep = np.any(wts != 0.0, axis=1)  # corners with bilinear weight 0 read nothing
        uniq, wts = uniq[keep], wts[keep]
        tile, rem = np.divmod(uniq, g * g)
        dy, dx = np.divmod(rem, g)
        count = np.bincount(tile, minlength=ids.size)
        start = np.concatenate([[0], np.cumsum(count)[:-1]])
        rank = np.arange(uniq.size) - start[tile]
        # tiles with one Jacobian for all pixels: its moments folded into W0 (W1 = W2 = 0)
        a_t, b_t, const = (v.ravel()[ids] for v in self.tile_jacobian(camera, w, h, k))
        fold = const[tile]
        wts[fold, 0] = wts[fold, 0] - a_t[tile[fold]] * wts[fold, 1] + b_t[tile[fold]] * wts[fold, 2]
        wts[fold, 1:] = 0.0
        sizes = np.asarray(STENCIL_SIZES)
        cls = np.searchsorted(sizes, count) + len(sizes) * const  # the smallest size >= count
        out = []
        for ci in np.unique(cls):
            size = int(sizes[ci % len(sizes)])
            sel_t = np.flatnonzero(cls == ci)
            row = np.full(ids.size, -1)
            row[sel_t] = np.arange(sel_t.size)
            e = row[tile] >= 0
            sdx, sdy = np.zeros((sel_t.size, size), np.int64), np.zeros((sel_t.size, size), np.int64)
            sw = np.zeros((sel_t.size, size, 4))
            sdx[row[tile[e]], rank[e]] = dx[e] - fld.PAD
            sdy[row[tile[e]], rank[e]] = dy[e] - fld.PAD
            sw[row[tile[e]], rank[e], :3] = wts[e]
            out.append((size, bool(ci >= len(sizes)), ids[sel_t].astype(np.int32), sdx, sdy, sw))
        return out

    def tile_jacobian(self, camera, w: int, h: int, k=None):
        r"""Per tile (tiles_y, tiles_x): the mean of a = C' + C/r and b = C' C/r over its pixels,
        and whether a Jacobian with them differs from every pixel's own by at most
        ``CONST_JAC_TOL`` (:math:`\max|a - \bar a|\,\max_k t_{k,r} + \max|b - \bar b|\,
        \max_k (t_{k,r}^2 + t_{k,s}^2)`): exact for a linear coefficient (a = 2k, b = k²)."""
        _, dc, q, _, _ = self.c_px(camera, w, h, k)
        ntx, nty = fld.tiles(w, h)
        big = np.full((2, nty * fld.TILE_H, ntx * fld.TILE_W), np.nan)
        big[0, :h, :w], big[1, :h, :w] = dc + q, dc * q
        blk = big.reshape(2, nty, fld.TILE_H, ntx, fld.TILE_W)
        mean = np.nanmean(blk, axis=(2, 4))
        dev = np.nanmax(np.abs(blk - mean[:, :, None, :, None]), axis=(2, 4))
        t = comet_offsets(fld.vogel_disc(self.uniform_taps).astype(np.float64))
        const = dev[0] * t[:, 1].max() + dev[1] * (t * t).sum(1).max() <= CONST_JAC_TOL
        return mean[0], mean[1], const

    def uniform_bound_px(self, camera, w: int, h: int, k=None) -> np.ndarray:
        """Per tile: :math:`\\max_k \\| (|t_{k,s}| m_{sx} + |t_{k,r}| m_{rx},\\ |t_{k,s}| m_{sy} +
        |t_{k,r}| m_{ry}) \\|` with m the largest deviation of the pixels' −C e_s, −C e_r (px) from
        the tile centre's: a bound on how far a pixel's landing point is from the tile's."""
        c, _, _, ex, ey = self.c_px(camera, w, h, k)
        tiles = self.tile_axes_px(camera, w, h, k)
        dev = np.abs(np.stack([c * ey, -c * ex, -c * ex, -c * ey]) - np.moveaxis(fld.per_pixel(tiles, w, h), -1, 0))
        ntx, nty = fld.tiles(w, h)
        big = np.zeros((4, nty * fld.TILE_H, ntx * fld.TILE_W))
        big[:, :h, :w] = dev
        m = big.reshape(4, nty, fld.TILE_H, ntx, fld.TILE_W).max(axis=(2, 4))
        t = np.abs(comet_offsets(fld.vogel_disc(self.uniform_taps).astype(np.float64)))[:, :, None, None]
        return np.hypot(t[:, 0] * m[0] + t[:, 1] * m[2], t[:, 0] * m[1] + t[:, 1] * m[3]).max(0)

    # -- the oracle -------------------------------------------------------------------------
    def tile_axes_px(self, camera, w: int, h: int, k=None) -> np.ndarray:
        """(tiles_y, tiles_x, 4) float64: per tile the gather offsets −C e_s and −C e_r (px; x
        and y each) of its centre's comet (C capped) — what the kernel's windows are placed by."""
        cx, cy = fld.principal_point_px(camera, w, h, k)
        pitch = fld.pitch_mm(camera, w, k)
        _, _, r, ex, ey = fld.tile_centres(w, h, cx, cy)
        c = np.clip(coma_curve(camera)(r * pitch) / pitch, -MAX_TAIL_PX / 3.0, MAX_TAIL_PX / 3.0)
        return np.stack([ey * c, -ex * c, -ex * c, -ey * c], -1)

    def shape_error_px(self, camera, w: int, h: int, k=None) -> tuple[float, tuple[int, int]]:
        """Largest distance (px) between a tap's landing point with the tile centre's comet and
        with the pixel's own, over all pixels and taps, and the pixel (x, y) where it occurs: the
        kernel's window is exact while this stays below ½ px."""
        c, _, _, ex, ey = self.c_px(camera, w, h, k)
        tsxx, tsxy, trxx, trxy = np.moveaxis(fld.per_pixel(self.tile_axes_px(camera, w, h, k), w, h), -1, 0)
        worst = np.zeros((h, w))
        for ts, tr in comet_offsets(fld.vogel_disc(self.taps).astype(np.float64)):
            d = np.hypot(c * (ts * ey - tr * ex) - (tsxx * ts + trxx * tr),
                         c * (-ts * ex - tr * ey) - (tsxy * ts + trxy * tr))
            worst = np.maximum(worst, d)
        j = np.unravel_index(int(np.argmax(worst)), worst.shape)
        return float(worst.max()), (int(j[1]), int(j[0]))

    def c_px(self, camera, w: int, h: int, k=None):
        """Per pixel: C in px (capped so the tail 3C ≤ 15 px), C' = dC/dr, C/r and the radial
        unit vector (float64)."""
        cx, cy = fld.principal_point_px(camera, w, h, k)
        pitch = fld.pitch_mm(camera, w, k)
        _, _, r, ex, ey = fld.radial_frame(w, h, cx, cy)
        fn = coma_curve(camera)
        c = fn(r * pitch) / pitch
        capped = np.abs(c) > MAX_TAIL_PX / 3.0
        c = np.clip(c, -MAX_TAIL_PX / 3.0, MAX_TAIL_PX / 3.0)
        dc = np.where(capped, 0.0, derivative(fn, r * pitch))
        q = np.where(r > 0, c / np.where(r > 0, r, 1.0), dc)
        return c, dc, q, ex, ey

    def reference(self, camera, frame, color):
        """float64 numpy implementation of the module docstring (exact C(r), no LUT; the landing
        point clamped to the tile's 3 × 3 window as the kernel does; the tile centre's landing
        point and ``uniform_taps`` taps on the ``tile_uniform`` tiles, with the tile's mean
        Jacobian where ``tile_jacobian`` allows)."""
        color = np.asarray(color, np.float64)
        h, w = color.shape[:2]
        k = fld.frame_geometry(camera, frame)
        c, dc, q, ex, ey = self.c_px(camera, w, h, k)
        tsxx, tsxy, trxx, trxy = np.moveaxis(fld.per_pixel(self.tile_axes_px(camera, w, h, k), w, h), -1, 0)
        xs, ys = np.mgrid[0:h, 0:w].astype(np.float64)[::-1]
        uniform = fld.per_pixel(self.tile_uniform(camera, w, h, k), w, h)
        a_t, b_t, const = (fld.per_pixel(v, w, h) for v in self.tile_jacobian(camera, w, h, k))
        a_px, b_px = np.where(const, a_t, dc + q), np.where(const, b_t, dc * q)
        out = np.zeros_like(color)
        for uni, n in ((False, self.taps), (True, self.uniform_taps)):
            if not np.any(uniform == uni):
                continue
            acc = np.zeros_like(color)
            for ts, tr in comet_offsets(fld.vogel_disc(n).astype(np.float64)):
                if uni:  # uniform tiles: the tile centre's landing point for every pixel
                    px, py = xs + tsxx * ts + trxx * tr, ys + tsxy * ts + trxy * tr
                else:
                    # sagittal e_s = (-ey, ex), radial e_r = (ex, ey); gather from x - ε
                    ox = c * (ts * -ey + tr * ex)
                    oy = c * (ts * ex + tr * ey)
                    # the tile's window: centre b = round(tile centre's -ε), the landing point within ±1 px
                    bx = np.floor(tsxx * ts + trxx * tr + 0.5)
                    by = np.floor(tsxy * ts + trxy * tr + 0.5)
                    px = xs + bx + np.clip(-ox - bx, -1.0, 1.0)
                    py = ys + by + np.clip(-oy - by, -1.0, 1.0)
                if uni:  # 1 - a t_r + b (t_r² + t_s²), the tile's mean a, b where tile_jacobian says so
                    jac = np.maximum(1.0 - a_px * tr + b_px * (tr * tr + ts * ts), 0.0)
                else:
                    jac = np.maximum((1.0 - dc * tr) * (1.0 - q * tr) + q * dc * ts * ts, 0.0)
                acc += fld.bilinear_padded(color, px, py) * jac[..., None]
            out[uniform == uni] = (acc / n)[uniform == uni]
        return out


def derivative(fn, r_mm, step_mm: float = 1e-3) -> np.ndarray:
    """dC/dr (dimensionless) by central differences (one-sided at r = 0)."""
    r = np.asarray(r_mm, np.float64)
    lo = np.maximum(r - step_mm, 0.0)
    return (fn(r + step_mm) - fn(lo)) / (r + step_mm - lo)


def comet_geometry_px(camera, r_mm: float, width: int) -> dict:
    """Closed form for a point at image height ``r_mm``: tail length 3C, width 2C and centroid
    shift C in px (for tests and docs)."""
    c = float(coma_curve(camera)(np.array(r_mm))) / fld.pitch_mm(camera, width)
    c = float(np.clip(c, -MAX_TAIL_PX / 3.0, MAX_TAIL_PX / 3.0))
    return {"length": 3 * c, "width": 2 * abs(c), "centroid": c}


__all__ = ["Coma", "coma_curve", "comet_geometry_px", "comet_offsets"]
