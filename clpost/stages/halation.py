r"""halation: the red halo a bright source throws on colour film — light that passed the emulsion,
reflected at the back of the film base and re-exposed the emulsion around the image.

Model (the geometry of Hecht §4.7 and the halation analysis of James, *The Theory of the
Photographic Process*, 4th ed., ch. 20): light scattered in the emulsion leaves it into the base
(thickness d, index n) with a diffuse (Lambertian) angular distribution, reflects at the
base–air interface with the Fresnel reflectance R(θ) (unpolarised; total beyond the critical
angle θ_c = asin(1/n)) and comes back at radius r = 2 d tan θ. Energy per dθ ∝ cos θ sin θ R(θ),
the ring's area 2πr dr with dr = 2d sec²θ dθ, so the returned irradiance is

.. math::

    K(r) \propto R(\theta)\cos^4\theta, \qquad \theta = \arctan\frac{r}{2d},

for θ ≤ :data:`THETA_MAX` (grazing light is absorbed on its long path through the base): a faint
disc that jumps to a bright ring at :math:`r_c = 2d\tan\theta_c` (the classic halation ring,
≈ 0.23 mm for a 127 µm acetate base) and fades outward. K is normalised to 1. The stage is
applied to the exposure, before the characteristic curve (halation is light, not dye):

.. math::

    x'_c = (1 - s_c)\,x_c + s_c\,(K * x_c)

with the per-layer strength :math:`s_c` — the fraction of layer c's exposure that returns
(:data:`STOCKS`). Σ x' = Σ x (energy conserved; K sums to 1, light leaving the frame is lost).
Red dominates because red light reaches the base (the red-sensitive layer is the bottom layer,
blue and green are absorbed above it and by the yellow filter layer).

Implementation: K is large (r_c ≈ 12 px at 1920 px across 36 mm, its tail to 2d tan 75° ≈
50 px), smooth and added to a blurred copy, so it is applied at a working resolution 1/f
(f = :func:`working_factor`, the ring ≈ :data:`RING_WORK_PX` working px: a 2-D gather of the
whole kernel at full resolution would be ~70² taps per pixel at 1280 px across 36 mm): f×f box mean,
direct 2-D gather of the cell-integrated K (zero outside the frame), bilinear upsampling
(edges clamped). Box-down then bilinear-up keeps Σ exactly away from the borders.

Skip rule (planned only when the halo can show): the halo at any pixel is at most
:math:`s_R\,\max x_R` (K sums to 1), so the stage runs when that bound reaches
:data:`VISIBLE` of middle grey's signal (ISO 12232: grey H = 10/S, saturation 78/S → 0.128):
a frame without highlights is not touched.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..params import boolean, param, parse_on_off
from . import _field as fld
from .base import GatherStage

THETA_MAX_DEG = 75.0
"""Largest reflection angle that returns (beyond it the path through the base is > 3.9 d)."""
RING_WORK_PX = 3.0
"""Working-resolution radius of the halation ring (sets the working factor f)."""
VISIBLE = 0.01 * 10.0 / 78.0
"""Halo level that can show: 1 % of middle grey's signal (saturation = 1)."""


@dataclass(frozen=True)
class Stock:
    """Halation data of a film stock: base thickness (µm), base index, strengths (R, G, B) and
    where the numbers come from."""

    base_um: float
    n_base: float
    strength: tuple[float, float, float]
    source: str


# Strengths: the returned fraction s_c = η_c · ρ_diffuse · T_ah², with ρ_diffuse the Lambertian
# hemispherical reflectance of the base–air interface up to THETA_MAX (≈ 0.53 for n = 1.48,
# :func:`diffuse_reflectance`), η_c the fraction of layer c's light reaching the base (red 0.25,
# green 0.04, blue 0: the red layer is at the bottom; Kodak's published layer order) and T_ah the
# single-pass transmittance of an anti-halation layer. Colour negative still films (C-41) carry
# an anti-halation undercoat / grey base (Kodak E-4046, E-7022 "Base: acetate, 127 µm, with
# antihalation undercoat"; Fujifilm's datasheet names the same layer): T_ah² ≈ 0.1 is assumed
# (published halation photographs of these stocks show a faint halo only around light sources
# several stops over), giving s_R ≈ 0.013. These are estimates, not measurements: the values are
# in one place here, to be replaced by measured ones.
STOCKS = {
    "kodak-ektar-100": Stock(127.0, 1.48, (0.013, 0.002, 0.0),
                             "Kodak E-4046 (acetate base with antihalation undercoat); estimate above"),
    "kodak-gold-200": Stock(127.0, 1.48, (0.013, 0.002, 0.0),
                            "Kodak E-7022 (acetate base with antihalation undercoat); estimate above"),
    "fuji-superia-400": Stock(127.0, 1.48, (0.013, 0.002, 0.0),
                              "Fujifilm Superia X-TRA 400 datasheet (antihalation layer); estimate above"),
}
"""Stocks with halation data; any other stock (``neutral-100``, a user .toml) has none."""


@dataclass(frozen=True)
class HalationParams:
    """halation: the film base's red halo around highlights (off by default)."""

    halation: bool = param(False, unit="on/off", flag="--halation", parse=parse_on_off, check=boolean,
                           header="clpost.halation", scalar=False,
                           help="film halation: the red halo of light reflected at the film base, per stock: on/off")


def fresnel_unpolarised(theta: np.ndarray, n: float) -> np.ndarray:
    """Reflectance of the base (index n) → air interface at internal angle θ; 1 beyond θ_c."""
    c = np.cos(theta)
    s_t = n * np.sin(theta)
    tir = s_t >= 1.0
    ct = np.sqrt(np.clip(1.0 - s_t * s_t, 0.0, 1.0))
    rs = ((n * c - ct) / (n * c + ct)) ** 2
    rp = ((c - n * ct) / (c + n * ct)) ** 2
    return np.where(tir, 1.0, 0.5 * (rs + rp))


def diffuse_reflectance(n: float) -> float:
    """Lambertian-weighted reflectance ∫ R 2 sinθ cosθ dθ over [0, THETA_MAX]."""
    th = (np.arange(20000) + 0.5) / 20000 * math.radians(THETA_MAX_DEG)
    return float(np.sum(fresnel_unpolarised(th, n) * 2 * np.sin(th) * np.cos(th)) * (th[1] - th[0]))


def radial_kernel(r_mm: np.ndarray, base_um: float, n: float) -> np.ndarray:
    """Unnormalised K(r) (module docstring), 0 beyond 2 d tan THETA_MAX."""
    d = base_um * 1e-3
    th = np.arctan(np.asarray(r_mm, np.float64) / (2 * d))
    return np.where(th <= math.radians(THETA_MAX_DEG), fresnel_unpolarised(th, n) * np.cos(th) ** 4, 0.0)


def working_factor(stock: Stock, pitch_mm: float) -> int:
    """f: the ring r_c = 2 d tan θ_c at about RING_WORK_PX working px (1 at low resolutions)."""
    r_c = 2 * stock.base_um * 1e-3 * math.tan(math.asin(1.0 / stock.n_base))
    return max(1, int(round(r_c / pitch_mm / RING_WORK_PX)))


@lru_cache(maxsize=16)
def kernel_taps(stock: Stock, cell_mm: float) -> np.ndarray:
    """(2R+1)² weights of K on the working grid (cell size ``cell_mm``), each cell's mean over
    8×8 sub-samples, summing to 1."""
    r_max = 2 * stock.base_um * 1e-3 * math.tan(math.radians(THETA_MAX_DEG))
    rad = int(math.ceil(r_max / cell_mm))
    sub = (np.arange(8) + 0.5) / 8 - 0.5
    o = np.arange(-rad, rad + 1)
    x = (o[:, None] + sub[None, :]).ravel() * cell_mm
    xx, yy = np.meshgrid(x, x)
    k = radial_kernel(np.hypot(xx, yy), stock.base_um, stock.n_base)
    k = k.reshape(2 * rad + 1, 8, 2 * rad + 1, 8).mean(axis=(1, 3))
    total = k.sum()
    if not total > 0.0:  # K lies inside the centre cell, between its sub-samples (cells of mm: 1-3 px frames)
        k = np.zeros_like(k)
        k[rad, rad] = total = 1.0
    return k / total


def _down(x: np.ndarray, f: int) -> np.ndarray:
    """f×f box mean (partial cells at the right/bottom: the mean of the pixels they hold)."""
    h, w = x.shape
    hw, ww = -(-h // f), -(-w // f)
    s = np.zeros((hw, ww)); n = np.zeros((hw, ww))
    ys, xs = np.arange(h) // f, np.arange(w) // f
    np.add.at(s, (ys[:, None], xs[None, :]), x)
    np.add.at(n, (ys[:, None], xs[None, :]), 1.0)
    return s / n


def _conv(x: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Direct 2-D gather Σ k[dy, dx] x[y + dy, x + dx], zero outside (k is symmetric)."""
    rad = k.shape[0] // 2
    h, w = x.shape
    p = np.pad(x, rad)
    out = np.zeros_like(x)
    for dy in range(-rad, rad + 1):
        for dx in range(-rad, rad + 1):
            kv = k[dy + rad, dx + rad]
            if kv != 0.0:
                out += kv * p[rad + dy:rad + dy + h, rad + dx:rad + dx + w]
    return out


def _up(x: np.ndarray, f: int, h: int, w: int) -> np.ndarray:
    """Bilinear upsampling of a 1/f image to h×w (pixel centres aligned, edges clamped)."""
    return sum(wt * x[ys][:, xs] for ys, xs, wt in fld.upsample_corners(h, w, *x.shape, f))


def halation_reference(color: np.ndarray, stock: Stock, pitch_mm: float) -> np.ndarray:
    """float64 oracle: x' = (1 − s) x + s · up(K * down(x)) per channel."""
    x = np.asarray(color, np.float64)
    h, w = x.shape[:2]
    f = working_factor(stock, pitch_mm)
    k = kernel_taps(stock, f * pitch_mm)
    out = x.copy()
    for c, s in enumerate(stock.strength):
        if s > 0:
            out[..., c] = (1 - s) * x[..., c] + s * _up(_conv(_down(x[..., c], f), k), f, h, w)
    return out


class Halation(GatherStage):
    name = "halation"
    order = 75.0
    role = "light reflected at the film base re-exposes the emulsion: on the exposure, before the curves"
    domains = ("signal", "signal")
    requires = ("exposure",)
    params = HalationParams
    example = {"halation": True, "film": "kodak-gold-200"}
    turn_off = "turn halation off with --halation off"

    def _stock(self, camera):
        return STOCKS.get(camera.film) if camera.film else None

    def _peak(self, camera, frame) -> float:
        """Largest red signal of the frame (exposure gain × the input's red maximum; vignetting
        only lowers it, so this bounds the halo)."""
        from ..photometry import exposure_gain

        c = frame.color
        cached = frame.__dict__.get("_halation_peak")
        if cached is None or cached[0] is not c:
            cached = (c, float(np.max(c[..., 0])) if c.size else 0.0)
            object.__setattr__(frame, "_halation_peak", cached)
        return cached[1] * exposure_gain(camera)

    def skip_reason(self, camera, frame):
        if not camera.halation:
            return "Camera.halation is off"
        if not camera.film:
            return "no film stock (halation is a film effect; Camera.film is None)"
        stock = self._stock(camera)
        if stock is None:
            return f"film stock {camera.film} has no halation data (clpost/stages/halation.py STOCKS)"
        bound = stock.strength[0] * self._peak(camera, frame)
        if bound < VISIBLE:
            return (f"no highlight bright enough: halo ≤ s_R × peak red signal = {bound:.3g} < {VISIBLE:.3g} "
                    f"(1 % of middle grey)")
        return None

    def reason_needed(self, camera, frame):
        s = self._stock(camera)
        pitch = camera.pixel_pitch_mm(fld.image_width_px(frame))
        f = working_factor(s, pitch)
        rad = kernel_taps(s, f * pitch).shape[0] // 2
        return (f"{camera.film}: halo bound s_R × peak red signal = {s.strength[0] * self._peak(camera, frame):.3g} "
                f"≥ {VISIBLE:.3g} (1 % of middle grey); strengths R/G/B {s.strength}, 1/{f} resolution, {2 * rad + 1}² taps")

    def reference(self, camera, frame, color):
        return halation_reference(color, self._stock(camera), camera.pixel_pitch_mm(fld.image_width_px(frame)))

    def enqueue(self, rt, camera, frame, src, dst, aux):
        from ..codegen import library
        from ..runtime import kernel_source

        stock = self._stock(camera)
        w, h = frame.width, frame.height
        pitch = camera.pixel_pitch_mm(fld.image_width_px(frame))
        f = working_factor(stock, pitch)
        k = kernel_taps(stock, f * pitch)
        rad = k.shape[0] // 2
        ww, hw = -(-w // f), -(-h // f)
        knl = rt.kernels(library() + kernel_source("halation"), "halation", {"HAL_F": f, "HAL_R": rad})
        down = rt.scratch(self, "down", (3, hw, ww))
        conv = rt.scratch(self, "conv", (3, hw, ww))
        taps = rt.constant(k.astype(np.float32))
        s = np.array(stock.strength, np.float32)
        i32 = np.int32
        return [rt.launch(knl["halation_down"], (ww, hw), None, src, down, i32(w), i32(h), i32(ww), i32(hw)),
                rt.launch(knl["halation_conv"], (ww, hw), None, down, conv, taps, i32(ww), i32(hw)),
                rt.launch(knl["halation"], (w, h), None, src, conv, dst, i32(w), i32(h), i32(ww), i32(hw),
                          s[0], s[1], s[2])]
