r"""distortion: resample the undistorted pinhole render into the image of a calibrated camera.

Each output pixel (u, v) of the distorted image asks where its light came from: the exact inverse
of the camera model (any family of :class:`clpost.calibration.OpenCVModel`, docs/camera_models.md:
:func:`clpost.calibration.undistort_newton`, or the Heikkilä fit if
``OpenCVModel.inverse == "heikkila"``) gives undistorted normalised coordinates (x', y'), and the
render's pinhole intrinsics (f_r, c_r) give the source position (:func:`source_positions`; a
cubemap render, for fields of view beyond 150°, is sampled at the pixel's ray instead:
:mod:`clpost.calibration.cubemap`)

.. math::

    s_x = f_{r,x}\,x' + c_{r,x}, \qquad s_y = f_{r,y}\,y' + c_{r,y}

Distortion is static, so this map is computed once per (model, render size, render intrinsics)
on the host in float64 and kept on the device; each frame costs one resampling pass
(Lambers, Sommerhoff & Kolb, "Realistic Lens Distortion Rendering", WSCG 2018, sec. 3).

The render's intrinsics come from ``frame.metadata["intrinsics"]`` (the pyvista renderer records
them) or, for EXRs, from the size of the frame's **display window** (:attr:`clpost.Frame.windows`):
the calibration's own size means "rendered with the calibration's K", the size of
:func:`clpost.calibration.required_render` means "rendered with that frustum" (use it: barrel
distortion then leaves no unfilled pixel). Any other size is an error. A data window beyond the
display window is **overscan**: the same camera's pixels around the image (c shifted by the
display window's offset in the arrays), which the map samples like any other — render with
:func:`clpost.calibration.overscan_px` of them (``clpost render-size``) and no output pixel is
unfilled. The output has the calibration's size; its data window is its display window.

Fill (``Camera.fill``, ``--fill``) says what happens to output pixels the render does not cover:
``overscan`` (default) samples the overscan and, where the render still falls short, leaves
them black with alpha 0 and warns once (one line naming the overscan needed and the other
modes: never a silent border); ``border`` does the same without the warning (a compositor's
choice, as Nuke's LensDistortion leaves its bounding box); ``crop`` magnifies the distorted image
about the principal point by the least factor s ≥ 1 that fills every output pixel
(:func:`crop_scale`: the map of a model with focal lengths s·f, same c and coefficients — the
field of view narrows by s, as scaling a plate up to hide the border does).

Quality: ``draft``/``preview`` bilinear (4 taps); ``final`` cubic B-spline *interpolation*
(Unser, "Splines: a perfect fit for signal and image processing", IEEE SPM 1999): the render's
B-spline coefficients (the prefilter as a separable FIR along rows, then columns, :func:`fir_taps`,
stored with :data:`PAD` edge pixels around the render) sampled by 16 taps with B-spline weights —
computed per lane on the tiles whose taps fit a tile-uniform 5 × 5 window (:func:`bspline_tiles`,
vector loads), from a per-pixel table built with the map elsewhere (:func:`tap_table`) — made
HDR-safe by :func:`resample`'s clamp to the 2 × 2 samples around the position and hand-over to
bilinear where the local contrast exceeds 32 : 1 (:func:`hdr_weight`, pass ``distortion_dering``):
no ring below the background around highlights, their energy kept. It passes
through the samples and reproduces cubics exactly, so an edge stays where it is whatever its
sub-pixel phase. Keys' cubic convolution (OpenCV's ``INTER_CUBIC``) is only first-order — a ramp is
off by up to 0.048 × its slope — and moves checkerboard corners
by ≈ 0.025 px in a way correlated over the image: k2 4.7–8 % and p2 6.7 % off in the
calibration check, against < 1 % for every parameter with the B-spline
(tools/distortion_calibration.py, docs/distortion_calibration.md). The reference is scipy's
``map_coordinates(order=3, mode="nearest")``, an independent implementation of the same filter,
with the clamp and hand-over in numpy.

Alpha: output pixels with no preimage inside the render — outside its frustum, beyond the model's
fold radius (clamped, see :mod:`clpost.calibration`), or where Newton did not converge — get
color 0 and **alpha 0**; elsewhere alpha is the input alpha resampled bilinearly (1 without one).
Depth is looked up at the nearest source pixel (+inf where alpha is 0); velocity likewise and
mapped into output pixels by the inverse Jacobian of the map, :math:`v_{out} = J^{-1} v_{in}`,
:math:`J = \partial s / \partial (u, v)` by central differences (0 where alpha is 0; untransformed
on the 1-pixel rim of the valid area, where a neighbour has no data). Label planes
(:attr:`clpost.Frame.labels`: ids, segmentation, normals, AOVs; ``Camera.labels`` chooses which an
EXR's are) take the same nearest source pixel, never blended (:mod:`clpost.labels.channels`,
kernel ``distortion_labels``), 0 where alpha is 0.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from ..calibration import OpenCVModel, overscan_px, required_render, undistort
from ..calibration.cubemap import CubemapSpec
from ..calibration.frustum import border_samples
from ..errors import InputError
from ..params import boolean, exact_g, one_of, param, parse_on_off
from . import _field as fld
from .base import GatherStage


def _check_calibration(name, value):
    if value is not None and not isinstance(value, OpenCVModel):
        raise InputError(f"Camera.{name} must be a clpost.calibration.OpenCVModel or None, not "
                         f"{type(value).__name__}; load one with load_calibration('cam.yaml')")
    return value


def _show_calibration(m):
    from ..calibration.traced import TRACED_SOURCE

    if m is None or TRACED_SOURCE in (m.source or ""):
        return None  # a lens's own traced model is re-traced from the lens (clpost.lensDistortion), at any size
    from ..calibration.header import header_text

    return header_text(m)  # named fields, exact floats: --camera-from reads the same model back


def _parse_calibration(text):
    """A calibration file → OpenCVModel; its errors become usage errors."""
    import argparse

    from ..calibration import load_calibration

    try:
        return load_calibration(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _check_labels(name, value):
    from ..labels.channels import check_labels

    return check_labels(name, value)


FILLS = ("overscan", "crop", "border")
"""``Camera.fill`` modes (see the module docstring)."""


@dataclass(frozen=True)
class DistortionParams:
    """distortion: a calibration's OpenCV model, or a traced lens's own curve."""

    distortion: OpenCVModel | None = param(
        None, unit="OpenCV model", flag="--calibration", parse=_parse_calibration, check=_check_calibration,
        header="clpost.distortion", show=_show_calibration, scalar=False,
        help="camera calibration (OpenCV YAML/XML/JSON, ROS camera_info, COLMAP cameras.txt[#ID], Kalibr "
             "camchain[#camN]): renders its "
             "distortion (a clpost.calibration.OpenCVModel in the library)")
    lens_distortion: bool = param(
        True, unit="on/off", flag="--lens-distortion", parse=parse_on_off, check=boolean, scalar=False,
        header="clpost.lensDistortion",
        help="a lens_data lens without --calibration distorts by its traced curve: on/off")
    fill: str = param(
        "overscan", unit="mode", flag="--fill", check=one_of(*FILLS), header="clpost.fill", scalar=False,
        help="output pixels of the distorted image the render does not cover: overscan (sample the EXR data "
             "window beyond the display window; black, alpha 0 and a warning where it falls short), crop "
             "(magnify until every pixel is covered), border (black, alpha 0, no warning)")
    labels: str = param(
        "auto", unit="channels", flag="--labels", check=_check_labels, header="clpost.labels", scalar=False,
        help="label channels of the input carried through the geometry by nearest sampling, never blended: auto "
             "(the id/segmentation channels it has: IndexOB, id, instance, Crypto…), all (every channel besides "
             "colour, alpha, depth, velocity), none, or comma-separated names (e.g. IndexOB,Normal); "
             "clpost.labels.channels")


INVALID = -1.0e30
"""Map value marking an output pixel without a preimage (the kernel writes 0, alpha is 0)."""


def source_intrinsics(model: OpenCVModel, frame):
    """(f_x, f_y, c_x, c_y) of the pinhole render in ``frame``'s arrays (see the module docstring),
    or the :class:`~clpost.calibration.cubemap.CubemapSpec` of a cubemap atlas
    (``frame.metadata["cubemap"] = (face, pad)``)."""
    cube = frame.metadata.get("cubemap") if isinstance(frame.metadata, dict) else None
    if cube is not None:
        spec = CubemapSpec(*(int(t) for t in cube))
        if frame.size != (spec.width, spec.height):
            raise InputError(f"distortion: the frame is {frame.width}x{frame.height} but its metadata['cubemap'] = "
                             f"{tuple(cube)} makes a {spec.width}x{spec.height} atlas; render it with "
                             "PyVistaRenderer.render_cubemap or fix the metadata")
        return spec
    recorded = fld.frame_intrinsics(frame)
    if recorded is not None:
        return recorded
    win = frame.windows
    dw, dh = win.display_size
    k = fld.render_intrinsics_px(model, dw, dh)
    if k is not None:
        ox, oy = win.display_offset
        return k[0], k[1], k[2] + ox, k[3] + oy
    spec = required_render(model)
    left, top, right, bottom = overscan_px(model)
    raise InputError(
        f"distortion: the frame is {dw}x{dh} but the calibration{model._where()} is "
        f"{model.width}x{model.height}; render at {model.width}x{model.height} (the calibration's K; with "
        f"{left}/{top}/{right}/{bottom} px of overscan left/top/right/bottom as an EXR data window for no "
        f"unfilled pixels) or at {spec.width}x{spec.height} (f={spec.f:.6g}, c=({spec.cx:.6g}, {spec.cy:.6g})): "
        "clpost render-size says how, or record the render's intrinsics in frame.metadata['intrinsics']")


def _covered(model: OpenCVModel, src_size: tuple[int, int], src_k: tuple[float, float, float, float],
             scale: float) -> bool:
    """Whether every output pixel of ``model`` magnified by ``scale`` has a preimage inside the
    render: its border (4 samples a pixel) maps inside [−½, size − ½] (for the radial models the
    border bounds the interior)."""
    m = _scaled(model, scale)
    sx, sy, ok = source_positions(m, *border_samples(m.width, m.height), src_k)
    sw, sh = src_size
    return bool(np.all(ok & (sx >= -0.5) & (sx <= sw - 0.5) & (sy >= -0.5) & (sy <= sh - 0.5)))


def _scaled(model: OpenCVModel, scale: float) -> OpenCVModel:
    if scale == 1.0:
        return model
    from dataclasses import replace

    return replace(model, fx=model.fx * scale, fy=model.fy * scale)


@lru_cache(maxsize=8)
def crop_scale(model: OpenCVModel, src_size: tuple[int, int], src_k: tuple[float, float, float, float]) -> float:
    """The least magnification s ≥ 1 (to 1e-6) about the principal point for which every output
    pixel has a preimage in the render (``--fill crop``), by bisection on :func:`_covered`."""
    if _covered(model, src_size, src_k, 1.0):
        return 1.0
    hi = 1.0
    while not _covered(model, src_size, src_k, hi * 2.0):
        hi *= 2.0
        if hi > 64:
            raise InputError(f"distortion: --fill crop: the render covers no centred part of the calibration"
                             f"{model._where()}'s image; render with the overscan clpost render-size states")
    lo, hi = hi, hi * 2.0
    while hi - lo > 1e-6 * lo:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if _covered(model, src_size, src_k, mid) else (mid, hi)
    return hi


def source_positions(model: OpenCVModel, u: np.ndarray, v: np.ndarray, src_k):
    """Where output pixels (u, v) of ``model`` sample the render: through the model's exact inverse
    to undistorted coordinates and the render's pinhole intrinsics ``src_k`` (module docstring), or,
    for a cubemap atlas (``src_k`` a :class:`~clpost.calibration.cubemap.CubemapSpec`), the pixel's
    ray (:meth:`OpenCVModel.unproject`) looked up on its face. Returns (s_x, s_y, has a preimage)."""
    if isinstance(src_k, CubemapSpec):
        x, y, z, ok = model.unproject(u, v)
        sx, sy = src_k.positions(x, y, z)
        return sx, sy, ok
    x, y, ok = undistort(model, u, v)
    fx, fy, cx, cy = src_k
    return fx * x + cx, fy * y + cy, ok


@lru_cache(maxsize=8)
def distortion_map(model: OpenCVModel, src_size: tuple[int, int],
                   src_k: tuple[float, float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """float64 source positions (2, H, W) for every output pixel and the validity mask (H, W)."""
    vv, uu = np.mgrid[0:model.height, 0:model.width].astype(np.float64)
    sx, sy, ok = source_positions(model, uu, vv, src_k)
    sw, sh = src_size
    ok &= (sx >= -0.5) & (sx <= sw - 0.5) & (sy >= -0.5) & (sy <= sh - 0.5)
    m = np.stack([np.where(ok, sx, INVALID), np.where(ok, sy, INVALID)])
    m.setflags(write=False)
    ok.setflags(write=False)
    return m, ok


class _MapGeometry(NamedTuple):
    alpha: np.ndarray   # float32 (H, W): 1 where the map has data
    flat: np.ndarray    # (H, W) flat index of the nearest source pixel (clamped, intp)
    invalid: np.ndarray # flat output indices without a preimage
    inv: np.ndarray     # (4, H, W): inverse Jacobian of the map, row-major (identity on the rim)


@lru_cache(maxsize=8)
def _map_geometry(model: OpenCVModel, src_size: tuple[int, int],
                  src_k: tuple[float, float, float, float]) -> _MapGeometry:
    """What :meth:`Distortion.host_buffers` needs of the map, once per map (the map is static,
    so it is not recomputed per frame: docs/measurements.md#host-work). Velocities transform by the
    inverse of the map's Jacobian J = ∂(source)/∂(output); on the 1-px rim of the valid area J is
    unknown (a neighbour has no data) and velocities pass untransformed."""
    m, ok = distortion_map(model, src_size, src_k)
    sw, sh = src_size
    xi = np.clip(np.where(ok, np.rint(m[0]), 0), 0, sw - 1).astype(np.int64)
    yi = np.clip(np.where(ok, np.rint(m[1]), 0), 0, sh - 1).astype(np.int64)
    sx, sy = np.where(ok, m[0], np.nan), np.where(ok, m[1], np.nan)

    def grad(a, axis):  # a 1-px-wide image has no neighbour along that axis: no derivative
        return np.gradient(a, axis=axis) if a.shape[axis] > 1 else np.full(a.shape, np.nan)

    j11, j12 = grad(sx, 1), grad(sx, 0)
    j21, j22 = grad(sy, 1), grad(sy, 0)
    det = j11 * j22 - j12 * j21
    with np.errstate(all="ignore"):
        inv = np.stack([j22 / det, -j12 / det, -j21 / det, j11 / det])
    good = np.isfinite(inv).all(axis=0)
    inv = np.where(good, inv, np.array([1.0, 0.0, 0.0, 1.0])[:, None, None])
    flat = (yi * sw + xi).astype(np.intp)
    invalid = np.flatnonzero(~ok)
    alpha = ok.astype(np.float32)
    for a in (flat, invalid, inv, alpha):
        a.setflags(write=False)
    return _MapGeometry(alpha, flat, invalid, inv)


def _aux_flat(g: _MapGeometry) -> np.ndarray:
    """The nearest source pixel of every output pixel as int32, -1 where there is no preimage
    (``distortion_aux``'s index table)."""
    flat = np.asarray(g.flat, np.int64).ravel().copy()
    flat[g.invalid] = -1
    if flat.size and flat.max() >= 2**31:
        raise InputError("distortion: the render is too large for 32-bit pixel indices")
    return flat.astype(np.int32)


def _taps(plane: np.ndarray, xi: np.ndarray, yi: np.ndarray) -> np.ndarray:
    h, w = plane.shape
    return plane[np.clip(yi, 0, h - 1), np.clip(xi, 0, w - 1)]


TILE = 16
"""Output tile of the draft/preview kernels (kernels/distortion.cl DISTORTION_TILE)."""


def _tile_offsets(model: OpenCVModel, src_size: tuple[int, int], src_k: tuple[float, float, float, float]):
    """Per :data:`TILE` × :data:`TILE` output tile: its corner (x0, y0), the least integer
    displacement (ox, oy) of floor(s) − x (and y) over its pixels with a preimage, whether the
    displacement takes at most the two values ox, ox + 1 (oy, oy + 1) there, and how many of its
    pixels have a preimage (TILE² for a whole tile with data everywhere)."""
    m, ok = distortion_map(model, src_size, src_k)
    m = m.astype(np.float32).astype(np.float64)
    h, w = ok.shape
    nty, ntx = -(-h // TILE), -(-w // TILE)
    ph, pw = nty * TILE, ntx * TILE
    yy, xx = np.mgrid[0:ph, 0:pw]
    okp = np.zeros((ph, pw), bool)
    okp[:h, :w] = ok
    dx = np.zeros((ph, pw), np.int64)
    dy = np.zeros((ph, pw), np.int64)
    dx[:h, :w] = np.floor(np.where(ok, m[0], 0.0)).astype(np.int64) - xx[:h, :w]
    dy[:h, :w] = np.floor(np.where(ok, m[1], 0.0)).astype(np.int64) - yy[:h, :w]

    def per_tile(a, fn):
        return fn(fn(a.reshape(nty, TILE, ntx, TILE), axis=3), axis=1)

    big = 1 << 40  # pixels without a preimage take no part in the displacement's range
    ox, oy = per_tile(np.where(okp, dx, big), np.min), per_tile(np.where(okp, dy, big), np.min)
    uniform = ((per_tile(np.where(okp, dx, -big), np.max) - ox <= 1)
               & (per_tile(np.where(okp, dy, -big), np.max) - oy <= 1))
    valid = per_tile(okp.astype(np.int64), np.sum)
    ty, tx = np.mgrid[0:nty, 0:ntx]
    return tx * TILE, ty * TILE, ox, oy, uniform, valid


def _split_tiles(x0, y0, ox, oy, fast) -> tuple[np.ndarray, np.ndarray]:
    tiles = np.stack([x0[fast], y0[fast], ox[fast], oy[fast]], -1).astype(np.int32)
    rest = np.stack([x0[~fast], y0[~fast]], -1).astype(np.int32)
    for a in (tiles, rest):
        a.setflags(write=False)
    return tiles, rest


@lru_cache(maxsize=4)
def bilinear_tiles(model: OpenCVModel, src_size: tuple[int, int],
                   src_k: tuple[float, float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The bilinear kernels' tile lists: (x0, y0, ox, oy) int32 for the whole
    :data:`TILE` × :data:`TILE` output tiles whose pixels all have a preimage, whose integer
    displacement floor(s) − x (and y) takes at most two neighbouring values ox, ox + 1 and whose
    3 × 3 window at (x + ox, y + oy) stays inside the source — ``distortion_tiles`` reads them
    with vector loads; (x0, y0) int32 for the other tiles (``distortion_rest``, per pixel)."""
    x0, y0, ox, oy, uniform, valid = _tile_offsets(model, src_size, src_k)
    sw, sh = src_size
    fast = (uniform & (valid == TILE * TILE) & (x0 + ox >= 0) & (x0 + TILE - 1 + ox + 2 <= sw - 1)
            & (y0 + oy >= 0) & (y0 + TILE - 1 + oy + 2 <= sh - 1))
    return _split_tiles(x0, y0, ox, oy, fast)


@lru_cache(maxsize=4)
def bspline_tiles(model: OpenCVModel, src_size: tuple[int, int],
                  src_k: tuple[float, float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The final filter's tile lists: (x0, y0, ox, oy) int32 for the tiles inside the image with at
    least one pixel with a preimage, whose displacement there takes at most two neighbouring values
    — ``distortion_bspline_tiles`` reads their 5 × 5 coefficient window at (x + ox − 1, y + oy − 1)
    with vector loads on every lane and row (valid positions are in [−½, size − ½], so the
    windows of pixels with a preimage stay inside the :data:`PAD` border; a tile is listed only if
    the windows of the others, which it loads and writes 0 for, stay inside the planes too); (x0, y0) int32 for the other tiles
    (``distortion_table``, per pixel: partial tiles at the image's right edge, tiles without data,
    strongly magnifying or minifying ones)."""
    x0, y0, ox, oy, uniform, valid = _tile_offsets(model, src_size, src_k)
    w, h = model.width, model.height
    pw, ph = coef_pitch(src_size[0]), -(-(src_size[1] + 2 * PAD) // FIR_ROWS) * FIR_ROWS
    # every lane and row (< h) loads its window, with or without a preimage: all 16 × 16 windows
    # must lie in the coefficient planes (lanes without data can sit up to TILE − 1 px from the
    # data that set ox, oy: at 3840×2160 they read 19215 floats before the buffer)
    inside = ((x0 + ox - 1 + PAD >= 0) & (x0 + TILE - 1 + ox + 3 + PAD <= pw - 1)
              & (y0 + oy - 1 + PAD >= 0) & (np.minimum(y0 + TILE, h) - 1 + oy + 3 + PAD <= ph - 1))
    fast = uniform & (valid > 0) & (x0 + TILE <= w) & inside  # rows below the image: the kernel skips them
    return _split_tiles(x0, y0, ox, oy, fast)


TILE_GROUP = 64
"""Tiles per work-group of ``distortion_bspline_tiles`` and ``distortion_tiles``: a group is one row
of that many consecutive tiles (local size (1, TILE_GROUP); kernels/distortion.cl says why)."""

PAD = 20
"""Edge pixels around the B-spline coefficients (kernels/distortion.cl DISTORTION_PAD). The 4×4
window of a valid position (in [−½, size − ½]) needs 2 of them; the rest lets the vector gather
take the border tiles too, whose lanes without a preimage load windows up to the render's
missing overscan beyond its edge (19 px at the bench's barrel distortion); tiles that reach
further take the per-pixel ``distortion_table`` (docs/benchmarks.md, "Distortion's final filter
and astigmatism")."""

FIR_K = 12
"""Half-length of the prefilter FIR (kernels/distortion.cl DISTORTION_FIR_K), see :func:`fir_taps`."""

FIR_ROWS = 4
"""Coefficient rows per work-item of the column pass (kernels/distortion.cl DISTORTION_FIR_ROWS)."""

COEF_SCALE = 512.0
"""The device's coefficient planes hold the B-spline coefficients / COEF_SCALE, so huge finite colour
stays finite (kernels/distortion.cl DISTORTION_COEF_SCALE, which says why 512)."""


def fir_taps(k_max: int = FIR_K) -> np.ndarray:
    r"""h_0 … h_K (float64) of the cubic B-spline prefilter as a symmetric FIR truncated at |k| ≤ K.

    Interpolating with cubic B-splines needs coefficients c with
    :math:`\sum_k c_k \beta^3(x - k) = f(x)` at the samples, i.e. :math:`c = (b^3)^{-1} * f`
    with :math:`B^3(z) = (z + 4 + z^{-1})/6`. Its inverse, with the pole
    :math:`z_1 = \sqrt 3 - 2` (Unser, "Splines: a perfect fit for signal and image processing",
    IEEE SPM 16(6), 1999, eq. 7–8; Unser, Aldroubi & Eden, IEEE TSP 41(2), 1993), has the
    two-sided impulse response

    .. math::

        h_k = \frac{-6 z_1}{1 - z_1^2}\, z_1^{|k|} = \sqrt 3\, z_1^{|k|}, \qquad
        \sum_k h_k = 1, \qquad \sum_k |h_k| = 3

    which scipy applies as a causal + anticausal recursion (one sequential chain per row: too
    slow on the device). Truncated at :math:`|k| \le K` and applied along rows then columns of
    the edge-extended source (what ``mode="nearest"`` means), each 1-D pass is off by
    at most :math:`\varepsilon_K \max|f|`, :math:`\varepsilon_K = \sum_{|k|>K}|h_k| =
    2\sqrt 3\,|z_1|^{K+1}/(1-|z_1|)` (1.74e-7 at K = 12; 2.4e-6 at K = 10), so the coefficients
    by :math:`(\varepsilon_K \sum|h| + \sum|h|\,\varepsilon_K) = 6\varepsilon_K = 1.04\cdot10^{-6}`
    times :math:`\max|f|` at worst; float32 rounding adds about 3 half-ulps of the largest
    coefficient (:math:`\le 9\max|f|`): the test bound is :math:`(6\varepsilon_K +
    27 \cdot 2^{-24}) \max|f| = 2.6\cdot10^{-6}\max|f|`, measured 0.6–0.7e-6 with 1e8 spikes
    (end to end at 720p with 1 % spikes of 1e8: 3.6e-7·1e8). The interpolated value has the same
    bound (B-spline weights ≥ 0, sum 1). scipy's mirror boundary on its 12-pixel padding differs
    from the infinite edge repeat only ≥ 22 pixels away from any coefficient the 4×4 windows read
    (:math:`|z_1|^{22} < 10^{-12}`)."""
    z = np.sqrt(3.0) - 2.0
    return -6.0 * z / (1.0 - z * z) * z ** np.arange(k_max + 1, dtype=np.float64)


def coef_pitch(src_w: int) -> int:
    """Row pitch of the coefficient planes: the render plus 2 :data:`PAD`, rounded up to 64, so a
    row is an even count of the prefilter kernels' 16-pixel work-items (PoCL's automatic
    work-group sizes for an odd count walk down column strips instead of along rows; measured in
    docs/benchmarks.md, "Distortion's final filter and astigmatism")."""
    return -(-(src_w + 2 * PAD) // 64) * 64


def bspline3(t: np.ndarray) -> list[np.ndarray]:
    """Cubic B-spline weights of the taps at floor − 1 … floor + 2 for the fraction ``t``."""
    s = 1.0 - t
    return [s**3 / 6, (4 - 6 * t**2 + 3 * t**3) / 6, (1 + 3 * t + 3 * t**2 - 3 * t**3) / 6, t**3 / 6]


DERING_RATIO = (32.0, 128.0)
"""Local contrast max/min (R_1, R_2) over which the final filter hands over from the clamped
B-spline to bilinear (:func:`hdr_weight`). R_1 lies above the 22.5 : 1 of the calibration
checkerboard (0.9 and 0.04 albedo), so the calibration check runs on the B-spline alone; HDR
emitters (250–1000 × diffuse white in the demo) are far beyond R_2."""


def hdr_weight(color: np.ndarray) -> np.ndarray:
    r"""Per source pixel, how much of the final filter is bilinear (float64 (h, w) in [0, 1]): over
    the 5 × 5 neighbourhood (edge repeated) of the channel sum :math:`S = R + G + B` (of the
    one plane given), with its least value lo and largest hi,

    .. math::

        w = \operatorname{clamp}\Big(\frac{hi - R_1\,lo}{(R_2 - R_1)\,lo}, 0, 1\Big)
        \quad (lo > 0), \qquad 1 \text{ where } lo \le 0 < hi - lo, \ 0 \text{ where } hi = lo \le 0

    (:data:`DERING_RATIO`). 5 × 5: the bilinear interpolation of w over an output pixel's 2 × 2
    cell reaches 1 wherever a high-contrast sample lies inside the 4 × 4 support of the B-spline.
    One weight for all channels (a per-channel weight costs three times the work; the clamp of
    :func:`resample` is per channel either way)."""
    from scipy.ndimage import maximum_filter, minimum_filter

    r1, r2 = DERING_RATIO
    color = np.asarray(color, np.float64)
    total = color.sum(axis=-1) if color.ndim == 3 else color
    lo = minimum_filter(total, 5, mode="nearest")
    hi = maximum_filter(total, 5, mode="nearest")
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(lo > 0, np.clip((hi - r1 * lo) / ((r2 - r1) * lo), 0.0, 1.0), (hi > lo).astype(np.float64))


def resample(plane: np.ndarray, m: np.ndarray, filt: int, hdr: np.ndarray | None = None) -> np.ndarray:
    r"""float64 oracle of the kernels: ``plane`` (h, w) sampled at the map ``m`` (2, H, W), edge
    repeated beyond the plane; ``filt`` 1 bilinear, 3 the final filter: cubic B-spline
    interpolation s (scipy's ``map_coordinates(order=3, mode="nearest")``, an independent
    implementation) made HDR-safe,

    .. math::

        v = (1 - t)\,\operatorname{clamp}(s, lo, hi) + t\,b

    with lo, hi the least and largest of the 2 × 2 samples around the position, b their bilinear
    interpolation and t the bilinear interpolation of :func:`hdr_weight` of the source extended by
    its edge (``hdr``: of the whole colour image padded by 1 pixel; by default of ``plane`` alone). The clamp is the anti-ringing clamp of
    libplacebo's ``antiring`` (and of the neighbourhood clamp in temporal AA, Karis, "High Quality
    Temporal Supersampling", SIGGRAPH 2014 course): no output below the least or above the largest
    sample of its cell, so no dark ring or negative value around a highlight. The clamp alone
    keeps the B-spline's main lobe, 1.2–1.44 × the energy of a one-pixel highlight (its negative
    lobes clamped away); bilinear preserves it exactly, hence the hand-over by contrast
    (measurements: docs/distortion_calibration.md#hdr-safe-final-filter)."""
    sx, sy = m
    ok = sx > -1e29
    sx, sy = np.where(ok, sx, 0.0), np.where(ok, sy, 0.0)
    x0, y0 = np.floor(sx), np.floor(sy)
    tx, ty = sx - x0, sy - y0
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)

    def bilinear(p, o=0):  # o: the padding of p
        a, b = _taps(p, x0 + o, y0 + o), _taps(p, x0 + 1 + o, y0 + o)
        d, e = _taps(p, x0 + o, y0 + 1 + o), _taps(p, x0 + 1 + o, y0 + 1 + o)
        return (a * (1 - tx) + b * tx) * (1 - ty) + (d * (1 - tx) + e * tx) * ty, (a, b, d, e)

    lin, cell = bilinear(plane)
    if filt == 1:
        v = lin
    else:
        from scipy.ndimage import map_coordinates

        s = map_coordinates(plane, [sy, sx], order=3, mode="nearest")
        lo, hi = np.minimum.reduce(cell), np.maximum.reduce(cell)
        # the weight of the edge-extended source (1 pixel around it: cell corners lie in [-1, size])
        hdr = hdr_weight(np.pad(plane, 1, mode="edge")) if hdr is None else hdr
        t = bilinear(hdr, 1)[0]
        v = (1.0 - t) * np.clip(s, lo, hi) + t * lin
    return np.where(ok, v, 0.0)


@lru_cache(maxsize=4)
def tap_table(model: OpenCVModel, src_size: tuple[int, int],
              src_k: tuple[float, float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The per-pixel taps of ``distortion_table`` (kernels/distortion.cl, the final filter): the
    index of the top-left tap in a coefficient plane padded by :data:`PAD` with row pitch
    :func:`coef_pitch` (int32, −1 where there is no preimage) and the B-spline weights (float32 (10, H, W): 4 horizontal,
    4 vertical, then the fractions x − ⌊x⌋, y − ⌊y⌋ that weigh the 2 × 2 cell of :func:`resample`).
    Positions are the float32 map the reference also samples; the weights are computed from them in
    float64. Valid positions lie in [−½, size − ½], so the 4×4 window stays inside the padding."""
    sw, sh = src_size
    m, ok = distortion_map(model, src_size, src_k)
    m = np.where(ok, m.astype(np.float32).astype(np.float64), 0.0)
    fx, fy = np.floor(m[0]), np.floor(m[1])
    bx, by = fx.astype(np.int64) - 1 + PAD, fy.astype(np.int64) - 1 + PAD
    base = np.where(ok, by * coef_pitch(sw) + bx, -1).astype(np.int32)
    w = np.stack(bspline3(m[0] - fx) + bspline3(m[1] - fy) + [m[0] - fx, m[1] - fy])
    w = np.where(ok, w, 0.0).astype(np.float32)
    for a in (base, w):
        a.setflags(write=False)
    return base, w


class Distortion(GatherStage):
    name = "distortion"
    order = 50.0
    role = "resampling from the undistorted render into the distorted image"
    domains = ("render", "image")
    params = DistortionParams

    def __init__(self, quality: str = "final") -> None:
        super().__init__(quality)
        self._dev_maps: dict = {}

    @property
    def filter_taps(self) -> int:
        """1: bilinear (draft, preview); 3: cubic B-spline interpolation (final)."""
        return 3 if self.quality == "final" else 1

    def _calibration(self, camera) -> OpenCVModel | None:
        return getattr(camera, "distortion", None)

    def _source_k(self, camera, frame) -> tuple[float, float, float, float]:
        return source_intrinsics(self._calibration(camera), frame)

    def _model(self, camera, frame) -> OpenCVModel:
        """The model the map is made of: the calibration, magnified by :func:`crop_scale` under
        ``--fill crop``."""
        model = self._calibration(camera)
        if getattr(camera, "fill", "overscan") != "crop":
            return model
        return _scaled(model, crop_scale(model, frame.size, self._source_k(camera, frame)))

    def skip_reason(self, camera, frame):
        model = self._calibration(camera)
        if model is None:
            return "no distortion model (Camera.distortion / --calibration)"
        k = self._source_k(camera, frame)
        if model.is_identity and not isinstance(k, CubemapSpec) and frame.size == (model.width, model.height) and np.allclose(
                k, (model.fx, model.fy, model.cx, model.cy), rtol=0, atol=1e-9):
            return "all distortion coefficients are 0 and the render already has the calibration's intrinsics"
        return None

    def reason_needed(self, camera, frame):
        model = self._calibration(camera)
        m, ok = self._host_map(camera, frame)
        nz = ", ".join(f"{n}={getattr(model, n):.4g}" for n in model.coeff_names[:5] if getattr(model, n))
        from ..calibration.model import FAMILY_TITLES

        return (f"{FAMILY_TITLES[model.distortion_model]} model {nz or '(intrinsics only)'} → "
                f"{model.width}x{model.height}, "
                f"{'cubic B-spline' if self.filter_taps == 3 else 'bilinear'}; {self.coverage(camera, frame)}; "
                f"{int((~ok).sum())} pixel(s) without data (alpha 0)")

    def coverage(self, camera, frame) -> str:
        """One line: the overscan the calibration needs, what the frame has, and the fill."""
        model = self._calibration(camera)
        need = overscan_px(model)
        fill = getattr(camera, "fill", "overscan")
        have = frame.windows.overscan
        text = (f"needs {'/'.join(map(str, need))} px overscan (left/top/right/bottom) at the calibration's K, "
                f"the frame has {'/'.join(map(str, have))}")
        if fill == "crop":
            text += f"; --fill crop magnifies x{crop_scale(model, frame.size, self._source_k(camera, frame)):.6g}"
        else:
            text += f"; --fill {fill}"
        return text

    def _host_map(self, camera, frame):
        return distortion_map(self._model(camera, frame), frame.size, self._source_k(camera, frame))

    def _warn_unfilled(self, camera, frame) -> None:
        """The one-line warning of ``--fill overscan`` when the render leaves pixels black."""
        if getattr(camera, "fill", "overscan") != "overscan" or isinstance(self._source_k(camera, frame), CubemapSpec):
            return  # a cubemap holds every ray: its pixels without data are the ones without a ray
        _, ok = self._host_map(camera, frame)
        missing = int(ok.size - np.count_nonzero(ok))
        if missing:
            import warnings

            model = self._calibration(camera)
            left, top, right, bottom = overscan_px(model)
            warnings.warn(
                f"distortion: {missing} output pixel(s) have no data in the {frame.width}x{frame.height} render "
                f"(black, alpha 0): render with {left}/{top}/{right}/{bottom} px of overscan (left/top/right/"
                f"bottom; clpost render-size --calibration/--lens says how), or pass --fill crop (magnify to "
                "fill) or --fill border (keep the border)", stacklevel=2)

    def output_size(self, camera, frame) -> tuple[int, int]:
        model = self._calibration(camera)
        return model.width, model.height

    def defines(self, camera):
        return {}  # both filters live in one program; the quality picks the kernels

    def taps_per_pixel(self, camera, frame) -> int:
        """Source samples read per output pixel, all three channels (``clpost bench`` taps/s)."""
        return 3 * (self.filter_taps + 1) ** 2

    def enqueue(self, rt, camera, frame, src, dst, aux):
        import pyopencl as cl

        from ..runtime import kernel_source

        model = self._model(camera, frame)
        kkey = self._source_k(camera, frame)
        bspline = self.filter_taps == 3
        sw, sh = frame.size
        pw, ph = coef_pitch(sw), -(-(sh + 2 * PAD) // FIR_ROWS) * FIR_ROWS  # coefficient planes
        th = ph + 2 * FIR_K  # the row pass's planes: the column FIR reads K rows beyond
        if bspline and 3 * max(pw * th, model.width * model.height) >= 2**31:
            raise InputError(f"distortion: {sw}x{sh} is too large for the final filter's 32-bit tap "
                             "indices; use --quality preview (bilinear)")
        key = (id(rt.context), model, frame.size, kkey, self.filter_taps)  # buffers belong to a context
        bufs = self._dev_maps.get(key)
        if bufs is None:
            self._warn_unfilled(camera, frame)  # once per map (a sequence), not per frame
            if bspline:  # the tap table, the map, the two tile lists, then scratch for the coefficients
                host = (*tap_table(model, frame.size, kkey),
                        np.ascontiguousarray(self._host_map(camera, frame)[0], dtype=np.float32),
                        *bspline_tiles(model, frame.size, kkey))
            else:  # the map and the two tile lists
                host = (np.ascontiguousarray(self._host_map(camera, frame)[0], dtype=np.float32),
                        *bilinear_tiles(model, frame.size, kkey))
            bufs = tuple(rt.empty(a.shape, a.dtype) for a in host)
            for b, a in zip(bufs, host):
                cl.enqueue_copy(rt.queue, b, np.ascontiguousarray(a))
            if bspline:  # coefficients, the row pass's planes, the hand-over weight
                bufs += (rt.empty((3, ph, pw)), rt.empty((3, th, pw)), rt.empty((ph, pw)))
            self._dev_maps = {key: bufs}  # one camera and size at a time: the map is static
        source = kernel_source("common") + kernel_source("distortion")

        def kernel(name):  # built once per device, one kernel object per name (not per frame)
            return rt.kernel(source, name, {}, "distortion")

        out = (np.int32(model.width), np.int32(model.height))
        if not bspline:
            tiles, rest = bilinear_tiles(model, frame.size, kkey)
            events = []
            if len(tiles):  # one row of TILE_GROUP tiles per work-group, as the final filter's gather
                events.append(rt.launch(kernel("distortion_tiles"), (TILE, len(tiles)), (1, TILE_GROUP), src, dst,
                                        bufs[0], bufs[1], np.int32(sw), np.int32(sh), *out, np.int32(len(tiles))))
            if len(rest):
                events.append(rt.launch(kernel("distortion_rest"), (TILE, TILE, len(rest)), None, src, dst, bufs[0],
                                        bufs[2], np.int32(sw), np.int32(sh), *out))
            return events
        base, wts, fmap, tiles_b, rest_b, coef, tmp, hdr = bufs
        tiles, rest = bspline_tiles(model, frame.size, kkey)
        # the CPU's 16-lane kernels, or their one-pixel forms on a GPU (kernels/distortion.cl says
        # why; the same operations per pixel): rows of 64 work-items, a tile per work-group
        wide = rt.wide
        sfx, per, group, plane = ("", 16, None, None) if wide else ("1", 1, (64, 1, 1), (64, 1))
        rows, cols = kernel("distortion_fir_rows" + sfx), kernel("distortion_fir_cols" + sfx)
        dering = kernel("distortion_dering" + sfx)
        col_rows = FIR_ROWS if wide else 1
        events = [rt.launch(rows, (pw // per, th, 3), group, src, tmp, np.int32(sw), np.int32(sh), np.int32(pw),
                            np.int32(th)),
                  rt.launch(cols, (pw // per, ph // col_rows, 3), group, tmp, coef, np.int32(pw), np.int32(th),
                            np.int32(ph)),
                  rt.launch(dering, (pw // per, ph // col_rows), plane, src, hdr, np.int32(sw), np.int32(sh),
                            np.int32(pw), np.int32(ph))]
        if len(tiles):
            tile_args = (coef, dst, fmap, tiles_b, hdr, np.int32(pw), np.int32(ph), *out, np.int32(len(tiles)))
            if wide:
                events.append(rt.launch(kernel("distortion_bspline_tiles"), (TILE, len(tiles)), (1, TILE_GROUP),
                                        *tile_args))
            else:
                events.append(rt.launch(kernel("distortion_bspline_tiles1"), (TILE, TILE, len(tiles)),
                                        (TILE, TILE, 1), *tile_args))
        if len(rest):
            kern = kernel("distortion_table")
            events.append(rt.launch(kern, (TILE, TILE, len(rest)), None, coef, dst, base, wts, rest_b, hdr,
                                    np.int32(pw), np.int32(ph), *out))
        return events

    def reference(self, camera, frame, color):
        m, _ = self._host_map(camera, frame)
        m = m.astype(np.float32).astype(np.float64)  # the device's map, to compare filters alone
        hdr = hdr_weight(np.pad(color[..., :3], ((1, 1), (1, 1), (0, 0)), mode="edge")) if self.filter_taps == 3 else None
        return np.stack([resample(np.asarray(color[..., c], np.float64), m, self.filter_taps, hdr)
                         for c in range(3)], -1)

    def replay_key(self, camera, frame):
        # a coverage (alpha) input is resampled on the host from the frame's pixels, and label
        # planes are uploaded from the frame's dict (a recording replays only its named arrays):
        # not replayable
        return None if frame.alpha is not None or frame.labels else super().replay_key(camera, frame)

    def enqueue_host_buffers(self, rt, camera, frame, aux) -> tuple[dict, list]:
        """:meth:`host_buffers` computed on the device (kernel ``distortion_aux``): depth and
        velocity are gathered there and downloaded without blocking into fresh arrays, which the
        plan's final (blocking) download completes; the map's static tables are uploaded once."""
        from ..runtime import kernel_source

        if frame.alpha is not None:  # a coverage input is resampled bilinearly on the host
            return self.host_buffers(camera, frame), []
        model = self._model(camera, frame)
        kkey = self._source_k(camera, frame)
        g = _map_geometry(model, frame.size, kkey)
        out: dict = {"alpha": g.alpha}
        key = ("distortion_aux", model, frame.size, kkey)
        flat = rt.constant(lambda: _aux_flat(g), key=key + ("flat",))
        label_events = self._enqueue_labels(rt, frame, flat, g.alpha.shape, out)
        if frame.depth is None and frame.velocity is None:
            return out, label_events
        h, w = g.alpha.shape
        n = w * h
        jinv = rt.constant(lambda: np.ascontiguousarray(g.inv, np.float32), key=key + ("jinv",))
        events, dev = [], {}
        for name, shape in (("depth", (frame.height, frame.width)), ("velocity", (frame.height, frame.width, 2))):
            host = getattr(frame, name)
            dev[name + "_out"] = rt.scratch(self, f"aux_out_{name}", (h, w) + shape[2:] if host is not None else (1,))
            if host is not None and name in aux and aux[name].size == host.nbytes:
                dev[name] = aux[name]  # the plan uploaded it for an earlier stage: not again
                continue
            dev[name] = rt.scratch(self, f"aux_in_{name}", shape if host is not None else (1,))
            if host is not None:
                events.append(("upload", rt.copy(dev[name], host)))
        kern = rt.kernel(kernel_source("common") + kernel_source("distortion"), "distortion_aux", {}, "distortion")
        events.append((self.name + "_aux", rt.launch(kern, (n,), (64,), dev["depth"], dev["velocity"], flat, jinv,
                                            dev["depth_out"], dev["velocity_out"], np.int32(n),
                                            np.int32(frame.depth is not None), np.int32(frame.velocity is not None))))
        if frame.depth is not None:
            out["depth"] = rt.host_array("depth", (h, w), np.float32)
            events.append(("download", rt.copy(out["depth"], dev["depth_out"])))
        if frame.velocity is not None:
            out["velocity"] = rt.host_array("velocity", (h, w, 2), np.float32)
            events.append(("download", rt.copy(out["velocity"], dev["velocity_out"])))
        return out, label_events + events

    def _enqueue_labels(self, rt, frame, flat, size_hw, out: dict) -> list:
        """The frame's label planes through ``distortion_labels`` (32-bit words, nearest source
        pixel ``flat``), downloaded without blocking into ``out["labels"]``; [] without labels."""
        if not frame.labels:
            return []
        from ..runtime import kernel_source

        names = list(frame.labels)
        h, w = size_hw
        n, n_src = w * h, frame.width * frame.height
        host_in = np.stack([np.ascontiguousarray(frame.labels[k]).view(np.uint32) for k in names])
        src = rt.scratch(self, "labels_in", host_in.shape, np.uint32)
        dst = rt.scratch(self, "labels_out", (len(names), h, w), np.uint32)
        host_out = np.empty((len(names), h, w), np.uint32)
        kern = rt.kernel(kernel_source("distortion_labels"), "distortion_labels", {}, "distortion_labels")
        events = [("upload", rt.copy(src, host_in)),
                  (self.name + "_labels", rt.launch(kern, (n, len(names)), (64, 1), src, dst, flat, np.int32(n),
                                                    np.int32(n_src))),
                  ("download", rt.copy(host_out, dst))]
        out["labels"] = {k: host_out[i].view(frame.labels[k].dtype) for i, k in enumerate(names)}
        return events

    def aux_bytes(self, camera, frame) -> int:
        """Bytes ``distortion_aux`` moves (``clpost bench``): per output pixel its index and
        inverse Jacobian, and depth and velocity read and written."""
        model = self._calibration(camera)
        n = model.width * model.height
        return n * (4 + 16 + (8 if frame.depth is not None else 0) + (16 if frame.velocity is not None else 0))

    def host_buffers(self, camera, frame) -> dict:
        """alpha, depth and velocity of the distorted image (see the module docstring)."""
        model = self._model(camera, frame)
        m, ok = self._host_map(camera, frame)
        g = _map_geometry(model, frame.size, self._source_k(camera, frame))
        alpha = g.alpha
        if frame.alpha is not None:
            alpha = alpha * np.clip(resample(frame.alpha.astype(np.float64), m, 1), 0.0, 1.0).astype(np.float32)
        out = {"alpha": alpha}
        # flat np.take with a cached index: faster than 2-D fancy indexing
        # (docs/measurements.md#host-work)
        if frame.depth is not None:
            d = np.ascontiguousarray(frame.depth, np.float32).ravel().take(g.flat)
            d.ravel()[g.invalid] = np.inf
            out["depth"] = d
        if frame.velocity is not None:
            vin = np.ascontiguousarray(frame.velocity).reshape(-1, 2).take(g.flat, axis=0).astype(np.float64)
            vx = g.inv[0] * vin[..., 0] + g.inv[1] * vin[..., 1]
            vy = g.inv[2] * vin[..., 0] + g.inv[3] * vin[..., 1]
            out["velocity"] = np.stack([np.where(ok, vx, 0.0), np.where(ok, vy, 0.0)], -1).astype(np.float32)
        if frame.labels:
            from ..labels.channels import nearest_labels

            out["labels"] = nearest_labels(frame.labels, g.flat, ok)
        return out

