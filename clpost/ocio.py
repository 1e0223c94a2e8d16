r"""OpenColorIO display/view transforms for previews and display-referred outputs.

clpost's physics stays in colour-science (spectral data, film, white balance); how a linear image
is *shown* comes from an OpenColorIO config, as in a studio pipeline:

- the config: ``--ocio-config`` (a ``config.ocio`` file or a built-in URI such as
  ``ocio://studio-config-latest``, ``ocio://cg-config-latest``, ``ocio://default`` — OCIO ≥ 2.5
  ships ACES 2.x display/view transforms in them), else ``$OCIO``; without either, clpost's own
  encodings (:data:`clpost.colorspace.DISPLAYS`) are used;
- the display, view and looks (``--display``, ``--ocio-view``, ``--look``) are names of that
  config (defaults: the config's default display and its default view; no extra look);
- the input colour space, in this order: ``--input-colorspace NAME`` (a colour space of the
  config), the ``chromaticities`` attribute of the input EXR, the camera's working space. A set of
  chromaticities (CIE xy of R, G, B and white) becomes the matrix
  :math:`M = M_{\rm sl}^{-1}\,\mathrm{CAT}_{\rm Bradford}(w \to D65)\,\mathrm{NPM}(r, g, b, w)`
  into the config's ``scene_linear`` role (NPM: SMPTE RP 177 normalised primary matrix, from
  colour-science; :math:`M_{\rm sl}` the config's own scene_linear → ``cie_xyz_d65_interchange``
  matrix, measured through OCIO). When the chromaticities are those of one of the config's linear
  colour spaces (its matrix to XYZ equal to :data:`MATCH_TOL`), that colour space is used by name,
  so the config's own conversion runs. The OCIO ACES configs convert between whites with Bradford
  too (measured: ACEScg → XYZ equal to colour-science's Bradford matrix to 1e-7).

The processor is ``input → [looks] → display/view`` (:class:`ocio.LegacyViewingPipeline`, what
OCIO's own tools use) and runs on the CPU through OCIO itself (:meth:`OcioView.encode`), so a
preview *is* OCIO's result (float32, checked to 1e-4 in ``tests/test_ocio.py``).

Tags: :func:`display_tags` identifies the display colour space of the (display, view) by
measuring it through OCIO (its code values → ``cie_xyz_d65_interchange`` against the primaries and
transfer functions of :data:`TAGGABLE`): SDR displays get the matching ICC profile
(:func:`clpost.display_image.icc_for`) and PNGs a cICP chunk (ITU-T H.273 code points), HDR ones
(PQ, HLG) the cICP chunk only (an ICC v2 profile cannot say PQ). A display that matches none is
written untagged, with a one-line warning.

References: OpenColorIO 2.x documentation (Config, DisplayViewTransform, LegacyViewingPipeline,
built-in configs); SMPTE RP 177-1993; ITU-T H.273 (cICP code points); PNG 3rd edition (cICP).
"""
from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .errors import InputError

MATCH_TOL = 1e-5
"""Largest difference between two RGB → XYZ matrices taken as the same colour space."""

BUILTIN_EXAMPLE = "ocio://studio-config-latest"


def _ocio():
    try:
        import PyOpenColorIO as ocio
    except ImportError:  # pragma: no cover
        raise InputError("OpenColorIO is not installed: pip install opencolorio (a clpost dependency)") from None
    return ocio


def config_spec(given: str | None) -> str | None:
    """The config to use: ``given`` (``--ocio-config``; ``none`` = clpost's own encodings), else
    ``$OCIO``, else None."""
    if given is not None:
        return None if given.strip().lower() == "none" else given
    env = os.environ.get("OCIO", "").strip()
    return env or None


@lru_cache(maxsize=8)
def load_config(spec: str):
    """The OCIO config of ``spec`` (a file or an ``ocio://`` URI), or InputError in one line."""
    ocio = _ocio()
    is_uri = spec.startswith("ocio://")
    if not is_uri and not os.path.isfile(spec):
        raise InputError(f"--ocio-config {spec}: no such file; give a config.ocio path or a built-in config "
                         f"such as {BUILTIN_EXAMPLE} (or --ocio-config none for clpost's own encodings)")
    try:
        config = ocio.Config.CreateFromFile(spec)
        config.validate()
    except Exception as e:  # OCIO raises its own Exception type with a multi-line text
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise InputError(f"--ocio-config {spec}: OpenColorIO cannot use it ({first}); give a valid config or "
                         f"a built-in one such as {BUILTIN_EXAMPLE}") from None
    return config


def _choice(what: str, flag: str, name: str, names: list[str], spec: str) -> str:
    if name in names:
        return name
    raise InputError(f"{flag} {name!r} is not a {what} of the OCIO config {spec}; use one of: "
                     + ", ".join(repr(n) for n in names))


# -- chromaticities ------------------------------------------------------------------------------

Chromaticities = tuple[float, float, float, float, float, float, float, float]
"""(x_r, y_r, x_g, y_g, x_b, y_b, x_w, y_w), as the OpenEXR ``chromaticities`` attribute."""


def file_chromaticities(path) -> Chromaticities | None:
    """The ``chromaticities`` attribute of an EXR's first part (None when absent or unreadable)."""
    if path is None:
        return None
    try:
        import OpenEXR

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            hdr = OpenEXR.File(str(path), header_only=True).header()
    except Exception:
        return None
    c = hdr.get("chromaticities")
    if c is None or len(c) != 8 or not all(math.isfinite(float(v)) for v in c):
        return None
    return tuple(float(v) for v in c)  # type: ignore[return-value]


def working_space_chromaticities(working_space: str) -> Chromaticities:
    """The chromaticities of a :data:`clpost.colorspace.WORKING_SPACES` space (colour-science)."""
    import colour

    from .colorspace import WORKING_SPACES

    if working_space not in WORKING_SPACES:
        raise InputError(f"working space {working_space!r} is unknown: use one of {', '.join(WORKING_SPACES)}")
    s = colour.RGB_COLOURSPACES[WORKING_SPACES[working_space]]
    return tuple(float(v) for v in (*np.ravel(s.primaries), *s.whitepoint))  # type: ignore[return-value]


def rgb_to_xyz_d65(chroma: Chromaticities) -> np.ndarray:
    r"""3×3 linear RGB → CIE XYZ (D65-adapted, Bradford) of a set of chromaticities:
    :math:`\mathrm{CAT}(w \to D65)\,\mathrm{NPM}` (colour-science)."""
    import colour

    c = np.asarray(chroma, dtype=np.float64)
    if c.shape != (8,) or not np.all(np.isfinite(c)):
        raise InputError(f"chromaticities {tuple(chroma)!r}: need 8 finite numbers (x, y of R, G, B, white)")
    prim, white = c[:6].reshape(3, 2), c[6:]
    try:
        npm = colour.normalised_primary_matrix(prim, white)
    except Exception:
        raise InputError(f"chromaticities {tuple(chroma)!r}: the primaries are degenerate (no RGB → XYZ "
                         "matrix); fix the file's chromaticities or give --input-colorspace") from None
    d65 = colour.xy_to_XYZ(colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"])
    cat = colour.adaptation.matrix_chromatic_adaptation_VonKries(colour.xy_to_XYZ(white), d65, transform="Bradford")
    return cat @ npm


def _linear_matrix(config, src: str, dst: str) -> np.ndarray | None:
    """The 3×3 matrix of the config's ``src`` → ``dst`` conversion, or None when it is not linear."""
    try:
        cpu = config.getProcessor(src, dst).getDefaultCPUProcessor()
    except Exception:
        return None
    probe = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [0.25, 0.5, 2.0], [4.0, 0.125, 0.03]], np.float32)
    out = probe.copy()
    cpu.applyRGB(out)
    m = out[:3].astype(np.float64).T  # columns: images of the unit vectors
    pred = probe[3:].astype(np.float64) @ m.T
    if not np.all(np.isfinite(out)) or np.max(np.abs(pred - out[3:])) > 1e-5 * max(1.0, np.max(np.abs(pred))):
        return None
    return m


@lru_cache(maxsize=8)
def _linear_spaces(spec: str) -> tuple[tuple[str, np.ndarray], ...]:
    """Every scene-referred colour space of the config that is a matrix from XYZ-D65, with it."""
    ocio = _ocio()
    config = load_config(spec)
    xyz = config.getRoleColorSpace("cie_xyz_d65_interchange")
    if not xyz:
        return ()
    out = []
    for cs in config.getColorSpaces(ocio.SEARCH_REFERENCE_SPACE_SCENE, ocio.COLORSPACE_ACTIVE):
        if cs.isData():
            continue
        m = _linear_matrix(config, cs.getName(), xyz)
        if m is not None:
            out.append((cs.getName(), m))
    return tuple(out)


@dataclass(frozen=True)
class InputSpace:
    """Where the image's RGB is: a colour space of the config by ``name``, or a ``matrix`` into the
    config's scene_linear (chromaticities that no colour space of the config has)."""

    name: str
    matrix: tuple | None = None
    source: str = ""
    """Where it came from (``--input-colorspace``, the file's chromaticities, the working space)."""


def input_space(spec: str, chroma: Chromaticities, source: str) -> InputSpace:
    """The config's colour space of ``chroma`` (see the module docstring)."""
    config = load_config(spec)
    m_file = rgb_to_xyz_d65(chroma)
    for name, m in _linear_spaces(spec):
        if np.max(np.abs(m - m_file)) <= MATCH_TOL:
            return InputSpace(name, None, source)
    sl = config.getRoleColorSpace("scene_linear")
    xyz = config.getRoleColorSpace("cie_xyz_d65_interchange")
    m_sl = _linear_matrix(config, sl, xyz) if sl and xyz else None
    if m_sl is None:
        raise InputError(f"--ocio-config {spec}: the config has no linear scene_linear and cie_xyz_d65_interchange "
                         f"roles to place the chromaticities {tuple(round(v, 4) for v in chroma)} ({source}); "
                         "give --input-colorspace NAME")
    m = np.linalg.solve(m_sl, m_file)
    return InputSpace(sl, tuple(float(v) for v in m.ravel()), source)


# -- the view --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class OcioView:
    """A display/view (and looks) of an OCIO config; what ``--display`` means when a config is in
    use. Picklable (Dask workers rebuild the processor from it)."""

    config: str
    display: str
    view: str
    looks: str = ""
    input_colorspace: str | None = None

    @classmethod
    def resolve(cls, config: str, display: str | None = None, view: str | None = None,
                looks: str | None = None, input_colorspace: str | None = None) -> "OcioView":
        """Check the names against the config (one line naming the choices) and fill defaults."""
        cfg = load_config(config)
        displays = list(cfg.getDisplays())
        display = _choice("display", "--display", display, displays, config) if display else cfg.getDefaultDisplay()
        views = list(cfg.getViews(display))
        view = _choice(f"view of display {display!r}", "--ocio-view", view, views, config) if view \
            else cfg.getDefaultView(display)
        look_names = list(cfg.getLookNames())
        parts = [p.strip() for p in (looks or "").split(",") if p.strip()]
        for p in parts:
            _choice("look", "--look", p.lstrip("+-"), look_names, config)
        if input_colorspace is not None and cfg.getColorSpace(input_colorspace) is None:
            names = list(cfg.getColorSpaceNames())
            raise InputError(f"--input-colorspace {input_colorspace!r} is not a colour space of the OCIO config "
                             f"{config}; use one of: " + ", ".join(repr(n) for n in names[:40])
                             + (" …" if len(names) > 40 else ""))
        return cls(config, display, view, ",".join(parts), input_colorspace)

    @property
    def label(self) -> str:
        look = f", look {self.looks}" if self.looks else ""
        return f"OCIO {self.display} / {self.view}{look} ({self.config})"

    def source_space(self, working_space: str = "rec709", chroma: Chromaticities | None = None) -> InputSpace:
        """The input colour space: ``--input-colorspace`` > the file's chromaticities > the working space."""
        if self.input_colorspace is not None:
            return InputSpace(self.input_colorspace, None, "--input-colorspace")
        if chroma is not None:
            return input_space(self.config, tuple(chroma), "the input's chromaticities")
        return input_space(self.config, working_space_chromaticities(working_space),
                           f"the working space {working_space}")

    def processor(self, src: InputSpace):
        """The OCIO processor input → looks → display/view."""
        return _processor(self, src)

    def encode(self, rgb: np.ndarray, working_space: str = "rec709",
               chroma: Chromaticities | None = None) -> np.ndarray:
        """Linear (…, 3) image → display code values (float32, not clipped), by OCIO's CPU processor."""
        cpu = self.processor(self.source_space(working_space, chroma)).getDefaultCPUProcessor()
        out = np.ascontiguousarray(np.asarray(rgb)[..., :3], dtype=np.float32).copy()
        flat = out.reshape(-1, 3)
        cpu.applyRGB(flat)
        return flat.reshape(out.shape)

    def display_colorspace(self) -> str:
        cfg = load_config(self.config)
        name = cfg.getDisplayViewColorSpaceName(self.display, self.view)
        return self.display if name == "<USE_DISPLAY_NAME>" else name  # OCIO's shared-view placeholder


@lru_cache(maxsize=32)
def _processor(view: OcioView, src: InputSpace):
    ocio = _ocio()
    cfg = load_config(view.config)
    dvt = ocio.DisplayViewTransform(src=src.name, display=view.display, view=view.view)
    vp = ocio.LegacyViewingPipeline()
    vp.setDisplayViewTransform(dvt)
    if view.looks:
        vp.setLooksOverrideEnabled(True)
        vp.setLooksOverride(view.looks)
    if src.matrix is not None:
        m = np.zeros(16)
        m.reshape(4, 4)[:3, :3] = np.asarray(src.matrix).reshape(3, 3)
        m[15] = 1.0
        vp.setLinearCC(ocio.MatrixTransform(m.tolist()))
    try:
        return vp.getProcessor(cfg, cfg.getCurrentContext())
    except Exception as e:
        first = str(e).strip().splitlines()[0]
        raise InputError(f"--display {view.display!r} --ocio-view {view.view!r}: OpenColorIO cannot build the "
                         f"transform from {src.name!r} ({first})") from None


# -- display identification (ICC / cICP tags) ---------------------------------------------------

TAGGABLE = {
    # name: (colour-science primaries, decoding y = f(code) relative to display white, cICP
    #        (primaries, transfer, matrix, full range) per ITU-T H.273, clpost ICC display or None)
    "srgb": ("sRGB", "sRGB", (1, 13, 0, 1), "srgb"),
    "display-p3": ("Display P3", "sRGB", (12, 13, 0, 1), "display-p3"),
    "gamma22-rec709": ("ITU-R BT.709", "Gamma 2.2", (1, 4, 0, 1), "gamma22-rec709"),
    "bt1886-rec709": ("ITU-R BT.709", "ITU-R BT.1886", (1, 1, 0, 1), "bt1886-rec709"),
    "gamma26-p3d65": ("Display P3", "Gamma 2.6", (12, 17, 0, 1), None),
    "pq-rec2020": ("ITU-R BT.2020", "ST 2084", (9, 16, 0, 1), None),
    "pq-p3d65": ("Display P3", "ST 2084", (12, 16, 0, 1), None),
}
"""Display encodings clpost can tag. The decodings are colour-science's (``Gamma 2.x`` a pure
power; ``ST 2084`` in cd/m² over OCIO's 100 cd/m² display-referred unit). cICP transfer 1 is
H.273's BT.709 code point, which players display with BT.1886 (gamma 2.4); 4 is gamma 2.2 (BT.470
M), 13 sRGB, 16 PQ, 17 SMPTE ST 428 (gamma 2.6)."""


def decode(name: str, code: np.ndarray) -> np.ndarray:
    """Display light (1 = 100 cd/m² for PQ, else display white) of code values, colour-science."""
    import colour

    fn = TAGGABLE[name][1]
    x = np.asarray(code, dtype=np.float64)
    if fn.startswith("Gamma "):
        return np.power(np.clip(x, 0.0, None), float(fn.split()[1]))
    if fn == "ST 2084":
        return colour.eotf(x, function="ST 2084") / 100.0
    if fn == "ITU-R BT.1886":
        return colour.eotf(x, function="ITU-R BT.1886", L_B=0.0, L_W=1.0)
    return colour.cctf_decoding(x, function=fn)


@lru_cache(maxsize=32)
def identify_display(spec: str, display_colorspace: str) -> str | None:
    """The :data:`TAGGABLE` encoding the config's display colour space is (measured: its code
    values → cie_xyz_d65_interchange through OCIO against colour-science to 2e-4 relative), or None."""
    import colour

    cfg = load_config(spec)
    xyz = cfg.getRoleColorSpace("cie_xyz_d65_interchange")
    if not xyz:
        return None
    try:
        cpu = cfg.getProcessor(display_colorspace, xyz).getDefaultCPUProcessor()
    except Exception:
        return None
    ramp = np.linspace(0.0, 1.0, 21)
    probe = np.concatenate([np.stack([ramp, 0 * ramp, 0 * ramp], 1), np.stack([0 * ramp, ramp, 0 * ramp], 1),
                            np.stack([0 * ramp, 0 * ramp, ramp], 1), np.stack([ramp] * 3, 1)])
    got = probe.astype(np.float32).copy()
    cpu.applyRGB(got)
    for name, (space, _fn, _cicp, _icc) in TAGGABLE.items():
        npm = rgb_to_xyz_d65(tuple((*np.ravel(colour.RGB_COLOURSPACES[space].primaries),
                                    *colour.RGB_COLOURSPACES[space].whitepoint)))
        want = decode(name, probe) @ npm.T
        if np.max(np.abs(want - got)) <= 2e-4 * max(1.0, float(np.max(np.abs(want)))):
            return name
    return None


def display_tags(view: OcioView) -> tuple[str | None, tuple[int, int, int, int] | None]:
    """(clpost ICC display name or None, cICP code points or None) of a view's display encoding;
    an unknown one warns once and gives (None, None)."""
    name = identify_display(view.config, view.display_colorspace())
    if name is None:
        _warn_untagged(view.display, view.view)
        return None, None
    return TAGGABLE[name][3], TAGGABLE[name][2]


@lru_cache(maxsize=None)
def _warn_untagged(display: str, view: str) -> None:
    warnings.warn(f"--display {display!r} --ocio-view {view!r}: its encoding is none clpost can tag (ICC/cICP); "
                  "the image is written untagged (viewers will assume sRGB)", stacklevel=3)
