r"""lateral_color: chromatic difference of magnification — each channel resampled radially.

**Channel wavelengths.** The R, G, B channels of the working space (linear Rec.709 primaries,
D65; CONVENTIONS) are represented by the dominant wavelengths of the primaries seen from the
white point (colour-science ``colour.dominant_wavelength``): 611, 549 and 464 nm. One wavelength
per channel is a model: a real channel integrates a band, so fringes are a little softer.

**Chief-ray height per wavelength.** The lens gives :math:`L(r) = h_F - h_C`, the chief-ray height
at F (486.1 nm) minus at C (656.3 nm) at d-line image height r (``lens_curves()
.at("lateral_color_mm", r)``), or parametrically ``Camera.lateral_color_mm`` = L at the image
corner :math:`r_c`, linear in r (a paraxial difference of magnification). Between and beyond F and
C the shift follows the glass's relative partial dispersion, taken from Cauchy's
:math:`n(\lambda) = a + b/\lambda^2`:

.. math::

    h_\lambda(r) = r + P(\lambda)\,L(r), \qquad
    P(\lambda) = \frac{\lambda^{-2} - \lambda_d^{-2}}{\lambda_F^{-2} - \lambda_C^{-2}}

(:math:`P(\lambda_F) - P(\lambda_C) = 1`; P_F,d = 0.699, as for normal crown glasses, 0.69–0.70;
Schott, "TIE-29 Refractive Index and Dispersion"). The d line is the geometry of the render
(what distortion uses), so every channel moves relative to it: R by −0.114 L, G by +0.221 L,
B by +0.915 L.

**Resampling.** The output of channel c at image height ρ is the input at r with
:math:`r + P_c L(r) = \rho` (four fixed-point steps from r = ρ; :math:`|P L'| \ll 1`), along the
same radius, scaled by the Jacobian of the radial map so the channel's flux is conserved:

.. math::

    C'_c(\rho\,\hat e) = C_c(r\,\hat e)\;\frac{r}{\rho}\,\frac{\mathrm{d}r}{\mathrm{d}\rho}

Bilinear interpolation with the image's edge values continued beyond it.

**Tiles (speed).** Per 16 × 8 tile (:mod:`clpost.stages._field`) and channel, the host evaluates
the exact map (float64) at three corners of the tile and takes the source displacement
:math:`d(x) = x_{src}(x) - x` and the Jacobian as affine in the pixel's position within the
tile, :math:`d = d_{00} + (d_{10} - d_{00})\,l_x/(W_t-1) + (d_{01} - d_{00})\,l_y/(H_t-1)`. Where

* that plane misses the exact map at the fourth corner and at the centre by at most
  ``AFFINE_TOL_PX`` (10⁻³ px; Jacobian: ``AFFINE_TOL_JAC``, 10⁻⁴) — a radial scale is affine wherever
  r/ρ is constant, so this holds everywhere for a linear L and almost everywhere for a traced one;
* the displacement over the tile stays within one bilinear cell :math:`[b, b + 1]` (b an integer
  per axis and tile), and that cell stays inside the frame,

the tile's pixels read the four samples at the *same* offset b with per-pixel fractions
:math:`d - b` (affine in the work-item id: the kernel vectorises across pixels). The other tiles
(the frame's border, partial tiles, the row and column of tiles where a displacement changes sign
or crosses an integer, strong lateral colour) take the per-pixel map, sampled into a LUT of
(r/ρ, Jacobian) per channel over image height and interpolated linearly. The reference
implements both paths and the same tile plan (``tile_plan``); ``model_error_px`` measures the
tile model against the exact map at every pixel.

Domain/range: colour ≥ 0 → ≥ 0; for an identity L = 0 the stage is not planned.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..optics.prescription import LAMBDA_C_NM, LAMBDA_D_NM, LAMBDA_F_NM
from ..params import CORNER_MM, param, parse_fraction
from . import _field as fld
from .base import GatherStage, per_camera


@dataclass(frozen=True)
class LateralColorParams:
    """Parametric lateral colour at the image corner (None: the traced lens's, or none for a thin lens)."""

    lateral_color_mm: float | None = param(
        None, unit="mm", flag="--lateral-color", parse=parse_fraction, check=CORNER_MM,
        header="clpost.lateral_color_mm", scalar=False,
        help="chief-ray height at F (486.1 nm) minus at C (656.3 nm) at the image corner in mm")


FIXED_POINT_STEPS = 4
DERIVATIVE_STEP_MM = 1e-3
AFFINE_TOL_PX = 1e-3
AFFINE_TOL_JAC = 1e-4
REC = 32
"""Floats per fast tile's record: the tile origin, then per channel the cell offset and the
affine fx, fy and Jacobian (1 + 3 × 10), padded to 32."""


@lru_cache(maxsize=1)
def channel_wavelengths_nm() -> tuple[float, float, float]:
    """Dominant wavelengths (nm) of the Rec.709 R, G, B primaries seen from D65 (colour-science)."""
    import colour

    cs = colour.RGB_COLOURSPACES["ITU-R BT.709"]
    return tuple(float(colour.dominant_wavelength(p, cs.whitepoint)[0]) for p in cs.primaries)


def partial_dispersion(wavelength_nm) -> np.ndarray:
    """P(λ) of the module docstring (Cauchy): 0 at d, P(F) − P(C) = 1."""
    lam = np.asarray(wavelength_nm, np.float64)
    return (lam ** -2 - LAMBDA_D_NM ** -2) / (LAMBDA_F_NM ** -2 - LAMBDA_C_NM ** -2)


def f_minus_c(camera):
    """``fn(r_mm) -> L`` (mm): chief-ray height F − C, or None (no source)."""
    if camera.lateral_color_mm is not None:
        k = camera.lateral_color_mm / fld.corner_mm(camera)
        return lambda r: k * np.asarray(r, np.float64)
    curves = camera.lens_curves()
    if curves is None:
        return None
    return lambda r: curves.at("lateral_color_mm", r)


def channel_shifts(camera):
    """``fn(r_mm) -> (3, ...)`` radial shift Δ_c = P_c L(r) of the R, G, B images (mm)."""
    fn = f_minus_c(camera)
    p = partial_dispersion(channel_wavelengths_nm())
    return lambda r: p.reshape((3,) + (1,) * np.ndim(r)) * fn(r)[None]


def inverse_map(camera, rho_mm) -> tuple[np.ndarray, np.ndarray]:
    """(r/ρ, Jacobian) per channel, shape (3, ...) float64, at output image heights ρ (mm)."""
    shift = channel_shifts(camera)
    rho = np.asarray(rho_mm, np.float64)
    r = np.broadcast_to(rho, (3,) + rho.shape).copy()
    idx = np.arange(3)
    for _ in range(FIXED_POINT_STEPS):
        s = shift(r)  # (3, 3, ...): every channel's shift at every channel's r
        r = rho[None] - s[idx, idx]
    d = DERIVATIVE_STEP_MM
    sp, sm = shift(r + d)[idx, idx], shift(np.maximum(r - d, 0.0))[idx, idx]
    deriv = (sp - sm) / (r + d - np.maximum(r - d, 0.0))
    dr_drho = 1.0 / (1.0 + deriv)
    safe = np.where(rho > 0, rho, 1.0)
    ratio = np.where(rho > 0, r / safe, dr_drho)  # r/ρ → dr/dρ at the centre
    return ratio, ratio * dr_drho


class LateralColor(GatherStage):
    name = "lateral_color"
    order = 30.0
    role = "per-channel radial magnification"
    domains = ("render", "render")
    params = LateralColorParams

    def __init__(self, quality: str = "final") -> None:
        super().__init__(quality)
        self._scratch: dict = {}
        self._plan_key = None
        self._plan: dict = {}

    @per_camera
    def _lut(self, camera) -> np.ndarray:
        r = np.linspace(0.0, fld.lut_range_mm(camera), fld.LUT_SIZE)
        ratio, jac = inverse_map(camera, r)
        return np.ascontiguousarray(np.concatenate([ratio, jac]), np.float32)

    def skip_reason(self, camera, frame):
        fn = f_minus_c(camera)
        if fn is None:
            return "thin lens without Camera.lateral_color_mm"
        if not np.any(fn(np.linspace(0.0, fld.lut_range_mm(camera), fld.LUT_SIZE))):
            return "lateral colour (F − C chief-ray height) is zero over the sensor"
        return None

    def reason_needed(self, camera, frame):
        r = np.linspace(0.0, fld.corner_mm(camera), 256)
        d = channel_shifts(camera)(r)
        i = int(np.argmax(np.abs(d[0] - d[2])))
        p = fld.pitch_mm(camera, fld.image_width_px(frame))
        return (f"largest R−B at {r[i]:.3g} mm: {(d[0, i] - d[2, i]) * 1000:+.3g} µm ({(d[0, i] - d[2, i]) / p:+.2g} px); "
                f"channels at {', '.join(f'{w:g}' for w in channel_wavelengths_nm())} nm")

    def defines(self, camera):
        return {"LATERAL_COLOR_LUT_SIZE": fld.LUT_SIZE, "LATERAL_COLOR_TILE_W": fld.TILE_W,
                "LATERAL_COLOR_TILE_H": fld.TILE_H, "LATERAL_COLOR_REC": REC}

    def _kernel(self, rt, camera, name):
        from ..runtime import kernel_source

        return rt.kernel(kernel_source("lateral_color"), name, self.defines(camera), "lateral_color")

    # -- the tile plan (host, float64) -----------------------------------------------------
    def tile_plan(self, camera, w: int, h: int, k=None) -> dict:
        """Per tile (tiles_y, tiles_x): ``fast`` (bool) and, per channel (3, tiles_y, tiles_x),
        the cell offset ``b`` (x, y; int), the affine fractions ``f`` (x, y) × (a0, ax, ay) and
        Jacobian ``jac`` (a0, ax, ay) of the module docstring (memoised per camera map and size)."""
        lut = self._lut(camera)
        pitch = fld.pitch_mm(camera, w, k)
        key = (lut.tobytes(), w, h, pitch, fld.principal_point_px(camera, w, h, k))
        if self._plan_key != key:
            self._plan_key, self._plan = key, self._tile_plan(camera, w, h, k)
        return self._plan

    def _tile_plan(self, camera, w, h, k=None) -> dict:
        tw, th = fld.TILE_W, fld.TILE_H
        ntx, nty = fld.tiles(w, h)
        cx, cy = fld.principal_point_px(camera, w, h, k)
        pitch = fld.pitch_mm(camera, w, k)
        ty, tx = np.mgrid[0:nty, 0:ntx].astype(np.float64)
        x0, y0 = tx * tw, ty * th

        def at(lx, ly):  # displacement (x, y) and Jacobian per channel at a pixel of every tile
            dx, dy = x0 + lx - cx, y0 + ly - cy
            ratio, jac = inverse_map(camera, np.hypot(dx, dy) * pitch)
            return np.stack([dx * (ratio - 1.0), dy * (ratio - 1.0), jac])  # (3 quantities, 3 ch, ...)

        v00, v10, v01 = at(0.0, 0.0), at(tw - 1.0, 0.0), at(0.0, th - 1.0)
        ax, ay = (v10 - v00) / (tw - 1.0), (v01 - v00) / (th - 1.0)
        plane = lambda lx, ly: v00 + ax * lx + ay * ly  # noqa: E731
        err = np.maximum(np.abs(plane(tw - 1.0, th - 1.0) - at(tw - 1.0, th - 1.0)),
                         np.abs(plane(0.5 * (tw - 1), 0.5 * (th - 1)) - at(0.5 * (tw - 1), 0.5 * (th - 1))))
        corners = np.stack([v00, v10, v01, plane(tw - 1.0, th - 1.0)])[:, :2]  # (4, 2 axes, 3, ...)
        b = np.floor(corners.min(0))
        one_cell = corners.max(0) - b <= 1.0
        inside = ((x0 + b[0] >= 0) & (x0 + tw + b[0] <= w - 1) & (y0 + b[1] >= 0) & (y0 + th + b[1] <= h - 1))
        fast = (np.all(one_cell, axis=(0, 1)) & np.all(inside, axis=0) & (x0 + tw <= w) & (y0 + th <= h)
                & np.all(err[:2] <= AFFINE_TOL_PX, axis=(0, 1)) & np.all(err[2] <= AFFINE_TOL_JAC, axis=0))
        f = np.stack([v00[:2] - b, ax[:2], ay[:2]], -1)  # (2 axes, 3 ch, ty, tx, 3 coeffs)
        jac = np.stack([v00[2], ax[2], ay[2]], -1)
        return dict(fast=fast, b=np.moveaxis(b, 0, 1).astype(np.int64), f=np.moveaxis(f, 0, 1), jac=jac)

    def records(self, plan: dict, w: int) -> tuple[np.ndarray, np.ndarray]:
        """(fast tiles' records (n, REC) float32, the other tiles' indices int32), row-major."""
        fast = plan["fast"]
        ty, tx = np.nonzero(fast)
        rec = np.zeros((ty.size, REC), np.float32)
        iv = rec.view(np.int32)
        iv[:, 0] = ty * fld.TILE_H * w + tx * fld.TILE_W
        for c in range(3):
            o = 1 + 10 * c
            bx, by = plan["b"][c, 0][ty, tx], plan["b"][c, 1][ty, tx]
            iv[:, o] = by * w + bx
            rec[:, o + 1:o + 4] = plan["f"][c, 0][ty, tx]
            rec[:, o + 4:o + 7] = plan["f"][c, 1][ty, tx]
            rec[:, o + 7:o + 10] = plan["jac"][c][ty, tx]
        return rec, np.flatnonzero(~fast.ravel()).astype(np.int32)

    def enqueue(self, rt, camera, frame, src, dst, aux):
        w, h = frame.width, frame.height
        g = fld.frame_geometry(camera, frame)
        cx, cy = fld.principal_point_px(camera, w, h, g)
        plan = self.tile_plan(camera, w, h, g)
        key = (id(rt.context), w, h, self._plan_key)
        if key not in self._scratch:
            # the records depend only on the camera's map and the frame size: uploaded once
            rec, rest = self.records(plan, w)
            mk = rt.constant
            self._scratch = {key: dict(rec=mk(rec), rest=mk(rest), n_fast=len(rec), n_rest=len(rest),
                                       lut=mk(self._lut(camera)))}
        b = self._scratch[key]
        events = []
        tile = (fld.TILE_W, fld.TILE_H)
        if b["n_fast"]:
            k = self._kernel(rt, camera, "lateral_color_tiles")
            events.append(rt.launch(k, (fld.TILE_W * b["n_fast"], fld.TILE_H), tile,
                                    src, dst, b["rec"], np.int32(w), np.int32(h)))
        if b["n_rest"]:
            k = self._kernel(rt, camera, "lateral_color")
            events.append(rt.launch(k, (fld.TILE_W * b["n_rest"], fld.TILE_H), tile,
                                    src, dst, b["lut"], b["rest"], np.int32(w), np.int32(h), np.float32(cx),
                                    np.float32(cy), np.float32(fld.pitch_mm(camera, w, g) * (fld.LUT_SIZE - 1)
                                                               / fld.lut_range_mm(camera))))
        return events

    # -- the oracle -------------------------------------------------------------------------
    def exact_positions(self, camera, w: int, h: int, k=None):
        """Per pixel and channel (3, h, w) float64: source x, y of the exact map, and its Jacobian."""
        cx, cy = fld.principal_point_px(camera, w, h, k)
        xs, ys, r, _, _ = fld.radial_frame(w, h, cx, cy)
        ratio, jac = inverse_map(camera, r * fld.pitch_mm(camera, w, k))
        return cx + (xs - cx) * ratio, cy + (ys - cy) * ratio, jac

    def model_positions(self, camera, w: int, h: int, k=None):
        """As ``exact_positions``, with the tile model on the fast tiles (what the kernels do)."""
        sx, sy, jac = self.exact_positions(camera, w, h, k)
        plan = self.tile_plan(camera, w, h, k)
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
        lx, ly = xs % fld.TILE_W, ys % fld.TILE_H
        fast = fld.per_pixel(plan["fast"], w, h)
        for c in range(3):
            bx, by = (fld.per_pixel(plan["b"][c, a], w, h) for a in range(2))
            fx, fy = (fld.per_pixel(plan["f"][c, a], w, h) for a in range(2))
            jc = fld.per_pixel(plan["jac"][c], w, h)
            sx[c] = np.where(fast, xs + bx + fx[..., 0] + fx[..., 1] * lx + fx[..., 2] * ly, sx[c])
            sy[c] = np.where(fast, ys + by + fy[..., 0] + fy[..., 1] * lx + fy[..., 2] * ly, sy[c])
            jac[c] = np.where(fast, jc[..., 0] + jc[..., 1] * lx + jc[..., 2] * ly, jac[c])
        return sx, sy, jac

    def model_error_px(self, camera, w: int, h: int, k=None) -> tuple[float, float, tuple[int, int, int]]:
        """Largest |tile model − exact map| over all pixels and channels: source position (px),
        Jacobian, and the (x, y, channel) of the largest position error."""
        ex, ey, ej = self.exact_positions(camera, w, h, k)
        mx, my, mj = self.model_positions(camera, w, h, k)
        d = np.hypot(mx - ex, my - ey)
        c, y, x = np.unravel_index(int(np.argmax(d)), d.shape)
        return float(d.max()), float(np.abs(mj - ej).max()), (int(x), int(y), int(c))

    def reference(self, camera, frame, color):
        """float64 numpy implementation of the module docstring (the tile model on the fast tiles,
        the exact map, no LUT, elsewhere)."""
        color = np.asarray(color, np.float64)
        h, w = color.shape[:2]
        k = fld.frame_geometry(camera, frame)
        sx, sy, jac = self.model_positions(camera, w, h, k)
        out = np.empty_like(color)
        for c in range(3):
            out[..., c] = fld.bilinear_padded(color[..., c:c + 1], sx[c], sy[c])[..., 0] * jac[c]
        return out


def fringe_px(camera, r_mm: float, width: int) -> np.ndarray:
    """Closed form: radial shift (px, + outward) of the R, G, B images of a point at image height
    ``r_mm`` relative to the d-line render (for tests and docs)."""
    return channel_shifts(camera)(np.array(r_mm)) / fld.pitch_mm(camera, width)
