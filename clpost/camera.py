r"""The camera: lens, aperture, focus, shutter, sensor — validated at creation.

A lens is a thin lens named ``thin:<focal length in mm>`` or a real prescription from
``lens_data/`` by name (``zeiss-planar-50-f1.4``; see :mod:`clpost.optics`).

Units: lengths on the sensor and of the lens in millimetres, scene distances in metres, time in
seconds. ``focus_distance_m`` is measured from the thin lens's principal plane (``math.inf`` for
infinity focus); for a real prescription it is measured **from the film plane** and must be at
least the lens's ``min_focus_m``.

Real prescriptions (issue "real lenses"): ``focal_length_mm`` is the paraxial EFL;
``image_distance_mm`` is the thin-lens-equivalent v = EFL + extension, where the extension is
the lens travel found by real-ray unit focusing at the taking f-number
(:meth:`clpost.optics.Lens.focus`); an ``f_number`` below the lens's maximum aperture is clamped
to it with a :class:`clpost.optics.FNumberClampedWarning`. :attr:`Camera.optics` is the
:class:`clpost.optics.Lens` (None for a thin lens) and :meth:`Camera.lens_curves` its curves at
this focus and f-number — the API later stages consume.

Derived optics (thin lens, Hecht, *Optics*, 5th ed., §5.2):

.. math::

    \frac{1}{u} + \frac{1}{v} = \frac{1}{f}
    \qquad
    \text{FOV} = 2\arctan\frac{K}{2f}

with u the focus distance, v the image distance, K the sensor extent along the direction of the
field of view (the FOV formula is the one for focus at infinity, as lens datasheets quote it;
:attr:`Camera.field_of_view_focused_deg` uses v instead of f).

Image aspect: the image spans the full sensor **width**; the pixel pitch is
``sensor_width_mm / width_px`` and the used sensor height is ``pitch · height_px`` (Blender's
"horizontal" sensor fit), so square pixels at any resolution.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

from .errors import InputError

METERING_MODES = ("average", "centre", "spot")


def _finite(name: str, value: Any, unit: str, fix: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"Camera.{name}={value!r} is not a number ({unit}); {fix}") from None
    if not math.isfinite(v):
        raise InputError(f"Camera.{name}={value!r} must be finite ({unit}); {fix}")
    return v


def parse_lens(name: str) -> float:
    """Focal length in mm of a lens name: ``thin:<mm>``, or the EFL of a ``lens_data`` prescription."""
    if isinstance(name, str) and not name.startswith("thin:") and _is_lens_data(name):
        from .optics import get_lens

        return get_lens(name).efl_mm
    if not isinstance(name, str) or not name.startswith("thin:"):
        raise InputError(
            f"Camera.lens={name!r} is unknown: use a thin lens 'thin:<focal length mm>', e.g. 'thin:50', "
            f"or a lens_data name ({', '.join(_lens_data_names())}; see `clpost lens list`)"
        )
    try:
        f = float(name[5:])
    except ValueError:
        raise InputError(f"Camera.lens={name!r}: focal length after 'thin:' must be a number of mm, e.g. 'thin:50'") from None
    if not (math.isfinite(f) and f > 0):
        raise InputError(f"Camera.lens={name!r}: focal length must be > 0 mm, e.g. 'thin:50'")
    return f


def _lens_data_names() -> list[str]:
    from .optics.prescription import available_lenses

    return available_lenses()


def _is_lens_data(name: str) -> bool:
    from .optics.prescription import lens_data_dir

    return (lens_data_dir() / f"{name}.toml").is_file()


@dataclass(frozen=True)
class Camera:
    """A physical camera. All fields carry their unit in the name or docstring.

    ``f_number`` or ``shutter_s`` may be ``None``: the missing one is chosen per frame by the
    reflected-light meter (aperture priority when ``shutter_s`` is None, shutter priority when
    ``f_number`` is None), see :mod:`clpost.metering`. With both given the camera is manual.
    """

    lens: str = "thin:50"
    f_number: float | None = 2.0
    focus_distance_m: float = 3.0
    shutter_s: float | None = 1 / 50
    iso: float = 100.0
    transmittance: float = 0.9
    """T in (0, 1]: fraction of light the glass passes (a multi-coated lens ≈ 0.9)."""
    sensor_mm: tuple[float, float] = (36.0, 24.0)
    luminance_scale: float = 1.0
    """cd/m² of input Y = 1 (maps a renderer's arbitrary units to photometric luminance)."""
    blades: int = 0
    """Aperture blades; 0 is a round aperture."""
    blade_rotation_deg: float = 0.0
    metering: str = "average"
    exposure_compensation_ev: float = 0.0
    distortion: Any = None
    """distortion stage: a :class:`clpost.calibration.OpenCVModel` (OpenCV standard model, e.g.
    from ``--calibration cam.yaml``); None = no distortion."""
    vignetting: str = "off"
    """vignetting stage: ``off``, ``natural`` (cos⁴θ of the thin lens), ``lens`` (the traced
    relative-illumination curve of ``lens``) or ``table:<path>`` (manufacturer-style table)."""
    # motion_blur stage: the frame rate turns px-per-frame velocities into a blur over the
    # shutter (fraction shutter_s × fps); None (default) leaves motion blur unmodelled.
    frame_rate_fps: float | None = None
    """Frames per second of the sequence (e.g. 24); with ``shutter_s`` it gives the open fraction."""
    readout_time_s: float = 0.0
    """Rolling shutter: time from reading the top row to the bottom row (s); 0 = global shutter."""
    # -- recording medium (stages film, grain, print, sensor) -----------------------------------
    film: str | None = None
    """Film stock name (``clpost.film_stock.stock_names()``) or stock .toml path; None: no film."""
    film_output: str = "print"
    """Negative film's output: 'print' (display-referred paper print), 'linear' (re-linearised
    scene-linear), 'negative' (the developed densities themselves)."""
    grain_scale: float = 1.0
    """Multiplier on the stock's grain radius; 0 turns grain off (grain stage)."""
    sensor_preset: str | None = None
    """Digital sensor preset (``clpost.stages.sensor.SENSOR_PRESETS``); None: no sensor stage."""
    noise_seed: int = 0
    """Seed of the grain and sensor noise (with the frame index, CONVENTIONS "Randomness")."""
    working_space: str = "rec709"
    """Linear RGB working space of the input: 'rec709' (default) or 'acescg'."""
    # -- dof stage (clpost/stages/dof.py); defaults keep the pinhole image (stage not planned) --
    depth_of_field: bool = False
    """dof: True renders the thin lens's defocus from the depth buffer; False keeps the pinhole."""
    aperture_roundness: float = 0.0
    """dof: 0 = straight blades (polygon), 1 = circle; corners stay on the f/N circle."""
    spherical_aberration: float = 0.0
    """dof: bokeh texture in [-1, 1]; > 0 undercorrected (near: bright rim, far: bright core)."""
    optical_vignetting: float = 0.0
    """dof: cat's-eye strength in [0, 1]: barrel-clip displacement in aperture radii at the corner."""
    # astigmatism / coma / lateral_color stages: parametric third-order aberrations (mm on the
    # film at the sensor's half diagonal) for a lens without a prescription. None (default) takes
    # them from the traced lens (a lens_data lens) or leaves them out (thin lens: passthrough);
    # a number replaces the traced curve (0 turns the effect off).
    field_curvature_mm: float | None = None
    """Mean of the sagittal and tangential focal offsets at the image corner (mm, + = behind the film)."""
    astigmatism_mm: float | None = None
    """Tangential minus sagittal focal offset at the image corner (mm)."""
    coma_mm: float | None = None
    """Length of the comet (tangential coma, 3C) at the image corner (mm; + = tail away from the centre)."""
    lateral_color_mm: float | None = None
    """Chief-ray height at F (486.1 nm) minus at C (656.3 nm) at the image corner (mm)."""
    # distortion stage, traced lenses: without a calibration (``distortion``), a lens_data lens
    # distorts by its traced curve (:func:`clpost.calibration.lens_distortion_model`).
    lens_distortion: bool = True
    """distortion: a lens_data lens without a calibration distorts by its traced curve; False = not."""

    def __post_init__(self) -> None:
        parse_lens(self.lens)
        if self.f_number is None and self.shutter_s is None:
            raise InputError(
                "Camera: f_number and shutter_s are both unset; give one (--f-number or --shutter) "
                "and the meter picks the other"
            )
        if self.f_number is not None:
            n = _finite("f_number", self.f_number, "f-number N = f/D", "e.g. 2.8")
            if n <= 0:
                raise InputError(f"Camera.f_number={self.f_number!r} must be > 0 (f/0.7 … f/64 are typical)")
            object.__setattr__(self, "f_number", n)
        if self.shutter_s is not None:
            t = _finite("shutter_s", self.shutter_s, "seconds", "e.g. 0.02 for 1/50 s")
            if t <= 0:
                raise InputError(f"Camera.shutter_s={self.shutter_s!r} must be > 0 seconds, e.g. 0.02 for 1/50 s")
            object.__setattr__(self, "shutter_s", t)
        u = float(self.focus_distance_m)
        if math.isnan(u) or u <= self.focal_length_mm / 1000.0:
            raise InputError(
                f"Camera.focus_distance_m={self.focus_distance_m!r} must be beyond the focal length "
                f"({self.focal_length_mm / 1000:g} m) — a real image needs u > f; use inf for infinity focus"
            )
        object.__setattr__(self, "focus_distance_m", u)
        iso = _finite("iso", self.iso, "ISO 12232 speed S", "e.g. 100")
        if iso <= 0:
            raise InputError(f"Camera.iso={self.iso!r} must be > 0, e.g. 100")
        object.__setattr__(self, "iso", iso)
        tr = _finite("transmittance", self.transmittance, "fraction", "e.g. 0.9")
        if not 0 < tr <= 1:
            raise InputError(f"Camera.transmittance={self.transmittance!r} must be in (0, 1], e.g. 0.9")
        object.__setattr__(self, "transmittance", tr)
        try:
            sw, sh = (float(s) for s in self.sensor_mm)
        except (TypeError, ValueError):
            raise InputError(f"Camera.sensor_mm={self.sensor_mm!r} must be (width, height) in mm, e.g. (36, 24)") from None
        if not (math.isfinite(sw) and math.isfinite(sh) and sw > 0 and sh > 0):
            raise InputError(f"Camera.sensor_mm={self.sensor_mm!r} must be two positive mm values, e.g. (36, 24)")
        object.__setattr__(self, "sensor_mm", (sw, sh))
        ls = _finite("luminance_scale", self.luminance_scale, "cd/m² per unit Y", "e.g. 100")
        if ls <= 0:
            raise InputError(f"Camera.luminance_scale={self.luminance_scale!r} must be > 0 cd/m² per unit Y")
        object.__setattr__(self, "luminance_scale", ls)
        if int(self.blades) != self.blades or self.blades < 0 or self.blades in (1, 2):
            raise InputError(f"Camera.blades={self.blades!r} must be 0 (round) or an integer >= 3")
        object.__setattr__(self, "blades", int(self.blades))
        _finite("blade_rotation_deg", self.blade_rotation_deg, "degrees", "e.g. 0")
        if self.metering not in METERING_MODES:
            raise InputError(f"Camera.metering={self.metering!r} must be one of {', '.join(METERING_MODES)}")
        _finite("exposure_compensation_ev", self.exposure_compensation_ev, "EV", "e.g. +1 for one stop brighter")
        # Real lenses (issue "real lenses"): clamp the f-number to the lens, check min focus.
        lens = self.optics
        if lens is not None:
            if self.f_number is not None:
                object.__setattr__(self, "f_number", lens.clamp_f_number(self.f_number))
            if self.focus_distance_m * 1000.0 < lens.min_focus_m * 1000.0 * (1 - 1e-12):
                raise InputError(
                    f"Camera.focus_distance_m={self.focus_distance_m!r} is closer than {self.lens}'s minimum "
                    f"focus distance {lens.min_focus_m:g} m (measured from the film plane); use >= {lens.min_focus_m:g}")
        # distortion stage
        if self.distortion is not None:
            from .calibration import OpenCVModel

            if not isinstance(self.distortion, OpenCVModel):
                raise InputError(f"Camera.distortion must be a clpost.calibration.OpenCVModel or None, not "
                                 f"{type(self.distortion).__name__}; load one with load_calibration('cam.yaml')")
        # vignetting stage
        v = self.vignetting
        if not isinstance(v, str) or not (v in ("off", "natural", "lens") or (v.startswith("table:") and len(v) > 6)):
            raise InputError(f"Camera.vignetting={v!r} must be 'off', 'natural', 'lens' or 'table:<path>'")
        # motion_blur stage
        if self.frame_rate_fps is not None:
            fps = _finite("frame_rate_fps", self.frame_rate_fps, "frames per second", "e.g. 24")
            if fps <= 0:
                raise InputError(f"Camera.frame_rate_fps={self.frame_rate_fps!r} must be > 0 frames per second, e.g. 24")
            object.__setattr__(self, "frame_rate_fps", fps)
        ro = _finite("readout_time_s", self.readout_time_s, "seconds", "e.g. 0.01 for a 10 ms sensor readout")
        if ro < 0:
            raise InputError(f"Camera.readout_time_s={self.readout_time_s!r} must be >= 0 seconds (0 = global shutter)")
        if ro > 0 and self.frame_rate_fps is None:
            raise InputError("Camera.readout_time_s > 0 needs Camera.frame_rate_fps (--fps) to turn "
                             "px-per-frame velocities into a per-row shift")
        object.__setattr__(self, "readout_time_s", ro)
        if (self.frame_rate_fps is not None and self.shutter_s is not None
                and self.shutter_s * self.frame_rate_fps > 1.0 + 1e-9):
            raise InputError(f"Camera.shutter_s={self.shutter_s:g} s is longer than one frame interval at "
                             f"{self.frame_rate_fps:g} fps (a 360° shutter is {1 / self.frame_rate_fps:.4g} s); "
                             "use a shorter --shutter or --shutter-angle <= 360")

        # film / grain / print / sensor stages: one recording medium per camera.
        if self.film is not None and self.sensor_preset is not None:
            raise InputError(f"Camera: film={self.film!r} and sensor_preset={self.sensor_preset!r} are both "
                             "set; a camera records on one medium — give --film or --sensor-preset, not both")
        if self.film is not None:
            from .film_stock import load_stock

            load_stock(self.film)
        if self.film_output not in ("print", "linear", "negative"):
            raise InputError(f"Camera.film_output={self.film_output!r} must be 'print', 'linear' or 'negative'")
        gs = _finite("grain_scale", self.grain_scale, "× the stock's grain radius", "e.g. 1, or 0 for no grain")
        if gs < 0:
            raise InputError(f"Camera.grain_scale={self.grain_scale!r} must be >= 0 (0 turns grain off)")
        object.__setattr__(self, "grain_scale", gs)
        if self.sensor_preset is not None:
            from .stages.sensor import SENSOR_PRESETS

            if self.sensor_preset not in SENSOR_PRESETS:
                raise InputError(f"Camera.sensor_preset={self.sensor_preset!r} is unknown: use one of "
                                 f"{', '.join(SENSOR_PRESETS)}")
        if int(self.noise_seed) != self.noise_seed or not 0 <= int(self.noise_seed) < 2**32:
            raise InputError(f"Camera.noise_seed={self.noise_seed!r} must be an integer in [0, 2**32)")
        object.__setattr__(self, "noise_seed", int(self.noise_seed))
        if self.working_space not in ("rec709", "acescg"):
            raise InputError(f"Camera.working_space={self.working_space!r} must be 'rec709' or 'acescg'")
        # dof stage fields
        if not isinstance(self.depth_of_field, (bool, int)):
            raise InputError(f"Camera.depth_of_field={self.depth_of_field!r} must be True or False")
        object.__setattr__(self, "depth_of_field", bool(self.depth_of_field))
        for name, lo, hi, eg in (("aperture_roundness", 0.0, 1.0, "0 (polygon) … 1 (circle)"),
                                 ("spherical_aberration", -1.0, 1.0, "0.5 (undercorrected) or -0.5"),
                                 ("optical_vignetting", 0.0, 1.0, "0.5 for visible cat's-eye bokeh")):
            v = _finite(name, getattr(self, name), "unitless", f"e.g. {eg}")
            if not lo <= v <= hi:
                raise InputError(f"Camera.{name}={v!r} must be in [{lo:g}, {hi:g}], e.g. {eg}")
            object.__setattr__(self, name, v)
        # astigmatism / coma / lateral_color stages
        for name in ("field_curvature_mm", "astigmatism_mm", "coma_mm", "lateral_color_mm"):
            val = getattr(self, name)
            if val is not None:
                object.__setattr__(self, name, _finite(name, val, "mm on the film at the image corner",
                                                       "e.g. 0.1, or 0 to turn the effect off"))
        if not isinstance(self.lens_distortion, (bool, int)):
            raise InputError(f"Camera.lens_distortion={self.lens_distortion!r} must be True or False")
        object.__setattr__(self, "lens_distortion", bool(self.lens_distortion))

    # -- derived quantities -------------------------------------------------------------------
    @property
    def focal_length_mm(self) -> float:
        return parse_lens(self.lens)

    @property
    def image_distance_mm(self) -> float:
        r"""Lens-to-film distance v (mm) for the focus distance: :math:`v = 1/(1/f - 1/u)`."""
        lens = self.optics
        if lens is not None:
            # Real lens: v = EFL + extension from real-ray unit focusing (u from the film plane).
            return lens.focus(self.focus_distance_m * 1000.0, self.f_number).image_distance_mm
        f = self.focal_length_mm
        u = self.focus_distance_m * 1000.0
        if math.isinf(u):
            return f
        return f * u / (u - f)

    @property
    def optics(self):
        """The :class:`clpost.optics.Lens` of a ``lens_data`` lens, None for a thin lens."""
        if self.lens.startswith("thin:"):
            return None
        from .optics import get_lens

        return get_lens(self.lens)

    def lens_curves(self):
        """:class:`clpost.optics.curves.LensCurves` at this focus and f-number (None for a thin
        lens); cached per (lens, focus, f-number). Auto f-number: the lens wide open."""
        lens = self.optics
        if lens is None:
            return None
        return lens.curves(self.focus_distance_m, self.f_number)

    @property
    def focused_depth_m(self) -> float:
        r"""Planar scene depth (m, from the camera centre) that is imaged sharply: the thin-lens
        conjugate of the image distance, :math:`u = f v / (v - f)`.

        For a thin lens this is ``focus_distance_m`` itself. For a traced lens,
        ``focus_distance_m`` is measured from the film plane (CONVENTIONS) and the real-ray focus
        sets v; its thin-lens equivalent (measured from the front principal plane, which the
        pinhole render's centre stands for) is what the CoC of every stage uses, so dof and
        astigmatism agree on the sharp plane.
        """
        if self.optics is None:
            return self.focus_distance_m
        f, v = self.focal_length_mm, self.image_distance_mm
        return math.inf if v <= f else f * v / (v - f) / 1000.0

    @property
    def is_auto_exposure(self) -> bool:
        return self.f_number is None or self.shutter_s is None

    def field_of_view_deg(self, extent_mm: float | None = None) -> float:
        r"""Angle of view :math:`2\arctan(K/2f)` in degrees for sensor extent K (default: width)."""
        k = self.sensor_mm[0] if extent_mm is None else extent_mm
        return math.degrees(2 * math.atan(k / (2 * self.focal_length_mm)))

    @property
    def field_of_view_focused_deg(self) -> float:
        r"""Horizontal angle of view with the lens focused at u: :math:`2\arctan(K/2v)`."""
        return math.degrees(2 * math.atan(self.sensor_mm[0] / (2 * self.image_distance_mm)))

    def pixel_pitch_mm(self, width_px: int) -> float:
        """Pixel pitch (mm) when the image is ``width_px`` wide (the image spans the sensor width)."""
        return self.sensor_mm[0] / float(width_px)

    def intrinsics(self, width_px: int, height_px: int) -> tuple[float, float, float, float]:
        r"""Pinhole intrinsics ``(f_x, f_y, c_x, c_y)`` in pixels (OpenCV convention).

        :math:`f_x = f_y = v / p` with v the image distance (the lens focused at u) and p the
        pixel pitch; the principal point is the image centre ``((W-1)/2, (H-1)/2)`` because pixel
        centres are at integer coordinates (CONVENTIONS.md).
        """
        f_px = self.image_distance_mm / self.pixel_pitch_mm(width_px)
        return f_px, f_px, (width_px - 1) / 2.0, (height_px - 1) / 2.0

    def default_resolution(self, width_px: int) -> tuple[int, int]:
        """(width, height) with the sensor's aspect ratio, height rounded to an even number."""
        h = int(round(width_px * self.sensor_mm[1] / self.sensor_mm[0] / 2)) * 2
        return width_px, max(h, 2)

    def with_(self, **changes: Any) -> "Camera":
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def describe(self) -> dict[str, str]:
        """The parameters as strings (written into output EXR headers)."""
        return {
            "clpost.lens": self.lens,
            "clpost.focalLength_mm": f"{self.focal_length_mm:g}",
            "clpost.fNumber": "auto" if self.f_number is None else f"{self.f_number:g}",
            "clpost.focusDistance_m": f"{self.focus_distance_m:g}",
            "clpost.shutter_s": "auto" if self.shutter_s is None else f"{self.shutter_s:g}",
            "clpost.iso": f"{self.iso:g}",
            "clpost.transmittance": f"{self.transmittance:g}",
            "clpost.sensor_mm": f"{self.sensor_mm[0]:g}x{self.sensor_mm[1]:g}",
            "clpost.luminanceScale": f"{self.luminance_scale:g}",
            "clpost.blades": str(self.blades),
            "clpost.bladeRotation_deg": f"{self.blade_rotation_deg:g}",
            "clpost.metering": self.metering,
            "clpost.exposureCompensation_ev": f"{self.exposure_compensation_ev:g}",
            # distortion / vignetting stages: recorded only when in use
            **({"clpost.distortion": " ".join(f"{t:.9g}" for t in (
                self.distortion.width, self.distortion.height, self.distortion.fx, self.distortion.fy,
                self.distortion.cx, self.distortion.cy, *self.distortion.vector()))}
               if self.distortion is not None else {}),
            **({"clpost.vignetting": self.vignetting} if self.vignetting != "off" else {}),
            "clpost.film": self.film or "none",
            "clpost.filmOutput": self.film_output,
            "clpost.grainScale": f"{self.grain_scale:g}",
            "clpost.sensorPreset": self.sensor_preset or "none",
            "clpost.noiseSeed": str(self.noise_seed),
            "clpost.workingSpace": self.working_space,
            "clpost.depthOfField": str(self.depth_of_field),
            "clpost.apertureRoundness": f"{self.aperture_roundness:g}",
            "clpost.sphericalAberration": f"{self.spherical_aberration:g}",
            "clpost.opticalVignetting": f"{self.optical_vignetting:g}",
            # astigmatism / coma / lateral_color stages: parametric coefficients when given
            **{f"clpost.{k}": f"{getattr(self, k):g}" for k in
               ("field_curvature_mm", "astigmatism_mm", "coma_mm", "lateral_color_mm") if getattr(self, k) is not None},
        }
