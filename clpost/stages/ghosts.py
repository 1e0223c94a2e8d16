r"""ghosts: the lens's two-reflection ghosts of the frame's brightest sources.

**Model** (formulas and sources in :mod:`clpost.optics.ghosts`): every pair of surfaces of the
traced prescription (focused, stopped to the working f-number) gives a ghost — the aperture shape
(blades, rotation, roundness as the DoF stage's, :func:`clpost.stages.dof.aperture_radius`) of
radius :math:`R_g` centred at :math:`s_g\,p` for a source at p (image position from the optical
centre), carrying the share :math:`\rho_g` of the source's flux. :math:`s_g, R_g, \rho_g` are
fitted from real traces (:func:`clpost.optics.ghosts.fit_ghosts`: element apertures clip the
bundles, aberrations move and spread them) at 550 nm on a grid of field angles, once per lens,
f-number and focus; per source they are interpolated at the source's field angle (from its image
height, through the traced direct image heights). Per channel (611, 549, 464 nm: the coatings
tint the ghosts) the first-order model's chromatic differences are kept: centre factor
+ (first order at λ − first order at 550 nm), radius and share × (first order at λ / at 550 nm).
Radii below 1 px are raised to 1 px; the traced radius is √2 × the RMS spread (a uniform disc's),
drawn as the aperture shape of that radius.

**Sources.** A pixel whose largest channel exceeds the threshold
:math:`T = \texttt{ghost\_threshold} / g` (g the exposure gain: T is ``ghost_threshold`` times the
scene value that saturates the sensor; :func:`clpost.photometry.exposure_gain`) belongs to a
source. The frame is cut into 16 × 16 tiles; the tiles holding the most flux above threshold (the
sum of their above-threshold pixels' luminance; at most ``ghost_sources``) are the sources, each
at its above-threshold pixels' luminance-weighted centroid with their summed RGB flux. The sources
are found on the host from the frame's input pixels (one pass, ~5 ms at 960 × 540), so the stage
runs in the render's geometry, before distortion (which then moves the ghosts with the image:
a first-order ghost carries no distortion of its own).

**Energy.** A source's above-threshold pixels keep :math:`1 - \sum_g \rho_g` (at its field
angle) of their value; each ghost spreads :math:`\rho_g` of the source's flux over its area (the
1-px coverage ramp of the DoF stage, normalised by the shape's area :math:`a_K R^2`), so the
frame's total is conserved except for ghost light that falls outside the frame (tested to 1 %).

**Planned** only when ``Camera.ghosts`` is on, the lens is a traced prescription and some pixel
exceeds T (``--explain`` names the brightest pixel in saturations).

Quality: the ghosts kept, brightest first by peak irradiance :math:`\rho_g/(a_K R_g^2)`: draft 8,
preview 24, final all (78 for the Planar). At every quality a source's ghost whose peak adds less
than ``GHOST_FLOOR`` (10⁻⁴) × saturation is not drawn and its share stays in the source (energy
still conserved; the large, faint defocused ghosts cost the most pixels).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..params import at_least, boolean, integer, param, parse_fraction, parse_on_off
from . import _field as fld
from ._highlights import below_threshold, scene_threshold
from .base import GatherStage, per_camera

TILE = 16
MIN_RADIUS_PX = 1.0
GHOSTS_KEPT = {"draft": 8, "preview": 24, "final": None}
GHOST_FLOOR = 1e-4
"""A source's ghost whose peak adds less than this × saturation is not drawn; its share stays in
the source (docs/flare.md measures what it saves and costs: 2.9 × faster at final, ≤ 2.6e-3 ×
saturation missing anywhere in the demo frame)."""
SRC_REC = 12
"""Floats per source: x, y (px), flux R, G, B, tile x0, y0, the share its pixels keep R, G, B, 0, 0."""
GHOST_REC = 12
"""Floats per ghost and source: per channel (centre factor, signed radius px, irradiance per unit
flux), padded (on the host: column 9 the path i*100 + j, column 10 the mean share)."""


@dataclass(frozen=True)
class GhostsParams:
    """ghosts: first-order two-reflection ghosts of a traced lens, driven by the frame's bright sources."""

    ghosts: bool = param(False, unit="on/off", flag="--ghosts", parse=parse_on_off, check=boolean,
                         header="clpost.ghosts", scalar=False,
                         help="lens ghosts of the brightest sources (a lens_data lens): on/off")
    ghost_threshold: float = param(
        1.0, unit="× saturation", flag="--ghost-threshold", parse=parse_fraction, header="clpost.ghostThreshold",
        check=at_least(0.0, "× saturation", "e.g. 1 (sources that clip the sensor)", "0 = every pixel"),
        scalar=True, help="a source is a pixel brighter than this many times the exposure's saturation")
    ghost_sources: int = param(8, unit="sources", flag="--ghost-sources", parse=int,
                               check=integer(1, 257, rule="an integer from 1 to 256"), header="clpost.ghostSources",
                               scalar=False, help="at most this many sources throw ghosts (brightest first)")


def threshold_scene(camera) -> float:
    """T: the scene value of ``ghost_threshold`` saturations (module docstring)."""
    return scene_threshold(camera, camera.ghost_threshold)


def find_sources(color: np.ndarray, threshold: float, max_sources: int, tile: int = TILE) -> np.ndarray:
    """(K, SRC_REC) float64 sources of the module docstring, brightest first (K ≤ max_sources)."""
    c = np.asarray(color, np.float64)
    h, w = c.shape[:2]
    over = c.max(axis=2) > threshold
    if not over.any():
        return np.zeros((0, SRC_REC))
    ty, tx = np.nonzero(over)
    lum = c[ty, tx] @ np.array([0.2126, 0.7152, 0.0722])
    tid = (ty // tile) * ((w + tile - 1) // tile) + tx // tile
    n_t = ((h + tile - 1) // tile) * ((w + tile - 1) // tile)
    tot = np.bincount(tid, lum, n_t)
    order = np.argsort(-tot, kind="stable")
    order = order[tot[order] > 0][:max_sources]
    out = np.zeros((len(order), SRC_REC))
    for k, t in enumerate(order):
        sel = tid == t
        wgt = lum[sel] / tot[t]
        out[k, 0], out[k, 1] = (tx[sel] * wgt).sum(), (ty[sel] * wgt).sum()
        out[k, 2:5] = c[ty[sel], tx[sel]].sum(axis=0)
        out[k, 5], out[k, 6] = (t % ((w + tile - 1) // tile)) * tile, (t // ((w + tile - 1) // tile)) * tile
    return out


class Ghosts(GatherStage):
    name = "ghosts"
    order = 45.0
    role = "light reflected twice between lens surfaces, imaged through the aperture (before distortion: it finds its sources in the render's pixels)"
    domains = ("render", "render")
    params = GhostsParams
    example = dict(lens="zeiss-planar-50-f1.4", f_number=4.0, ghosts=True, ghost_threshold=0.5,
                   ghost_sources=4, blades=6)
    turn_off = "give --ghosts off"

    @per_camera
    def fitted(self, camera, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The ghosts kept at this quality on the field-angle grid: ((G, T, GHOST_REC) records of
        the module docstring, per channel (centre factor, signed radius px, share); (T,) the direct
        image's height in px at each angle; (G,) paths i*100 + j), brightest first (peak green
        irradiance ρ/(a_K R²), the largest over the grid)."""
        from ..optics.ghosts import ghosts
        from .dof import aperture_area
        from .lateral_color import channel_wavelengths_nm

        lens = camera.optics
        n = lens.clamp_f_number(camera.f_number, warn=False)
        pres = lens.focused(camera.focus_from_film_m * 1000.0, n)
        r_stop = lens.stop_radius_mm(n)
        pitch = fld.pitch_mm(camera, width)
        a_k = aperture_area(camera.blades, 0.0, camera.aperture_roundness)
        fit = _fit_cached(pres, r_stop)
        par = [{g.path: g for g in ghosts(pres, r_stop, lam)} for lam in (*channel_wavelengths_nm(), 550.0)]
        rows, paths, peaks = [], [], []
        for gi, path in enumerate(map(tuple, fit["paths"])):
            share = fit["share"][gi]
            ok = share > 0
            if not ok.any():
                continue  # no real ray takes this path at any field angle
            idx = np.arange(len(share))
            near = idx[ok][np.abs(idx[:, None] - idx[ok][None, :]).argmin(1)]  # nearest angle with rays
            centre, radius = fit["centre"][gi][near], fit["radius_mm"][gi][near]
            g0 = par[3][path]
            row = np.zeros((len(share), GHOST_REC))
            for c in range(3):
                g = par[c][path]
                r_px = np.maximum(radius * (g.radius_mm / g0.radius_mm) / pitch, MIN_RADIUS_PX)
                row[:, 3 * c] = centre + (g.centre_factor - g0.centre_factor)
                row[:, 3 * c + 1] = np.copysign(r_px, g.scale)
                row[:, 3 * c + 2] = share * (g.share / g0.share)
            rows.append(row)
            paths.append(path[0] * 100 + path[1])
            peaks.append(float(np.max(row[:, 5] / (a_k * row[:, 4] ** 2))))
        order = np.argsort(-np.array(peaks), kind="stable")[:GHOSTS_KEPT[self.quality]]
        return (np.array([rows[k] for k in order]).reshape(len(order), len(fit["thetas_deg"]), GHOST_REC),
                fit["direct_mm"] / pitch, np.array([paths[k] for k in order]))

    def table(self, camera, frame, srcs) -> np.ndarray:
        """(S, G, GHOST_REC) per source the kept ghosts interpolated at its field angle: per channel
        centre factor, signed radius px, irradiance per unit flux (1/px²); a source's ghosts
        fainter than GHOST_FLOOR (module docstring) are moved to the end of its row with zero
        irradiance, and column 11 of its first record counts the rest (what the kernel draws)."""
        from ..optics.ghosts import fit_weights
        from ..photometry import exposure_gain
        from .dof import aperture_area

        grid, direct_px, _ = self.fitted(camera, fld.image_width_px(frame))
        a_k = aperture_area(camera.blades, 0.0, camera.aperture_roundness)
        cx, cy = self._centre(camera, frame)
        out = np.zeros((len(srcs), len(grid), GHOST_REC))
        for k, s in enumerate(srcs):
            i0, i1, f = fit_weights(direct_px, math.hypot(s[0] - cx, s[1] - cy))
            rec = (1 - f) * grid[:, i0] + f * grid[:, i1]
            for c in range(3):
                r = np.abs(rec[:, 3 * c + 1])
                out[k, :, 3 * c] = rec[:, 3 * c]
                out[k, :, 3 * c + 1] = np.copysign(r, grid[:, i0, 3 * c + 1])
                out[k, :, 3 * c + 2] = rec[:, 3 * c + 2] / (a_k * r * r)
            peak = (out[k, :, 2:9:3] * s[2:5]).max(axis=1)  # brightest channel's irradiance, scene units
            bright = peak >= GHOST_FLOOR / exposure_gain(camera)
            out[k] = np.concatenate([out[k][bright], out[k][~bright]])
            out[k, int(bright.sum()):, 2:9:3] = 0.0
            if len(grid):
                out[k, 0, 11] = bright.sum()
        return out

    def shares(self, camera, frame, srcs) -> np.ndarray:
        """(S, 3) Σ ρ_g per source and channel over the kept ghosts (what a source's pixels give up)."""
        t = self.table(camera, frame, srcs)
        return np.stack([(t[..., 3 * c + 2] * _area(camera, np.abs(t[..., 3 * c + 1]))).sum(-1) for c in range(3)], -1)

    def sources(self, camera, frame) -> np.ndarray:
        """The frame's sources (:func:`find_sources`) with the share each one's pixels keep (columns 7–9)."""
        s = find_sources(frame.color, threshold_scene(camera), camera.ghost_sources)
        if len(s):
            s[:, 7:10] = 1.0 - self.shares(camera, frame, s)
        return s

    def _centre(self, camera, frame):
        w, h = frame.width, frame.height
        g = fld.frame_geometry(camera, frame)
        return fld.field_centre_px(camera, frame) if g is not None else fld.principal_point_px(camera, w, h)

    def skip_reason(self, camera, frame):
        if not camera.ghosts:
            return "Camera.ghosts is off"
        if camera.optics is None:
            return "thin lens: no prescription to reflect light (use a lens_data lens)"
        return below_threshold(camera, frame, camera.ghost_threshold, "source")

    def reason_needed(self, camera, frame):
        t = threshold_scene(camera)
        s = self.sources(camera, frame)
        g = self.fitted(camera, fld.image_width_px(frame))[0]
        share = (1.0 - s[0, 8]) if len(s) else 0.0
        return (f"{len(s)} source(s) above {camera.ghost_threshold:g} × saturation (brightest pixel "
                f"{float(np.max(frame.color)) / t * camera.ghost_threshold:.3g} × saturation), {len(g)} ghosts "
                f"fitted from traces, Σρ = {share:.2e} of the brightest source's flux")

    def replay_key(self, camera, frame):
        return (super().replay_key(camera, frame), self.sources(camera, frame).tobytes())

    def defines(self, camera):
        return {"GHOSTS_BLADES": int(camera.blades)}

    def enqueue(self, rt, camera, frame, src, dst, aux):
        from ..runtime import kernel_source

        w, h = frame.width, frame.height
        cx, cy = self._centre(camera, frame)
        srcs = self.sources(camera, frame)
        table = self.table(camera, frame, srcs)
        n_g = table.shape[1]
        src_buf = rt.scratch(self, "sources", (max(len(srcs), 1), SRC_REC))
        tab = rt.scratch(self, "table", (max(table.size, 1),))
        if len(srcs):
            rt.copy(src_buf, np.ascontiguousarray(srcs, np.float32))
            rt.copy(tab, np.ascontiguousarray(table, np.float32).ravel())
        k = rt.kernel(kernel_source("ghosts"), "ghosts", self.defines(camera), "ghosts")
        rot = math.radians(camera.blade_rotation_deg)
        return [rt.launch(k, (w, h), None, src, dst, src_buf, np.int32(len(srcs)), tab, np.int32(n_g),
                          np.int32(w), np.int32(h), np.float32(cx), np.float32(cy),
                          np.float32(threshold_scene(camera)), np.float32(rot), np.float32(camera.aperture_roundness))]

    def reference(self, camera, frame, color):
        """float64 numpy implementation of the module docstring."""
        from .dof import aperture_radius

        color = np.asarray(color, np.float64)
        h, w = color.shape[:2]
        cx, cy = self._centre(camera, frame)
        srcs = self.sources(camera, frame)
        table = self.table(camera, frame, srcs)
        out = color.copy()
        t = threshold_scene(camera)
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
        over = color.max(axis=2) > t
        for s in srcs:
            in_tile = over & (xs >= s[5]) & (xs < s[5] + TILE) & (ys >= s[6]) & (ys < s[6] + TILE)
            out[in_tile] *= s[7:10]
        for s, rows in zip(srcs, table):
            for row in rows:
                for c in range(3):
                    f, r, e = row[3 * c:3 * c + 3]
                    ox = xs - (cx + (s[0] - cx) * f)
                    oy = ys - (cy + (s[1] - cy) * f)
                    if r < 0:
                        ox, oy, r = -ox, -oy, -r
                    rho = aperture_radius(np.arctan2(oy, ox), camera.blades, camera.blade_rotation_deg,
                                          camera.aperture_roundness)
                    cov = np.clip(r * rho - np.hypot(ox, oy) + 0.5, 0.0, 1.0)
                    out[..., c] += s[2 + c] * e * cov
        return out


_FITS: dict = {}


def _fit_cached(pres, r_stop):
    """:func:`clpost.optics.ghosts.fit_ghosts` at 550 nm, memoised per (prescription, stop) (a
    few seconds of traces; shared by every camera and quality with that lens state). The key is
    the prescription's repr: the dataclass holds dicts, so it does not hash."""
    from ..optics.ghosts import fit_ghosts

    key = (repr(pres), float(r_stop))
    fit = _FITS.get(key)
    if fit is None:
        fit = fit_ghosts(pres, r_stop, 550.0)
        if len(_FITS) >= 8:
            _FITS.pop(next(iter(_FITS)))
        _FITS[key] = fit
    return fit


def _area(camera, r_px) -> np.ndarray:
    from .dof import aperture_area

    return aperture_area(camera.blades, 0.0, camera.aperture_roundness) * np.asarray(r_px) ** 2
