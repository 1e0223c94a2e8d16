r"""grain: the developed negative's grain, per dye layer, on the film stage's densities.

Model (:mod:`clpost.grain_model`): each dye layer is a Boolean model of discs of radius r (the
stock's effective grain radius × ``Camera.grain_size``, in µm on the film → pixels through
``Camera.pixel_pitch_mm``) with Poisson intensity :math:`λ = D_{img}\ln 10/(\pi r^2)`, where
:math:`D_{img} = D - D_{min}` is the image density above base. A pixel records the clear fraction
:math:`T'` of its area; :math:`D' = D_{min} - \log_{10} T'`, clamped to [D_min, D_max].
:math:`E[T'] = 10^{-D_{img}}` exactly; granularity grows with density and with speed, and
σ_D·√(pixel area) is constant (Selwyn) — so the same film at 2× resolution has the same grain
in millimetres.

Two implementations, matched in mean, variance and lag-1 autocorrelation (tested):

- ``final`` with resolved grains (r ≥ 1/8 px): Newson et al.'s Boolean model rendered in
  OpenCL. The pixel is split into GRAIN_CELLS² cells (cell ≥ r); each cell holds
  Poisson(λ/K²) grains placed by a hash of (seed, frame, cell, layer) — so a grain straddling two
  pixels is the same grain for both — with λ from the density of the pixel the cell lies in;
  T' is the clear fraction of GRAIN_NS² jittered-stratified samples. Cost grows with
  (cells per pixel)·(grains per cell)·samples: about 64·(K+2)²·λ/K² disc tests per layer.
- otherwise (``draft``/``preview``, or grains smaller than 1/8 px where the samples could not
  resolve them and the central limit theorem makes the pixel average Gaussian): a Gaussian clear
  fraction, :math:`T' = T + σ_T(D_{img})\,G`, with σ_T from the model's exact pixel-box variance
  (in closed form, :func:`gaussian_tables`; where final renders the Boolean model, the variance
  of its 64-sample estimator, so draft matches final) and G a unit-variance field correlated by
  the separable kernel [a, b, a] so its lag-1 correlation equals the model's. Where that
  correlation is below :data:`RHO_WHITE` the noise is white (a = 0) and the stage is per pixel:
  the plan runs it as :class:`GrainWhite`, fused with film and print into one pass over the frame
  (:meth:`Grain.planned_form`); the correlated path and the Boolean model are this gather.

Strength: ``Camera.grain_amount`` a scales the clear fraction's deviation from its mean,
:math:`T'' = T + a\,(T' - T)`, :math:`T = 10^{-D_{img}}` — σ_T grows a-fold, the mean, the grain
size and the correlation stay; a = 1 is the physical model, 0 no grain. Size and amount are
separate controls: in the physical model a larger grain is also stronger (σ_D ∝ r at a fixed pixel,
Selwyn), so ``grain_size`` alone moves both; ``grain_amount`` moves only the strength.

Randomness: counter-based hash of (``Camera.noise_seed``, ``metadata["frame_index"]``, …).
Reference: A. Newson, J. Delon, B. Galerne, "A Stochastic Film Grain Model for
Resolution-Independent Rendering", Computer Graphics Forum 36(8), 2017; Selwyn (1935).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .. import random as rnd
from ..film_stock import load_stock
from ..grain_model import LN10, grain_radius_um, pixel_covariance
from ..params import at_least, param, positive
from . import _field as fld
from .base import GatherStage, PointwiseStage, per_camera
from .sensor import frame_index


@dataclass(frozen=True)
class GrainParams:
    """grain: the grain's size (× the stock's physical grain radius) and amount (× its strength)."""

    grain_size: float = param(1.0, unit="× the stock's grain radius", flag="--grain-size", parse=float,
                              check=positive("× the stock's grain radius", "e.g. 1 (the stock's own), 2 for "
                                             "clumps twice as large"),
                              header="clpost.grainSize", scalar=False,
                              help="grain/clump radius relative to the stock's physical grain (1 = the "
                                   "stock's; larger grains are also stronger, as on film)")
    grain_amount: float = param(1.0, unit="× the model's strength", flag="--grain-amount", parse=float,
                                check=at_least(0.0, "× the model's strength", "e.g. 1, or 0 for no grain",
                                               "0 turns grain off"),
                                header="clpost.grainAmount", scalar=True,
                                help="grain strength relative to the physical model (1 = physical, 0 = no "
                                     "grain; the size stays)")


GRAIN_NS = 8
"""Samples per pixel side of the final Boolean model (64 samples)."""
RESOLVED_MIN_PX = 1.0 / 8.0
"""Grain radius (px) from which final renders the Boolean model (cells ≥ r, ≤ 8 per pixel side)."""
RHO_WHITE = 0.02
"""Lag-1 correlation below which the Gaussian path's noise is white (filter [0, 1, 0])."""
T_FLOOR_MARGIN = 0.0


def grain_radius_px(camera, width: int) -> float:
    stock = load_stock(camera.film)
    r_um = grain_radius_um(stock.iso) * camera.grain_size
    return r_um / 1000.0 / camera.pixel_pitch_mm(width)


def use_boolean(quality: str, r_px: float) -> bool:
    return quality == "final" and r_px >= RESOLVED_MIN_PX


SIGMA_POLY_DEG = 8
"""Degree of the polynomial σ_T is evaluated with (:func:`gaussian_tables`)."""


@lru_cache(maxsize=64)
def gaussian_tables(r_px: float, d_span: float, samples_side: int | None):
    r"""(σ_T polynomial, kernel weights (a, b)) for the Gaussian path.

    σ_T in closed form: the model's pixel variance is :math:`T^2 F(D)` with
    :math:`F(D) = \sum_i w_i\,\mathrm{expm1}(D\ln 10\,g_i)` (:mod:`clpost.grain_model`: the
    covariance integrated against the pixel box), an entire function with F(0) = 0 and F > 0
    beyond, so

    .. math:: σ_T(D) = T\sqrt{t + 1}\;R(t),\qquad t = 2\min(D, D_{span})/D_{span} - 1,

    R the degree-:data:`SIGMA_POLY_DEG` Chebyshev interpolant of :math:`\sqrt{F(D)/(t + 1)}` at
    65 Chebyshev–Lobatto nodes over [0, D_span], returned in the power basis of t (constant term
    first; the kernel evaluates it as a polynomial in t² of pairs of terms, and √(t + 1) beside
    it). Above D_span (input beyond D_max) σ_T/T is held. Error against the exact variance:
    |σ_fit/σ − 1| < 1e-7 for r from 0.005 to 4 px on every stock (tests/test_grain.py checks
    1e-6; the forms this replaced and their errors: docs/benchmarks.md)."""
    nodes = 0.5 * d_span * (1.0 - np.cos(np.linspace(0.0, math.pi, 65)))
    nodes[0] = 1e-9 * d_span  # F(D)/D at D → 0 (F(0) = 0 itself)
    var = pixel_covariance(nodes, r_px, samples_side=samples_side)
    t = 2.0 * nodes / d_span - 1.0
    q = np.sqrt(var * 10.0 ** (2.0 * nodes) / (t + 1.0))
    poly = np.polynomial.chebyshev.cheb2poly(np.polynomial.chebyshev.chebfit(t, q, SIGMA_POLY_DEG))
    # lag-1 correlation at a mid density (the model's ρ₁ varies little with D): solve
    # 2ab/(2a²+b²) = ρ for the kernel [a, b, a], then normalise 2a² + b² = 1.
    dm = np.array([min(1.0, d_span / 2)])
    rho = float(pixel_covariance(dm, r_px, lag=(1, 0), samples_side=samples_side)[0]
                / pixel_covariance(dm, r_px, samples_side=samples_side)[0])
    rho = min(max(rho, 0.0), 0.7)
    # a/b = t: 2t/(2t²+1) = ρ → ρ·2t² − 2t + ρ = 0 → t = (1 − sqrt(1 − 2ρ²)) / (2ρ)
    # ρ below 0.02 is invisible: treat it as white (a = 0, b = 1: the filter passes one normal).
    tt = 0.0 if rho < RHO_WHITE else (1 - math.sqrt(1 - 2 * rho * rho)) / (2 * rho)
    b = 1.0 / math.sqrt(2 * tt * tt + 1)
    return poly, (tt * b, b)


def sigma_t(poly: np.ndarray, d_span: float, d_img) -> np.ndarray:
    """σ_T of image density ``d_img`` from :func:`gaussian_tables`' polynomial, float64 (the
    kernel's ``grain_pixel`` formula)."""
    d = np.asarray(d_img, np.float64)
    t = np.minimum(d * (2.0 / d_span), 2.0) - 1.0
    return 10.0 ** -d * np.sqrt(t + 1.0) * np.polynomial.polynomial.polyval(t, poly)


def _stats_samples(r_px: float) -> int | None:
    """Whose statistics the Gaussian reproduces: where final renders the Boolean model with
    GRAIN_NS² samples, that estimator's (so draft matches final); else the continuous pixel box."""
    return GRAIN_NS if r_px >= RESOLVED_MIN_PX else None


class Grain(GatherStage):
    name = "grain"
    order = 90.0
    role = "noise of the film, on its densities"
    domains = ("density", "density")
    requires = ("film",)
    params = GrainParams

    def skip_reason(self, camera, frame):
        if not camera.film:
            return "no film stock (Camera.film is None)"
        if camera.grain_amount == 0:
            return "Camera.grain_amount is 0"
        return None

    def reason_needed(self, camera, frame):
        r = grain_radius_px(camera, fld.image_width_px(frame))
        if use_boolean(self.quality, r):
            how = "Boolean model (Newson 2017), 64 samples/px"
        elif self.white(camera, fld.image_width_px(frame)):
            how = ("Gaussian clear fraction matched to the Boolean model, white (lag-1 correlation < "
                   f"{RHO_WHITE:g}): per pixel, fused with the pointwise stages beside it")
        else:
            how = "Gaussian clear fraction matched to the Boolean model, correlated by a 3×3 filter"
        return (f"grain radius {r:.3g} px ({r * camera.pixel_pitch_mm(fld.image_width_px(frame)) * 1e3:.3g} µm), amount "
                f"{camera.grain_amount:g}: {how}")

    # -- host tables --------------------------------------------------------------------------
    @per_camera
    def _setup(self, camera, width):
        stock = load_stock(camera.film)
        d_min = stock.d_min()
        d_max = stock.d_max()
        span = float((d_max - d_min).max())
        r = grain_radius_px(camera, width)
        boolean = use_boolean(self.quality, r)
        return stock, d_min, d_max, span, r, boolean

    def defines(self, camera):
        return {}

    def white(self, camera, width: int) -> bool:
        """Whether this camera's grain is the Gaussian path's white noise at ``width`` (filter
        [0, 1, 0]): per pixel, so the plan runs it as :class:`GrainWhite`, fused with film and
        print."""
        _, _, _, span, r, boolean = self._setup(camera, width)
        return not boolean and gaussian_tables(round(r, 12), span, _stats_samples(r))[1][0] == 0.0

    def planned_form(self, camera, frame):
        if not self.white(camera, fld.image_width_px(frame)):
            return self
        form = self.__dict__.get("_white")
        if form is None:
            form = self.__dict__["_white"] = GrainWhite(self)
        return form

    def taps_per_pixel(self, camera, frame) -> int | None:
        """Filter taps per pixel, all three layers, of the gather's Gaussian path (3×3 normals per
        layer, for ``clpost bench`` taps/s — the kernel draws 9/14 Box–Muller pairs per pixel and
        layer and filters them separably, :data:`GAUSSIAN_ROWS`); None on the Boolean path, whose
        work varies with density. (White noise runs as :class:`GrainWhite`, not this gather.)"""
        _, _, _, _, r, boolean = self._setup(camera, fld.image_width_px(frame))
        return None if boolean else 27

    def replay_key(self, camera, frame):
        return (super().replay_key(camera, frame), frame_index(frame))  # the noise hash's frame counter

    def enqueue(self, rt, camera, frame, src, dst, aux):
        stock, d_min, d_max, span, r, boolean = self._setup(camera, fld.image_width_px(frame))
        w, h = frame.width, frame.height
        params = np.concatenate([d_min, d_max]).astype(np.float32)
        seed, fr = np.uint32(camera.noise_seed), np.uint32(frame_index(frame))
        if boolean:
            k = int(min(8, max(1, math.floor(1.0 / r))))
            poly, (a, b) = np.zeros(SIGMA_POLY_DEG + 1), (0.0, 1.0)
        else:
            k = 1
            poly, (a, b) = gaussian_tables(round(r, 12), span, _stats_samples(r))
            if a == 0.0:
                raise RuntimeError("white grain is per pixel: plan it through Grain.planned_form (GrainWhite)")
        lanes = 32 if rt.wide else 1
        rows = GAUSSIAN_ROWS
        defines = {"GRAIN_BOOLEAN": int(boolean), "GRAIN_NS": GRAIN_NS, "GRAIN_CELLS": k,
                   "GRAIN_POLY_DEG": SIGMA_POLY_DEG, "GRAIN_ROWS": rows, "GRAIN_LANES": lanes}
        knl = rt.kernel(_program_source(), "grain", defines)
        # the Gaussian path: 32 pixels × GAUSSIAN_ROWS rows per work-item, 8×1 work-groups, where
        # the device is wide (a CPU), else one pixel per work-item in 16×8 groups (kernels/grain.cl);
        # the Boolean path one pixel per work-item
        if boolean:
            size, local = (w, h), None
        elif lanes == 32:
            size, local = (-(-w // 32), -(-h // rows)), (8, 1)
        else:
            size, local = (w, h), (16, 8)
        return [rt.launch(knl, size, local, src, dst, np.int32(w), np.int32(h), rt.constant(params),
                          rt.constant(poly.astype(np.float32)), np.float32(2.0 / span),
                          np.float32(a), np.float32(b), np.float32(r), np.float32(camera.grain_amount), seed, fr)]

    # -- float64 reference --------------------------------------------------------------------
    def reference(self, camera, frame, color):
        stock, d_min, d_max, span, r, boolean = self._setup(camera, fld.image_width_px(frame))
        seed, fr = camera.noise_seed, frame_index(frame)
        d = np.asarray(color, np.float64)
        d_img = np.clip(d - d_min, 0.0, None)
        if boolean:
            t_mean = 10.0 ** -d_img
            t = t_mean + camera.grain_amount * (boolean_clear_fraction(d_img, r, seed, fr) - t_mean)
        else:
            poly, (a, b) = gaussian_tables(round(r, 12), span, _stats_samples(r))
            t = 10.0 ** -d_img + camera.grain_amount * sigma_t(poly, span, d_img) * correlated_normal(
                color.shape[0], color.shape[1], a, b, seed, fr)
        t_floor = 10.0 ** -(d_max - d_min)
        return d_min + -np.log10(np.clip(t, t_floor, 1.0))


class GrainWhite(PointwiseStage):
    """grain's white Gaussian path as a pointwise stage (kernels/grain_white.cl): the plan's form of
    :class:`Grain` where its noise is white (:meth:`Grain.white`), fused with its pointwise
    neighbours (film, print) so the frame is read and written once for all of them. The same
    counters and arithmetic as the gather's white path; reasons, skip rules and the float64
    reference are :class:`Grain`'s."""

    form_of = Grain
    name = Grain.name
    order = Grain.order
    role = Grain.role
    domains = Grain.domains
    requires = Grain.requires
    state = True
    args = (("__global const float *", "params"), ("__global const float *", "poly"),
            ("float", "inv_half_span"), ("float", "amount"), ("uint", "seed"), ("uint", "frame"))

    def __init__(self, grain: Grain) -> None:
        super().__init__(grain.quality)
        self.grain = grain

    def source(self) -> str:
        from ..runtime import kernel_source

        return kernel_source("grain_pixel") + kernel_source("grain_white")

    def defines(self, camera):
        return {"GRAIN_POLY_DEG": SIGMA_POLY_DEG}

    def skip_reason(self, camera, frame):
        return self.grain.skip_reason(camera, frame)

    def reason_needed(self, camera, frame):
        return self.grain.reason_needed(camera, frame)

    def replay_key(self, camera, frame):
        return self.grain.replay_key(camera, frame)

    def reference(self, camera, frame, color):
        return self.grain.reference(camera, frame, color)

    @per_camera
    def _tables(self, camera, width):
        """(params [D_min, D_max] per layer, σ polynomial, 2/span), float32, read-only: uploaded once."""
        _, d_min, d_max, span, r, _ = self.grain._setup(camera, width)
        poly, _ = gaussian_tables(round(r, 12), span, _stats_samples(r))
        params = np.concatenate([d_min, d_max]).astype(np.float32)
        poly32 = np.asarray(poly, np.float32)
        for a in (params, poly32):
            a.setflags(write=False)
        return params, poly32, np.float32(2.0 / span)

    def values(self, camera, frame):
        params, poly, inv_half_span = self._tables(camera, fld.image_width_px(frame))
        return (params, poly, inv_half_span, np.float32(camera.grain_amount), np.uint32(camera.noise_seed),
                np.uint32(frame_index(frame)))


GAUSSIAN_ROWS = 14
"""Rows per work-item (each 32 pixels wide) of the correlated Gaussian path's lane form: each row of
normals filtered by [a, b, a] serves three output rows, so R rows cost R + 2 filtered rows, one
float16 of draws each, and two float16 of draws for the normals left and right of the block —
(R + 4)·16 / (32 R) draws per pixel and layer: 9/14 at 14, the most kernels/grain.cl takes (the row
counts' measured cost: docs/benchmarks.md). White noise is :class:`GrainWhite` (half a draw per
pixel and layer, fused with film and print)."""


def _program_source() -> str:
    """common.cl, the one-pixel libraries and grain_pixel.cl (plain names), the 16-lane ones
    (``_w16``), grain.cl."""
    from ..codegen import library, library_lanes16
    from ..runtime import kernel_source

    pixel = kernel_source("grain_pixel")
    return library() + pixel + library_lanes16() + pixel + kernel_source("grain")


def grain_normals(h, w, seed, fr, c):
    """(h + 2, w + 2) normals of counters (X, Y), X in -1 … w, Y in -1 … h, of layer ``c``: in
    block ⌊X/32⌋ of row Y the Box–Muller draws of hashes (seed, frame, 16⌊X/32⌋ + k, Y << 2 | c)
    give counter 32⌊X/32⌋ + k its cosine and 32⌊X/32⌋ + 16 + k its sine (kernels/grain.cl)."""
    ys, xs = np.mgrid[-1:h + 1, -1:w + 1]
    p = (np.floor_divide(xs, 32) << 4 | (xs & 15)).astype(np.int64).astype(np.uint32)
    hh = rnd.hash4(seed, fr, p, (ys.astype(np.int64) << 2 | c).astype(np.uint32))
    cos_, sin_ = rnd.normal_pair(hh, rnd.mix(hh ^ np.uint32(0x68E31DA4)))
    return np.where(xs & 16, sin_, cos_)


def correlated_normal(h, w, a, b, seed, fr):
    """(h, w, 3) unit-variance field: [a, b, a]⊗[a, b, a] over the normals of counters
    (x + i, y + j), i, j ∈ {−1, 0, 1} (:func:`grain_normals`); a = 0: white, counter (x, y)."""
    out = np.zeros((h, w, 3))
    wts = (a, b, a)
    for c in range(3):
        n = grain_normals(h, w, seed, fr, c)
        if a == 0.0:
            out[..., c] = n[1:h + 1, 1:w + 1]
            continue
        for j in range(3):
            for i in range(3):
                out[..., c] += wts[j] * wts[i] * n[j:j + h, i:i + w]
    return out


def boolean_clear_fraction(d_img, r, seed, fr):
    """Reference Boolean model: the clear fraction of each pixel's GRAIN_NS² jittered samples.

    Same cells, Poisson counts, grain positions and samples as ``grain_boolean`` (all from the
    counter hash), evaluated in float64 and vectorised over samples."""
    h, w, _ = d_img.shape
    k = int(min(8, max(1, math.floor(1.0 / r))))
    ns = GRAIN_NS
    # samples, shared by the three layers
    py, px = np.mgrid[0:h, 0:w]
    pix = (py * w + px).astype(np.uint32)[..., None]
    s = np.arange(ns * ns, dtype=np.uint32)[None, None]
    hs = rnd.hash4(seed, fr, pix, s | np.uint32(0x80000000))
    su = px[..., None] + ((s % ns) + rnd.uniform(hs)) / ns
    sv = py[..., None] + ((s // ns) + rnd.uniform(rnd.mix(hs ^ np.uint32(0x85EBCA6B)))) / ns
    out = np.empty((h, w, 3))
    reach = int(math.ceil(r * k))  # cells a grain centre within r of a sample can lie in
    margin = reach + 2
    cx0, cy0 = -margin, -margin
    ncx, ncy = w * k + 2 * margin, h * k + 2 * margin
    cy, cx = np.mgrid[cy0:cy0 + ncy, cx0:cx0 + ncx]
    for c in range(3):
        pxl = np.clip(np.floor_divide(cx, k), 0, w - 1)
        pyl = np.clip(np.floor_divide(cy, k), 0, h - 1)
        lam = d_img[pyl, pxl, c] * LN10 / (math.pi * r * r) / (k * k)
        hc = rnd.hash4(seed, fr, (cx + 64).astype(np.uint32), (((cy + 64) << 2) | c).astype(np.uint32))
        n = rnd.poisson_inversion(lam, rnd.uniform(hc)).astype(int)
        kmax = max(int(n.max()), 1)
        kk = np.arange(kmax, dtype=np.uint32)
        with np.errstate(over="ignore"):
            hk = rnd.mix(hc[..., None] + np.uint32(0x9E3779B9) * (kk + np.uint32(1)))
        gx = (cx[..., None] + rnd.uniform(hk)) / k
        gy = (cy[..., None] + rnd.uniform(rnd.mix(hk ^ np.uint32(0x85EBCA6B)))) / k
        valid = kk[None, None, :] < n[..., None]
        covered = np.zeros(su.shape, bool)
        scx = np.floor(su * k).astype(int) - cx0
        scy = np.floor(sv * k).astype(int) - cy0
        for dy in range(-reach, reach + 1):
            for dx in range(-reach, reach + 1):
                ix, iy = scx + dx, scy + dy
                gxx, gyy, vv = gx[iy, ix], gy[iy, ix], valid[iy, ix]
                dist2 = (gxx - su[..., None]) ** 2 + (gyy - sv[..., None]) ** 2
                covered |= ((dist2 <= r * r) & vv).any(axis=-1)
        out[..., c] = 1.0 - covered.mean(axis=-1)
    return out
