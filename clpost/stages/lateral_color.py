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

Bilinear interpolation with the image's edge values continued beyond it. The map is sampled into
a LUT of (r/ρ, Jacobian) per channel over image height, interpolated linearly in the kernel.

Domain/range: colour ≥ 0 → ≥ 0; for an identity L = 0 the stage is not planned.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..optics.prescription import LAMBDA_C_NM, LAMBDA_D_NM, LAMBDA_F_NM
from . import _field as fld
from .base import GatherStage

FIXED_POINT_STEPS = 4
DERIVATIVE_STEP_MM = 1e-3


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

    def __init__(self, quality: str = "final") -> None:
        super().__init__(quality)
        self._kernels: dict = {}
        self._scratch: dict = {}

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
        p = fld.pitch_mm(camera, frame.width)
        return (f"largest R−B at {r[i]:.3g} mm: {(d[0, i] - d[2, i]) * 1000:+.3g} µm ({(d[0, i] - d[2, i]) / p:+.2g} px); "
                f"channels at {', '.join(f'{w:g}' for w in channel_wavelengths_nm())} nm")

    def defines(self, camera):
        return {"LATERAL_COLOR_LUT_SIZE": fld.LUT_SIZE}

    def _kernel(self, rt, camera):
        import pyopencl as cl

        from ..runtime import kernel_source

        prog = rt.program(kernel_source("lateral_color"), "lateral_color", self.defines(camera))
        if id(prog) not in self._kernels:
            self._kernels[id(prog)] = cl.Kernel(prog, "lateral_color")
        return self._kernels[id(prog)]

    def enqueue(self, rt, camera, frame, src, dst, aux):
        import pyopencl as cl

        q = rt.queue
        w, h = frame.width, frame.height
        key = id(rt.context)
        if key not in self._scratch:
            self._scratch = {key: rt.empty((6, fld.LUT_SIZE))}
        lut = self._scratch[key]
        cx, cy = fld.principal_point_px(camera, w, h)
        events = [cl.enqueue_copy(q, lut, self._lut(camera), is_blocking=False)]
        k = self._kernel(rt, camera)
        k.set_args(src, dst, lut, np.int32(w), np.int32(h), np.float32(cx), np.float32(cy),
                   np.float32(fld.pitch_mm(camera, w) * (fld.LUT_SIZE - 1) / fld.lut_range_mm(camera)))
        events.append(cl.enqueue_nd_range_kernel(q, k, (w, h), None))
        return events

    def reference(self, camera, frame, color):
        """float64 numpy implementation of the module docstring (exact map, no LUT)."""
        color = np.asarray(color, np.float64)
        h, w = color.shape[:2]
        cx, cy = fld.principal_point_px(camera, w, h)
        xs, ys, r, _, _ = fld.radial_frame(w, h, cx, cy)
        ratio, jac = inverse_map(camera, r * fld.pitch_mm(camera, w))
        out = np.empty_like(color)
        for c in range(3):
            sx = cx + (xs - cx) * ratio[c]
            sy = cy + (ys - cy) * ratio[c]
            out[..., c] = fld.bilinear_padded(color[..., c:c + 1], sx, sy)[..., 0] * jac[c]
        return out


def fringe_px(camera, r_mm: float, width: int) -> np.ndarray:
    """Closed form: radial shift (px, + outward) of the R, G, B images of a point at image height
    ``r_mm`` relative to the d-line render (for tests and docs)."""
    return channel_shifts(camera)(np.array(r_mm)) / fld.pitch_mm(camera, width)
