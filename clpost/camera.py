r"""The camera: lens, aperture, focus, shutter, sensor — validated at creation.

A lens is a thin lens named ``thin:<focal length in mm>`` or a real prescription from
``lens_data/`` by name (``zeiss-planar-50-f1.4``; see :mod:`clpost.optics`).

Units: lengths on the sensor and of the lens in millimetres, scene distances in metres, time in
seconds. ``focus_distance_m`` is the **planar depth that is sharp, measured like the depth pass**:
along the optical axis from the render's pinhole, which stands for the thin lens itself and for a
real prescription's entrance pupil (the centre of projection of its chief rays), for thin and
traced lenses alike (``math.inf`` for infinity focus). The lens-scale distance, film plane →
object as engraved on a focus ring, is :attr:`Camera.focus_from_film_m`; giving ``focus_scale_m=``
instead of ``focus_distance_m`` converts it exactly (a real lens must reach the scale distance:
at least its ``min_focus_m``). docs/conventions.md "Focus".

Real prescriptions: ``focal_length_mm`` is the paraxial EFL;
``image_distance_mm`` is the thin-lens-equivalent v = EFL + extension, where the extension is
the lens travel found by real-ray unit focusing at the taking f-number
(:meth:`clpost.optics.Lens.focus_depth`); an ``f_number`` below the lens's maximum aperture is clamped
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
:attr:`Camera.field_of_view_focused_deg` uses the focused camera's focal length instead of f).

Focus breathing: :attr:`Camera.render_focal_length_mm` is the focal length of the pinhole camera
that images like the lens at this focus — v for a thin lens (image scale v/f of infinity focus),
for a real lens the film height K of the paraxial chief ray per tan θ of its object-side angle
(:attr:`clpost.optics.FocusState.render_focal_mm`; its distortion curve is the real chief ray's
departure from K tan θ). :meth:`Camera.intrinsics` uses it: render with them and the plate has
the field of view the lens has at this focus.

Image aspect: the image spans the full sensor **width**; the pixel pitch is
``sensor_width_mm / width_px`` and the used sensor height is ``pitch · height_px`` (Blender's
"horizontal" sensor fit), so square pixels at any resolution.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, replace
from typing import Any, Mapping

from .errors import InputError
from .params import (META_KEY, ParamSpec, in_range, integer, one_of, param, parse_auto_or_fraction,
                     parse_fraction, parse_wxh_mm, positive, show_auto, specs_of, to_float)


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


_LENS_DATA_FOUND: set[str] = set()  # names found once (get_lens keeps them for the process, too)


def _is_lens_data(name: str) -> bool:
    if name in _LENS_DATA_FOUND:  # a camera is validated per frame (the meter): no file system look-up
        return True
    from .optics.prescription import lens_data_dir

    found = (lens_data_dir() / f"{name}.toml").is_file()
    if found:
        _LENS_DATA_FOUND.add(name)
    return found


def _check_lens(name: str, value: Any) -> str:
    parse_lens(value)
    return value


def _check_sensor(name: str, value: Any) -> tuple[float, float]:
    try:
        sw, sh = (float(s) for s in value)
    except (TypeError, ValueError):
        raise InputError(f"Camera.{name}={value!r} must be (width, height) in mm, e.g. (36, 24)") from None
    if not (math.isfinite(sw) and math.isfinite(sh) and sw > 0 and sh > 0):
        raise InputError(f"Camera.{name}={value!r} must be two positive mm values, e.g. (36, 24)")
    return sw, sh


def _breathing():
    from . import breathing

    return breathing


def depth_for_focus_scale(camera, scale_m: Any) -> float:
    r"""The focus depth (m, from the pinhole) of a lens-scale distance L (film → object).

    Thin lens: L = u + v with 1/u + 1/v = 1/f gives :math:`u = (L + \sqrt{L^2 - 4Lf})/2` (the
    far conjugate; L ≥ 4f). Real lens: :meth:`clpost.optics.Lens.focus` at L, its ``depth_mm``."""
    L = to_float("focus_scale_m", scale_m, "m", "use inf for infinity focus")
    if math.isinf(L):
        return math.inf
    lens = camera.optics
    if lens is not None:
        if not (L >= lens.min_focus_m * (1 - 1e-12)):
            raise InputError(f"Camera.focus_scale_m={scale_m!r} is closer than {camera.lens}'s minimum focus "
                             f"distance {lens.min_focus_m:g} m (from the film plane); use >= {lens.min_focus_m:g}")
        return lens.focus(L * 1000.0, camera.f_number).depth_mm / 1000.0
    f = camera.focal_length_mm / 1000.0
    if not (L >= 4 * f):
        raise InputError(f"Camera.focus_scale_m={scale_m!r} is closer than a thin lens of {f * 1000:g} mm can "
                         f"focus (film to object >= 4f = {4 * f:g} m); use >= {4 * f:g}")
    return 0.5 * (L + math.sqrt(L * L - 4 * L * f))

DEFAULT_ISO = 100.0
"""ISO of a camera without film (with ``film``: the stock's box speed) when none is given."""


@dataclass(frozen=True)
class CoreParams:
    """The camera's own parameters, read by several stages (lens, aperture, focus, shutter, sensor)."""

    lens: str = param("thin:50", unit="lens name", flag="--lens", check=_check_lens, header="clpost.lens",
                      scalar=False, help="lens name: thin:<focal mm> (e.g. thin:50) or a lens_data name "
                                         "(`clpost lens list`)")
    f_number: float | None = param(
        2.0, unit="f-number N = f/D", flag="--f-number", parse=parse_auto_or_fraction, header="clpost.fNumber",
        show=show_auto, scalar=True, help="f-number N, or 'auto' (shutter priority)",
        check=positive("f-number N = f/D", "e.g. 2.8", optional=True,
                       message="Camera.{name}={value!r} must be > 0 (f/0.7 … f/64 are typical)"))
    focus_distance_m: float = param(
        3.0, unit="m", flag="--focus", parse=parse_fraction, header="clpost.focusDistance_m", scalar=True,
        check=lambda name, v: to_float(name, v, "m", "use inf for infinity focus"),
        help="depth in metres that is sharp, measured like the depth pass (planar, from the camera's "
             "pinhole = a real lens's entrance pupil); 'inf' for infinity. Lens-scale distance: --focus-scale")
    focus_scale_m: float | None = param(
        None, unit="m", flag="--focus-scale", parse=parse_fraction, scalar=True, input_only=True,
        help="focus by the lens's distance scale instead: metres from the film plane to the object, as engraved "
             "on a focus ring (sets --focus exactly; not with --focus)")
    plate_fov: str = param(
        "focused", unit="field of view", flag="--plate-fov", header="clpost.plateFov", scalar=False,
        check=one_of("focused", "infinity"), show=lambda v: None if v == "focused" else v,
        help="field of view the plate was rendered at: 'focused' (with the camera at this focus, Camera.intrinsics; "
             "--explain prints it) or 'infinity' (the lens focused at infinity, e.g. a renderer set to the lens's "
             "focal length: the plate is magnified by the focus breathing first, clpost.breathing)")
    shutter_s: float | None = param(
        1 / 50, unit="seconds", flag="--shutter", parse=parse_auto_or_fraction, header="clpost.shutter_s",
        show=show_auto, scalar=True, cli_default="1/50",
        check=positive("seconds", "e.g. 0.02 for 1/50 s", optional=True),
        help="shutter time in seconds (1/50 works), or 'auto' (aperture priority)")
    iso: float | None = param(None, unit="ISO 12232 speed S", flag="--iso", parse=parse_fraction, header="clpost.iso",
                              scalar=True, cli_default="100", show=lambda v: "box speed" if v is None else f"{v:g}",
                              help="ISO 12232 saturation-based speed; with --film, the stock's box speed "
                                   "unless given",
                              check=positive("ISO 12232 speed S", "e.g. 100", optional=True,
                                             message="Camera.{name}={value!r} must be > 0, e.g. 100"))
    transmittance: float = param(0.9, unit="fraction", flag="--transmittance", parse=parse_fraction,
                                 header="clpost.transmittance", scalar=True,
                                 check=in_range(0.0, 1.0, "fraction", "0.9", lo_open=True),
                                 help="lens transmittance T in (0, 1]: fraction of light the glass passes")
    sensor_mm: tuple[float, float] = param((36.0, 24.0), unit="mm", flag="--sensor", parse=parse_wxh_mm,
                                           header="clpost.sensor_mm", check=_check_sensor, scalar=False,
                                           help="sensor WxH in mm (e.g. 36x24)")
    luminance_scale: float | None = param(
        None, unit="cd/m² per unit Y", flag="--luminance-scale", parse=parse_fraction,
        header="clpost.luminanceScale", scalar=True, cli_default="none: passthrough, gain 1",
        help="cd/m² of input luminance Y = 1: exposes physically from f-number, shutter, ISO and T",
        check=positive("cd/m² per unit Y", "e.g. 100", optional=True,
                       message="Camera.{name}={value!r} must be > 0 cd/m² per unit Y"))
    working_space: str = param("rec709", unit="RGB space", flag="--working-space", header="clpost.workingSpace",
                               check=one_of("rec709", "acescg"), scalar=False,
                               help="linear RGB working space of the input: rec709 or acescg")
    noise_seed: int = param(0, unit="seed", flag="--noise-seed", parse=int, header="clpost.noiseSeed",
                            check=integer(0, 2**32, rule="an integer in [0, 2**32)"), scalar=True,
                            help="seed of the grain and sensor noise (with the frame index)")

    @staticmethod
    def check_options(camera, given) -> None:
        if "focus_distance_m" in given and "focus_scale_m" in given:
            raise InputError("--focus (depth from the camera, as the depth pass measures it) and --focus-scale "
                             "(distance from the film plane) set the same focus; give one of them")

    @staticmethod
    def validate(camera, inputs) -> None:
        scale = inputs.get("focus_scale_m")
        if scale is not None:  # the lens-scale distance names a focus depth (one internal state)
            object.__setattr__(camera, "focus_distance_m", depth_for_focus_scale(camera, scale))
        if camera.iso is None:  # a film is rated at its box speed unless an ISO is given
            # marked, so the header says "box speed" (a camera read back rates another film at its
            # own speed) and with_(film=…) rates the new stock
            object.__setattr__(camera, "iso_default", True)
            film = getattr(camera, "film", None)
            if film:
                from .film_stock import load_stock

                object.__setattr__(camera, "iso", float(load_stock(film).iso))
            else:
                object.__setattr__(camera, "iso", DEFAULT_ISO)
        if camera.f_number is None and camera.shutter_s is None:
            raise InputError(
                "Camera: f_number and shutter_s are both unset; give one (--f-number or --shutter) "
                "and the meter picks the other"
            )
        u = camera.focus_distance_m
        if math.isnan(u) or u <= camera.focal_length_mm / 1000.0:
            raise InputError(
                f"Camera.focus_distance_m={u!r} must be beyond the focal length "
                f"({camera.focal_length_mm / 1000:g} m) — a real image needs u > f; use inf for infinity focus"
            )
        # Real lenses: clamp the f-number to the lens, check min focus.
        lens = camera.optics
        if lens is not None:
            if camera.f_number is not None:
                object.__setattr__(camera, "f_number", lens.clamp_f_number(camera.f_number))
            d_min = lens.focus(lens.min_focus_m * 1000.0, camera.f_number).depth_mm / 1000.0
            if u < d_min * (1 - 1e-12):
                raise InputError(
                    f"Camera.focus_distance_m={u!r} is closer than {camera.lens}'s minimum focus distance "
                    f"{lens.min_focus_m:g} m on its scale (from the film), which is depth {d_min:.4g} m from the "
                    f"entrance pupil; use --focus >= {d_min:.4g} (or --focus-scale >= {lens.min_focus_m:g})")

    @staticmethod
    def extra_header(camera) -> dict[str, str]:
        out = {"clpost.focalLength_mm": f"{camera.focal_length_mm:g}"}
        if camera.__dict__.get("iso_default"):
            out["clpost.iso"] = "box speed"  # read back as unset: the default rule, not this number
        return out


class _CameraBase:
    """Derived quantities and the generated API of :class:`Camera` (fields: :meth:`param_specs`)."""

    _param_groups: tuple = ()
    _param_specs: tuple = ()
    _field_checks: tuple = ()
    _input_checks: tuple = ()
    _validators: tuple = ()

    # -- derived quantities -------------------------------------------------------------------
    @property
    def focal_length_mm(self) -> float:
        return parse_lens(self.lens)

    @property
    def focus_state(self):
        """The real lens's :class:`clpost.optics.FocusState` at this focus depth and f-number
        (unit focusing solved with real rays, cached on the lens); None for a thin lens."""
        lens = self.optics
        return None if lens is None else lens.focus_depth(self.focus_distance_m * 1000.0, self.f_number)

    @property
    def focus_from_film_m(self) -> float:
        """The lens-scale focus distance (m): film plane → sharp object, as a focus ring is engraved.
        Thin lens: u + v; real lens: from the unit-focusing solution."""
        st = self.focus_state
        if st is not None:
            return st.distance_mm / 1000.0
        u = self.focus_distance_m
        return math.inf if math.isinf(u) else u + self.image_distance_mm / 1000.0

    @property
    def render_focal_length_mm(self) -> float:
        """Focal length (mm) of the pinhole camera that images like the lens at this focus (module
        docstring, "Focus breathing"): v for a thin lens, K of the focus state for a real lens."""
        st = self.focus_state
        return self.image_distance_mm if st is None else st.render_focal_mm

    @property
    def image_distance_mm(self) -> float:
        r"""Lens-to-film distance v (mm) for the focus distance: :math:`v = 1/(1/f - 1/u)`."""
        st = self.focus_state
        if st is not None:
            # Real lens: v = EFL + extension from real-ray unit focusing.
            return st.image_distance_mm
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
        return lens.curves(self.focus_from_film_m, self.f_number)

    @property
    def focused_depth_m(self) -> float:
        """Planar scene depth (m, from the camera's pinhole) that is imaged sharply: the CoC of
        every stage is zero here. It is ``focus_distance_m`` for thin and real lenses alike (a real
        lens is focused by :meth:`clpost.optics.Lens.focus_depth` so that it is)."""
        return self.focus_distance_m

    @property
    def is_auto_exposure(self) -> bool:
        return self.f_number is None or self.shutter_s is None

    def field_of_view_deg(self, extent_mm: float | None = None) -> float:
        r"""Angle of view :math:`2\arctan(K/2f)` in degrees for sensor extent K (default: width)."""
        k = self.sensor_mm[0] if extent_mm is None else extent_mm
        return math.degrees(2 * math.atan(k / (2 * self.focal_length_mm)))

    @property
    def field_of_view_focused_deg(self) -> float:
        r"""Horizontal angle of view with the lens focused at u: :math:`2\arctan(K/2F)`, F the
        :attr:`render_focal_length_mm` (focus breathing)."""
        return math.degrees(2 * math.atan(self.sensor_mm[0] / (2 * self.render_focal_length_mm)))

    def focus_summary(self, width_px: int) -> str:
        """One line for ``--explain``: the focus depth, its lens-scale distance and the camera to
        render the plate with at this focus (focal length, f_x at ``width_px``, horizontal FOV)."""
        u, s = self.focus_distance_m, self.focus_from_film_m
        where = "entrance pupil" if self.optics is not None else "lens"
        return (f"focus: depth {u:.6g} m from the {where} (the depth pass's camera centre) = {s:.6g} m from the film "
                f"(lens scale); render with focal length {self.render_focal_length_mm:.6g} mm "
                f"(f_x {self.render_focal_length_mm / self.pixel_pitch_mm(width_px):.6g} px), "
                f"horizontal FOV {self.field_of_view_focused_deg:.4g}° (infinity focus: "
                f"{self.with_(focus_distance_m=math.inf).field_of_view_focused_deg:.4g}°)"
                + ("" if self.plate_fov == "focused" else
                   f"; the plate (--plate-fov {self.plate_fov}) is magnified ×{_breathing().magnification(self):.6g} first"))

    def pixel_pitch_mm(self, width_px: int) -> float:
        """Pixel pitch (mm) when the image is ``width_px`` wide (the image spans the sensor width)."""
        return self.sensor_mm[0] / float(width_px)

    def intrinsics(self, width_px: int, height_px: int) -> tuple[float, float, float, float]:
        r"""Pinhole intrinsics ``(f_x, f_y, c_x, c_y)`` in pixels (OpenCV convention).

        :math:`f_x = f_y = F / p` with F the :attr:`render_focal_length_mm` (the lens focused at
        u: v for a thin lens) and p the pixel pitch; the principal point is the image centre ``((W-1)/2, (H-1)/2)`` because pixel
        centres are at integer coordinates (CONVENTIONS.md).
        """
        f_px = self.render_focal_length_mm / self.pixel_pitch_mm(width_px)
        return f_px, f_px, (width_px - 1) / 2.0, (height_px - 1) / 2.0

    def default_resolution(self, width_px: int) -> tuple[int, int]:
        """(width, height) with the sensor's aspect ratio, height rounded to an even number."""
        h = int(round(width_px * self.sensor_mm[1] / self.sensor_mm[0] / 2)) * 2
        return width_px, max(h, 2)

    def with_(self, **changes: Any) -> "Camera":
        """A copy with some fields changed (validated again). A camera set by the meter
        (:func:`clpost.metering.resolve`) stays marked as such unless f-number or shutter change."""
        if self.__dict__.get("iso_default") and "iso" not in changes:
            changes = {**changes, "iso": None}  # still the default rule (another film: its box speed)
        cam = replace(self, **changes)
        if self.__dict__.get("metered") and not {"f_number", "shutter_s"} & changes.keys():
            object.__setattr__(cam, "metered", True)
        return cam

    def describe(self) -> dict[str, str]:
        """The parameters as strings (written into output EXR headers), from each parameter's
        ``header`` key; a value whose header text is None (unset / off) is omitted. Formatted
        once per camera (a plan records it on every frame)."""
        cached = self.__dict__.get("_described")
        if cached is not None:
            return dict(cached)
        out: dict[str, str] = {}
        for pcls, specs in self._param_groups:
            for s in specs:
                if s.meta.header is not None and not s.meta.input_only:
                    text = s.header_text(getattr(self, s.name))
                    if text is not None:
                        out[s.meta.header] = text
            extra = getattr(pcls, "extra_header", None)
            if extra is not None:
                out.update(extra(self))
        object.__setattr__(self, "_described", dict(out))
        return out

    @classmethod
    def param_specs(cls) -> tuple[ParamSpec, ...]:
        """Every parameter: name, owning stage (``"camera"`` for the core), default and metadata."""
        return cls._param_specs

    def structure_key(self) -> tuple:
        """The structural parameters as a hashable ``((name, value), ...)``: the values that choose
        programs, ``#define``s, stage tables and which stages exist; cache plans by it (with the
        frame size and quality). What the scalars change is per-frame work (:meth:`scalars`)."""
        return tuple((s.name, getattr(self, s.name)) for s in self._param_specs
                     if not s.meta.scalar and not s.meta.input_only)

    def scalars(self) -> dict[str, Any]:
        """The per-frame scalar parameters by name (they may change without rebuilding a plan)."""
        return {s.name: getattr(self, s.name) for s in self._param_specs if s.meta.scalar and not s.meta.input_only}

    def params(self, owner: str | type):
        """The params dataclass of a stage name (or ``"camera"``, or the class) filled from this camera."""
        for pcls, specs in self._param_groups:
            if owner is pcls or (specs and specs[0].owner == owner):
                return pcls(**{s.name: getattr(self, s.name) for s in specs if not s.meta.input_only})
        raise KeyError(f"no parameters declared by {owner!r}")

    @classmethod
    def from_options(cls, given: Mapping[str, Any], defaults: Mapping[str, Any] | None = None):
        """A camera from options a user gave (``given``) over ``defaults`` (e.g. the demo's), also
        checking each params class's ``check_options`` rules about the given names (the CLI's path)."""
        cam = cls(**{**(defaults or {}), **given})
        for pcls, _ in cls._param_groups:
            hook = getattr(pcls, "check_options", None)
            if hook is not None:
                hook(cam, frozenset(given))
        return cam


def _post_init(self, *input_values) -> None:
    """Validate every declared field (its ``check``), then each params class's ``validate`` rules."""
    cls = type(self)
    setattr_ = object.__setattr__
    for name, check in cls._field_checks:
        setattr_(self, name, check(name, getattr(self, name)))
    inputs = {}
    for (name, check), value in zip(cls._input_checks, input_values):
        inputs[name] = check(name, value) if check is not None and value is not None else value
    for hook in cls._validators:
        hook(self, inputs)


CAMERA_DOC = """A physical camera. All fields carry their unit in the name or their declaration.

    ``f_number`` or ``shutter_s`` may be ``None``: the missing one is chosen per frame by the
    reflected-light meter (aperture priority when ``shutter_s`` is None, shutter priority when
    ``f_number`` is None), see :mod:`clpost.metering`. With both given the camera is manual.

    The fields are the camera core's (:class:`CoreParams`) followed by each stage's declared
    parameters in physical order (``Stage.params``, :mod:`clpost.params`);
    :meth:`param_specs` lists them with their units and owners. Input-only parameters (e.g.
    ``shutter_angle_deg``) are accepted by the constructor and turned into stored fields.
    """


def build_camera_class(stages: Mapping[str, type] | None = None, name: str = "Camera") -> type:
    """The frozen dataclass composing :class:`CoreParams` and the ``params`` of ``stages``
    (default: the stage registry, in physical order)."""
    if stages is None:
        from .stages import registry

        stages = registry()
    groups = [(CoreParams, tuple(specs_of("camera", CoreParams)))]
    for stage_name, stage in stages.items():
        pcls = getattr(stage, "params", None)
        if pcls is not None:
            groups.append((pcls, tuple(specs_of(stage_name, pcls))))
    specs = tuple(s for _, group in groups for s in group)
    seen: dict[str, str] = {}
    for s in specs:
        if s.name in seen:
            raise TypeError(f"camera parameter {s.name!r} is declared by both {seen[s.name]} and {s.owner}")
        seen[s.name] = s.owner
    fields = [(s.name, dataclasses.InitVar[Any] if s.meta.input_only else s.type,
               dataclasses.field(default=s.default, metadata={META_KEY: s.meta}))
              for s in specs]
    namespace = {"__post_init__": _post_init, "__doc__": CAMERA_DOC, "__module__": __name__, "__qualname__": name,
                 "_param_groups": tuple(groups), "_param_specs": specs,
                 # precomputed for __post_init__ (a camera is built per frame by the meter)
                 "_field_checks": tuple((s.name, s.meta.check) for s in specs
                                        if s.meta.check is not None and not s.meta.input_only),
                 "_input_checks": tuple((s.name, s.meta.check) for s in specs if s.meta.input_only),
                 "_validators": tuple(h for pcls, _ in groups if (h := getattr(pcls, "validate", None)) is not None)}
    cls = dataclasses.make_dataclass(name, fields, bases=(_CameraBase,), namespace=namespace, frozen=True)
    cls.__module__, cls.__qualname__ = __name__, name
    return cls


Camera = build_camera_class()
