r"""Lens prescriptions: load ``lens_data/<name>.toml``, validate, and give indices at any wavelength.

File format (TOML, millimetres; documented in ``lens_data/README.md``): top-level ``name``,
``description``, ``units = "mm"``, nominal ``focal_length_mm`` and ``f_number`` (maximum
aperture), ``f_number_min_aperture``, ``min_focus_m`` (from the film plane), a ``[provenance]``
table (``source``, ``dataset``, ``notes``), optional ``[reference]`` / ``[published]`` focal
lengths, and one ``[[surface]]`` per surface from object to image side:

====================  ==========================================================================
key                   meaning
====================  ==========================================================================
``radius_mm``         radius of curvature; 0 or ±inf = plane; > 0: centre of curvature on the film side
``thickness_mm``      axial distance to the next surface (last surface: to the film at infinity focus)
``n_d``               refractive index of the medium after the surface at 587.5618 nm (air = 1)
``V_d``               Abbe number of that medium (omit for air or when unknown: no dispersion)
``semi_diameter_mm``  clear semi-diameter (for the stop: its fully open semi-diameter)
``stop``              ``true`` on the aperture stop (exactly one surface)
``coating``           optional: ``"none"`` (bare), ``"mgf2"`` (quarter-wave MgF₂ at 550 nm, the
                      default on air–glass surfaces) or ``{index = n, thickness_nm = d}`` (ghosts)
====================  ==========================================================================

Dispersion: a two-term Cauchy fit through n_d and the principal dispersion implied by V_d,

.. math::

    n(\lambda) = A + \frac{B}{\lambda^2},\qquad
    B = \frac{(n_d - 1)/V_d}{\lambda_F^{-2} - \lambda_C^{-2}},\qquad A = n_d - \frac{B}{\lambda_d^2}

with the Fraunhofer lines F = 486.1327 nm, d = 587.5618 nm, C = 656.2725 nm, so that
:math:`V_d = (n_d - 1)/(n_F - n_C)` holds exactly (the formula of the reference tables,
``shared/reference/lenses/README.md``). It matches Schott's Sellmeier N-BK7 / N-BAF10 / SF10 to
about 1e-4 across 450–700 nm. Media without ``V_d`` have a constant index.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..errors import InputError

LAMBDA_F_NM = 486.1327
LAMBDA_D_NM = 587.5618
LAMBDA_C_NM = 656.2725


def lens_data_dir() -> Path:
    """``clpost/lens_data`` in a wheel, ``<repo>/lens_data`` in a source checkout."""
    here = Path(__file__).resolve().parent.parent
    for cand in (here / "lens_data", here.parent / "lens_data"):
        if cand.is_dir():
            return cand
    raise InputError(f"clpost's lens_data directory was not found beside {here}; reinstall clpost")


def available_lenses() -> list[str]:
    """Names of the lenses in ``lens_data/`` (sorted)."""
    return sorted(p.stem for p in lens_data_dir().glob("*.toml"))


def cauchy_coefficients(n_d: float, v_d: float | None) -> tuple[float, float]:
    """(A, B[nm²]) of :math:`n = A + B/\\lambda^2` through n_d with n_F − n_C = (n_d − 1)/V_d."""
    if v_d is None or n_d == 1.0:
        return n_d, 0.0
    b = (n_d - 1.0) / v_d / (LAMBDA_F_NM ** -2 - LAMBDA_C_NM ** -2)
    return n_d - b / LAMBDA_D_NM ** 2, b


@dataclass(frozen=True)
class Surface:
    radius_mm: float  # math.inf for a plane
    thickness_mm: float
    n_d: float
    v_d: float | None
    semi_diameter_mm: float
    stop: bool = False
    coating: tuple[float, float] | None = None
    """(layer index, thickness nm) of a single-layer coating from the lens file; None: the
    default of :func:`clpost.optics.ghosts.surface_coating`."""

    @property
    def curvature(self) -> float:
        """c = 1/R in 1/mm (0 for a plane)."""
        return 0.0 if math.isinf(self.radius_mm) else 1.0 / self.radius_mm

    def sag(self, h: float) -> float:
        """Axial sag (mm) of the surface at height h (h ≤ |R|)."""
        c = self.curvature
        return c * h * h / (1.0 + math.sqrt(max(0.0, 1.0 - c * c * h * h)))


@dataclass(frozen=True)
class Prescription:
    """A validated lens: surfaces in order from object to image side. Lengths in mm."""

    name: str
    description: str
    surfaces: tuple[Surface, ...]
    focal_length_mm: float
    f_number: float
    f_number_min_aperture: float
    min_focus_m: float
    provenance: dict
    reference: dict = field(default_factory=dict)
    published: dict = field(default_factory=dict)
    path: str = ""

    @property
    def stop_index(self) -> int:
        return next(i for i, s in enumerate(self.surfaces) if s.stop)

    @property
    def has_dispersion(self) -> bool:
        return any(s.v_d is not None for s in self.surfaces)

    @property
    def vertex_z(self) -> np.ndarray:
        """z (mm) of each surface vertex, surface 1 at 0."""
        t = np.array([s.thickness_mm for s in self.surfaces])
        return np.concatenate([[0.0], np.cumsum(t[:-1])])

    @property
    def total_track_mm(self) -> float:
        """First vertex to last vertex (mm)."""
        return float(self.vertex_z[-1])

    def indices(self, wavelength_nm: float) -> np.ndarray:
        """Index of the medium after each surface at ``wavelength_nm`` (object space is air)."""
        lam = float(wavelength_nm)
        out = []
        for s in self.surfaces:
            a, b = cauchy_coefficients(s.n_d, s.v_d)
            out.append(a + b / (lam * lam))
        return np.array(out)

    def with_stop_semi_diameter(self, r: float) -> "Prescription":
        """A copy whose stop is ``r`` mm (stopped down)."""
        from dataclasses import replace

        surfs = list(self.surfaces)
        i = self.stop_index
        surfs[i] = replace(surfs[i], semi_diameter_mm=float(r))
        return replace(self, surfaces=tuple(surfs))

    def with_back_distance(self, b: float) -> "Prescription":
        """A copy whose last thickness (last vertex → film) is ``b`` mm."""
        from dataclasses import replace

        surfs = list(self.surfaces)
        surfs[-1] = replace(surfs[-1], thickness_mm=float(b))
        return replace(self, surfaces=tuple(surfs))


_NUM_FIELDS = ("radius_mm", "thickness_mm", "n_d", "semi_diameter_mm")


def _num(where: str, key: str, value, fix: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{where}: field '{key}' = {value!r} is not a number; {fix}")
    return float(value)


def _coating(where: str, value) -> tuple[float, float] | None:
    """A surface's ``coating`` field as (layer index, thickness nm), or None (not given)."""
    if value is None:
        return None
    if value == "none":
        return (1.0, 0.0)
    if value == "mgf2":
        return (1.38, 550.0 / (4 * 1.38))
    if isinstance(value, dict) and set(value) == {"index", "thickness_nm"}:
        n = _num(where, "coating.index", value["index"], "the layer's refractive index, e.g. 1.38")
        d = _num(where, "coating.thickness_nm", value["thickness_nm"], "the layer's thickness in nm, e.g. 99.6")
        if math.isfinite(n) and n >= 1.0 and math.isfinite(d) and d >= 0.0:
            return (n, d)
    raise InputError(f"{where}: field 'coating' = {value!r} must be \"none\", \"mgf2\" or "
                     "{index = <n >= 1>, thickness_nm = <d >= 0>}")


def parse_prescription(data: dict, path: str) -> Prescription:
    """Validate a decoded lens file; every error names the file, the surface and the field."""
    for key in ("name", "focal_length_mm", "f_number", "surface", "provenance"):
        if key not in data:
            raise InputError(f"{path}: missing top-level field '{key}' (see lens_data/README.md)")
    if data.get("units", "mm") != "mm":
        raise InputError(f"{path}: field 'units' = {data['units']!r}; only \"mm\" is supported")
    prov = data["provenance"]
    if not isinstance(prov, dict) or not prov.get("source"):
        raise InputError(f"{path}: [provenance] needs a 'source' (patent, publication or dataset path)")
    raw = data["surface"]
    if not isinstance(raw, list) or len(raw) < 2:
        raise InputError(f"{path}: needs at least two [[surface]] entries")
    surfaces = []
    for i, s in enumerate(raw, 1):
        where = f"{path}: surface {i}"
        for key in _NUM_FIELDS:
            if key not in s:
                raise InputError(f"{where}: missing field '{key}'")
        r = _num(where, "radius_mm", s["radius_mm"], "use 0 for a plane")
        t = _num(where, "thickness_mm", s["thickness_mm"], "axial distance to the next surface in mm")
        n = _num(where, "n_d", s["n_d"], "refractive index at 587.6 nm (air = 1)")
        sd = _num(where, "semi_diameter_mm", s["semi_diameter_mm"], "clear semi-diameter in mm")
        v = s.get("V_d")
        if v is not None:
            v = _num(where, "V_d", v, "Abbe number, e.g. 64.17 for N-BK7; omit for air")
            if not (math.isfinite(v) and v > 0):
                raise InputError(f"{where}: field 'V_d' = {v!r} must be > 0 (omit it for no dispersion)")
        if math.isnan(r):
            raise InputError(f"{where}: field 'radius_mm' is NaN; use 0 for a plane")
        if r == 0.0:
            r = math.inf
        if not (math.isfinite(t) and t >= 0):
            raise InputError(f"{where}: field 'thickness_mm' = {t!r} must be finite and >= 0")
        if not (math.isfinite(n) and n >= 1.0):
            raise InputError(f"{where}: field 'n_d' = {n!r} must be >= 1 (air = 1)")
        if not (math.isfinite(sd) and sd > 0):
            raise InputError(f"{where}: field 'semi_diameter_mm' = {sd!r} must be > 0")
        if sd > abs(r):
            raise InputError(f"{where}: field 'semi_diameter_mm' = {sd:g} exceeds |radius_mm| = {abs(r):g}; "
                             "a sphere has no surface beyond its radius")
        stop = s.get("stop", False)
        if not isinstance(stop, bool):
            raise InputError(f"{where}: field 'stop' = {stop!r} must be true or false")
        if stop and not math.isinf(r):
            raise InputError(f"{where}: the stop must be a plane (radius_mm = 0)")
        surfaces.append(Surface(r, t, n, v, sd, stop, _coating(where, s.get("coating"))))
    stops = [i for i, s in enumerate(surfaces, 1) if s.stop]
    if len(stops) != 1:
        raise InputError(f"{path}: {'no surface is' if not stops else f'surfaces {stops} are'} marked "
                         "'stop = true'; mark exactly one (the aperture stop, radius_mm = 0)")
    if surfaces[-1].n_d != 1.0:
        raise InputError(f"{path}: surface {len(surfaces)}: field 'n_d' must be 1 (the film is in air)")
    if surfaces[-1].thickness_mm <= 0:
        raise InputError(f"{path}: surface {len(surfaces)}: field 'thickness_mm' must be > 0 "
                         "(distance from the last surface to the film at infinity focus)")
    # Neighbouring surfaces must not cross inside their common clear aperture (edge thickness >= 0).
    for i in range(len(surfaces) - 1):
        a, b = surfaces[i], surfaces[i + 1]
        for h in np.linspace(0.0, min(a.semi_diameter_mm, b.semi_diameter_mm), 9)[1:]:
            gap = a.thickness_mm + b.sag(h) - a.sag(h)
            if gap < -1e-9:
                raise InputError(
                    f"{path}: surfaces {i + 1} and {i + 2} intersect at height {h:.3g} mm "
                    f"(edge gap {gap:.3g} mm): reduce field 'semi_diameter_mm' or increase 'thickness_mm'")
    fl = _num(path, "focal_length_mm", data["focal_length_mm"], "nominal focal length in mm")
    fn = _num(path, "f_number", data["f_number"], "nominal maximum aperture, e.g. 1.4")
    fmin = _num(path, "f_number_min_aperture", data.get("f_number_min_aperture", 22.0), "e.g. 16")
    mfd = _num(path, "min_focus_m", data.get("min_focus_m", 0.0), "closest focus in metres from the film")
    if not (fl > 0 and fn > 0 and fmin >= fn and mfd >= 0):
        raise InputError(f"{path}: need focal_length_mm > 0, 0 < f_number <= f_number_min_aperture, "
                         "min_focus_m >= 0")
    return Prescription(
        name=str(data["name"]), description=str(data.get("description", "")),
        surfaces=tuple(surfaces), focal_length_mm=fl, f_number=fn, f_number_min_aperture=fmin,
        min_focus_m=mfd, provenance=dict(prov), reference=dict(data.get("reference", {})),
        published=dict(data.get("published", {})), path=str(path))


def load_prescription_file(path: str | Path) -> Prescription:
    """Load and validate one lens file (TOML)."""
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text())
    except FileNotFoundError:
        raise InputError(f"{p}: lens file does not exist") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{p}: not valid TOML ({exc})") from None
    return parse_prescription(data, str(p))


@lru_cache(maxsize=None)
def load_prescription(name: str) -> Prescription:
    """The prescription called ``name`` in ``lens_data/`` (lowercase-hyphen names)."""
    path = lens_data_dir() / f"{name}.toml"
    if not path.is_file():
        raise InputError(f"lens {name!r} is unknown: use a thin lens 'thin:<focal length mm>' (e.g. 'thin:50') "
                         f"or one of lens_data/: {', '.join(available_lenses())}")
    return load_prescription_file(path)
