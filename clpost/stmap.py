r"""ST maps: a distortion model as an image that Nuke's STMap node (Resolve, Flame, Natron alike)
applies to a plate.

Convention (Nuke's STMap node): a map pixel holds the position its output pixel samples in the
source image of W × H pixels, normalised with the origin at the bottom-left corner:

.. math::

    R = s = \frac{x_\text{src} + 0.5}{W}, \qquad G = t = 1 - \frac{y_\text{src} + 0.5}{H}

with :math:`(x_\text{src}, y_\text{src})` in clpost's (OpenCV's) pixel coordinates — pixel centres
at integers, y down (``docs/conventions.md``); B = 0; all float32.

Two directions, both on the calibration's pixel grid (the undistorted image has the
calibration's own K, as ``cv2.initUndistortRectifyMap(K, D, None, K)`` makes it):

* **distort** (default): the map has the distorted image's size; each pixel (u, v) holds where the
  *undistorted* image is sampled, :math:`x_\text{src} = f_x x' + c_x`, :math:`y_\text{src} = f_y y' + c_y`
  with (x', y') the exact inverse of the model (:func:`clpost.calibration.undistort_newton`, the
  distortion stage's inverse, for every camera model family of docs/camera_models.md — a ray at or
  beyond 90° has no place in the undistorted image: alpha 0; always Newton, also for a model that asks
  the stage for Heikkilä's fit). Applied to an undistorted plate or a CG render it gives the lens's
  image. A render with overscan (its EXR data window beyond the display window, the size
  ``clpost render-size`` states) is sampled at s, t outside [0, 1].
* **undistort** (``--undistort``): each pixel (x, y) of the undistorted image holds where the
  *distorted* plate is sampled, :math:`(u, v) = \text{project}((x - c_x)/f_x, (y - c_y)/f_y)`
  (:meth:`clpost.calibration.OpenCVModel.project`, OpenCV's ``projectPoints``).

Domain (alpha, A): 1 where the sampled position lies inside the source image
([−0.5, W − 0.5] × [−0.5, H − 0.5], i.e. s, t in [0, 1]); 0 where it lies outside (no data
there without overscan) and where the pixel has no preimage at all — beyond the model's fold
radius (:meth:`~clpost.calibration.OpenCVModel.fold_radius`, two undistorted radii meet there) or
where Newton did not converge. Those pixels hold :data:`NO_PREIMAGE` in R and G.

Why the host and float64: the map is computed once per model and size (no per-frame work) and must
agree with OpenCV to 1e-3 px; the distortion stage's own map is the same float64 numpy computation
(:func:`clpost.stages.distortion.distortion_map`), and there is no device kernel for maps to reuse.
It runs in bands of rows so a 4K map needs ~0.5 GB, not several.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .calibration import OpenCVModel, undistort_newton
from .errors import InputError

NO_PREIMAGE = -1.0
"""R and G of a map pixel that has no preimage (alpha 0): far outside any source, so an STMap node
reads nothing (black) there."""

DIRECTIONS = ("distort", "undistort")

_BAND_ROWS = 128


def st_from_xy(x: np.ndarray, y: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel positions (OpenCV convention) in a ``width`` × ``height`` image → Nuke's (s, t)."""
    return (np.asarray(x, np.float64) + 0.5) / width, 1.0 - (np.asarray(y, np.float64) + 0.5) / height


def xy_from_st(s: np.ndarray, t: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`st_from_xy`."""
    return np.asarray(s, np.float64) * width - 0.5, (1.0 - np.asarray(t, np.float64)) * height - 0.5


def map_points(model: OpenCVModel, direction: str, x: np.ndarray, y: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where output positions (x, y) (pixels, float64) sample their source in ``direction``, and
    whether they have a preimage (module docstring); the map evaluated anywhere, not only at pixel
    centres."""
    if direction not in DIRECTIONS:
        raise InputError(f"STMap direction {direction!r} must be one of {', '.join(DIRECTIONS)}")
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    if direction == "distort":
        xn, yn, ok = undistort_newton(model, x, y)
        return model.fx * xn + model.cx, model.fy * yn + model.cy, ok
    xn, yn = (x - model.cx) / model.fx, (y - model.cy) / model.fy
    u, v = model.project(xn, yn)
    ok = (np.hypot(xn, yn) < model.fold_radius()) & np.isfinite(u) & np.isfinite(v)
    return np.where(ok, u, 0.0), np.where(ok, v, 0.0), ok


@dataclass(frozen=True)
class STMap:
    """An ST map: ``st`` (H, W, 2) float64 (s, t), ``alpha`` (H, W) float32, for ``model`` and ``direction``."""

    model: OpenCVModel
    direction: str
    st: np.ndarray
    alpha: np.ndarray

    def rgba(self) -> np.ndarray:
        """(H, W, 4) float32: R = s, G = t, B = 0, A = alpha."""
        h, w = self.alpha.shape
        out = np.zeros((h, w, 4), np.float32)
        out[..., :2] = self.st
        out[..., 3] = self.alpha
        return out

    def header(self) -> dict[str, str]:
        """The EXR header that says what the map is (source, size, direction, convention)."""
        from .calibration import header_text

        m = self.model
        what = ("each pixel of the distorted image -> where it samples the undistorted image"
                if self.direction == "distort" else
                "each pixel of the undistorted image -> where it samples the distorted plate")
        return {
            "clpost.stmap.direction": self.direction,
            "clpost.stmap.meaning": what,
            "clpost.stmap.size": f"{m.width}x{m.height}",
            "clpost.stmap.source": m.source or "OpenCVModel",
            "clpost.stmap.convention": ("Nuke STMap: R=s=(x+0.5)/W, G=t=1-(y+0.5)/H of the sampled source pixel "
                                        "(x, y) (pixel centres at integers, y down), origin bottom-left; A=1 inside "
                                        f"the source, 0 outside or without preimage (then R=G={NO_PREIMAGE:g})"),
            "clpost.distortion": header_text(m),
        }


def make_stmap(model: OpenCVModel, direction: str = "distort") -> STMap:
    """The ST map of ``model`` in ``direction`` (module docstring), float64."""
    w, h = model.width, model.height
    st = np.empty((h, w, 2), np.float64)
    alpha = np.empty((h, w), np.float32)
    for y0 in range(0, h, _BAND_ROWS):
        band = slice(y0, min(h, y0 + _BAND_ROWS))
        yy, xx = np.mgrid[band, 0:w].astype(np.float64)
        x, y, ok = map_points(model, direction, xx, yy)
        s, t = st_from_xy(x, y, w, h)
        st[band, :, 0] = np.where(ok, s, NO_PREIMAGE)
        st[band, :, 1] = np.where(ok, t, NO_PREIMAGE)
        inside = ok & (x >= -0.5) & (x <= w - 0.5) & (y >= -0.5) & (y <= h - 0.5)
        alpha[band] = inside
    return STMap(model, direction, st, alpha)


def write_stmap(path, stmap: STMap, compression: str = "zip") -> None:
    """Write the map as a float32 RGBA EXR with :meth:`STMap.header`, atomically."""
    from . import exr
    from .frame import Frame

    rgba = stmap.rgba()
    exr.write_frame(path, Frame(rgba[..., :3], alpha=rgba[..., 3]), header=stmap.header(), compression=compression)


# -- the command --------------------------------------------------------------------------------

CAMERA_FIELDS = ("distortion", "lens", "f_number", "focus_distance_m", "focus_scale_m", "sensor_mm",
                 "lens_distortion")
"""The camera options ``clpost stmap`` takes (the rest of a camera does not change the geometry)."""


def model_from_args(args, size: tuple[int, int] | None) -> OpenCVModel:
    """The distortion ``--calibration`` or a ``--lens``'s traced curve (at ``size``) gives."""
    from .calibration import lens_distortion_model
    from .camera import Camera

    cam = Camera.from_options({k[4:]: v for k, v in vars(args).items() if k.startswith("cam_")})
    if cam.distortion is not None:
        m = cam.distortion
        return m if size is None or tuple(size) == (m.width, m.height) else m.scaled_to(*size)
    if cam.optics is None:
        why = f"; {cam.lens} is a thin lens, distortion-free" if "cam_lens" in vars(args) else ""
        raise InputError(f"no distortion to map; give --calibration FILE or a real --lens NAME (`clpost lens list`){why}")
    if size is None:
        size = (1920, max(1, round(1920 * cam.sensor_mm[1] / cam.sensor_mm[0])))
    m = lens_distortion_model(cam, size)
    if m is None:
        raise InputError(f"--lens {cam.lens} has no distortion here (off by --lens-distortion, or "
                         "below 0.001 %): its STMap would be the identity")
    return m


def cmd_stmap(args) -> int:
    from pathlib import Path

    from .outputs import check_paths

    out = Path(args.output)
    if out.suffix.lower() != ".exr":
        raise InputError(f"-o {args.output}: an STMap is written as float32 EXR; name it .exr")
    calib = getattr(args, "cam_distortion", None)
    if calib is not None and calib.source:
        src = Path(calib.source.split("#")[0])
        check_paths([(src, out)], args.output)
    if out.exists() and not args.overwrite:
        raise InputError(f"-o {args.output}: exists; pass --overwrite to replace it")
    model = model_from_args(args, args.size)
    m = make_stmap(model, "undistort" if args.undistort else "distort")
    write_stmap(out, m)
    bad = int((m.alpha == 0).sum())
    print(f"wrote {out}: {m.direction} STMap {model.width}x{model.height} of {model.source or 'the model'}"
          + (f"; {bad} pixels outside the source or without preimage (alpha 0)" if bad else ""))
    return 0


def add_parser(sub, size, options) -> None:
    """Register ``clpost stmap`` on the CLI's subparsers; ``size`` parses WxH and ``options`` are the CLI's
    generated camera options (:func:`clpost.cli.camera_options`), handed in so this module does not import
    the CLI."""
    p = sub.add_parser(
        "stmap", help="write a Nuke-convention ST map (EXR) of a calibration's or lens's distortion",
        description="R = s = (x+0.5)/W, G = t = 1-(y+0.5)/H of the source position each pixel samples (origin "
                    "bottom-left), A = 1 where that lies inside the source. Default: the distort map (each "
                    "distorted pixel -> the undistorted image, for CG and undistorted plates); --undistort: the "
                    "reverse (each undistorted pixel -> the plate). Both on the calibration's pixel grid and K.")
    p.add_argument("-o", "--output", required=True, help="output EXR (float32 RGBA)")
    p.add_argument("--undistort", action="store_true",
                   help="the undistort map (plate -> undistorted image) instead of the distort map")
    p.add_argument("--size", type=size, default=None,
                   help="WIDTHxHEIGHT: the calibration scaled to this size (same aspect), or the traced lens's "
                        "image size (default: the calibration's; 1920 wide at the sensor's aspect for --lens)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")
    add_source_options(p, options)
    p.set_defaults(func=cmd_stmap)


def add_source_options(p, options) -> None:
    """``--calibration`` or ``--lens`` with the options that shape a traced lens's distortion."""
    import argparse

    g = p.add_argument_group("distortion source (--calibration, or --lens with its focus and f-number)")
    for flag, dest, typ, help_ in options:
        if dest in CAMERA_FIELDS:
            g.add_argument(flag, dest=f"cam_{dest}", type=typ, default=argparse.SUPPRESS, help=help_)
