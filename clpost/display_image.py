r"""Viewable images: display-encoded PNG/JPEG/TIFF with an embedded ICC profile — the one place
that decides what an output's extension means and writes the non-EXR ones.

- :func:`output_format` maps an output path's extension to ``"exr"`` or an image format
  (:data:`IMAGE_FORMATS`); any other extension is an :class:`~clpost.errors.InputError`, so a file
  is never written under a name that lies about its content.
- :func:`write_image` display-encodes a linear working-space image (1.0 = display white) for a
  display of :data:`clpost.colorspace.DISPLAYS` (primaries converted, clipped, encoded, 8-bit)
  or an OpenColorIO display/view (:class:`clpost.ocio.OcioView`: OCIO's own processor, clipped,
  8-bit) and writes it atomically (:func:`clpost.atomic.atomic_path`) with that display's ICC
  profile embedded and, in a PNG, its cICP chunk (ITU-T H.273 code points, read before the ICC
  profile by PNG 3rd-edition readers), so colour-managed viewers show Display P3 as P3 and sRGB
  as sRGB.
- :func:`icc_profile` builds the profile: an ICC.1:2001-04 (v2.1) RGB display matrix/TRC profile,
  the smallest kind every colour-managed reader understands. Colorants are the display's RGB → XYZ
  matrix chromatically adapted to the ICC's D50 PCS with Bradford (ICC.1 Annex E), the ``chad`` tag
  holds that adaptation and ``wtpt`` is D50 (the ICC v4 convention, read alike by v2 readers); the
  tone curves are 1024-entry tables of the display's decoding (the inverse of the encoding
  :func:`clpost.colorspace.display_encode` applies). Every number comes from colour-science; no
  profile file is shipped. Checked against LittleCMS (Pillow's ImageCms) in ``tests/test_display_image.py``.

References: ICC.1:2001-04 (File Format for Color Profiles, v2.4.0), IEC 61966-2-1 (sRGB),
SMPTE EG 432-1 / Apple Display P3, ITU-R BT.709.
"""
from __future__ import annotations

import os
import struct
from functools import lru_cache
from pathlib import Path

import numpy as np

from .errors import InputError

IMAGE_FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG", ".tif": "TIFF", ".tiff": "TIFF"}
"""Display-encoded image outputs by extension (lower case) → Pillow format."""

JPEG_QUALITY = 95
TRC_ENTRIES = 1024


def output_format(path: str | os.PathLike, option: str = "-o") -> str:
    """``"EXR"`` for ``.exr``, an :data:`IMAGE_FORMATS` format, or InputError naming the choices."""
    ext = Path(str(path)).suffix.lower()
    if ext == ".exr":
        return "EXR"
    fmt = IMAGE_FORMATS.get(ext)
    if fmt is None:
        raise InputError(f"{option} {path}: unknown extension {ext or '(none)'!r}; write .exr (linear, the "
                         f"camera in the header) or a display-encoded {', '.join(IMAGE_FORMATS)}")
    return fmt


# -- ICC profile --------------------------------------------------------------------------------

def _s15f16(v: float) -> bytes:
    return struct.pack(">i", int(round(v * 65536.0)))


def _xyz_tag(xyz) -> bytes:
    return b"XYZ " + b"\0" * 4 + b"".join(_s15f16(v) for v in xyz)


def _curve_tag(table: np.ndarray) -> bytes:
    codes = np.round(np.clip(table, 0.0, 1.0) * 65535.0).astype(">u2")
    return b"curv" + b"\0" * 4 + struct.pack(">I", codes.size) + codes.tobytes()


def _text_tag(text: str) -> bytes:
    return b"text" + b"\0" * 4 + text.encode("ascii") + b"\0"


def _desc_tag(text: str) -> bytes:
    # textDescriptionType (v2): ASCII, then empty Unicode and ScriptCode parts (67 bytes)
    ascii_ = text.encode("ascii") + b"\0"
    return (b"desc" + b"\0" * 4 + struct.pack(">I", len(ascii_)) + ascii_ + struct.pack(">II", 0, 0)
            + struct.pack(">HB", 0, 0) + b"\0" * 67)


def _sf32_tag(m: np.ndarray) -> bytes:
    return b"sf32" + b"\0" * 4 + b"".join(_s15f16(v) for v in np.asarray(m, float).reshape(-1))


ICC_TITLES = {"srgb": "sRGB IEC61966-2.1 (clpost)", "rec709": "ITU-R BT.709 (clpost)",
              "display-p3": "Display P3 (clpost)", "gamma22-rec709": "Rec.709 gamma 2.2 (clpost)",
              "bt1886-rec709": "Rec.709 BT.1886 gamma 2.4 (clpost)"}
"""Profiles clpost can build: the :data:`clpost.colorspace.DISPLAYS` and the SDR encodings of OCIO
displays that :func:`clpost.ocio.identify_display` recognises."""


def _icc_source(display: str):
    """(colour-science colourspace name, decoding code → display light) of an ICC display."""
    import colour

    from .colorspace import DISPLAYS

    if display in DISPLAYS:
        space_name, cctf = DISPLAYS[display]
        return space_name, lambda x: colour.cctf_decoding(x, function=cctf)
    from .ocio import TAGGABLE, decode

    if display in ICC_TITLES and display in TAGGABLE:
        return TAGGABLE[display][0], lambda x: decode(display, x)
    raise InputError(f"display {display!r} is unknown: use one of {', '.join(DISPLAYS)}")


@lru_cache(maxsize=None)
def icc_profile(display: str) -> bytes:
    """The ICC profile (bytes) of a display of :data:`ICC_TITLES` (see the module)."""
    import colour

    space_name, decoding = _icc_source(display)
    space = colour.RGB_COLOURSPACES[space_name]
    d50 = colour.xy_to_XYZ(colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D50"])
    white = colour.xy_to_XYZ(space.whitepoint)
    chad = colour.adaptation.matrix_chromatic_adaptation_VonKries(white, d50, transform="Bradford")
    m = chad @ space.matrix_RGB_to_XYZ  # columns: the R, G, B colorants in the D50 PCS
    x = np.linspace(0.0, 1.0, TRC_ENTRIES)
    trc = _curve_tag(np.asarray(decoding(x), float))
    title = ICC_TITLES[display]
    tags = [(b"desc", _desc_tag(title)),
            (b"cprt", _text_tag("No copyright, use freely; generated by clpost from colour-science data")),
            (b"wtpt", _xyz_tag(d50)),
            (b"rXYZ", _xyz_tag(m[:, 0])), (b"gXYZ", _xyz_tag(m[:, 1])), (b"bXYZ", _xyz_tag(m[:, 2])),
            (b"rTRC", trc), (b"gTRC", trc), (b"bTRC", trc),
            (b"chad", _sf32_tag(chad))]
    table_len = 4 + 12 * len(tags)
    offset = 128 + table_len
    entries, blobs, seen = [], [], {}
    for sig, data in tags:
        if data in seen:  # the three TRCs share one element, as ICC allows
            entries.append((sig, seen[data], len(data)))
            continue
        seen[data] = offset
        entries.append((sig, offset, len(data)))
        pad = (-len(data)) % 4
        blobs.append(data + b"\0" * pad)
        offset += len(data) + pad
    body = struct.pack(">I", len(tags)) + b"".join(struct.pack(">4sII", s, o, n) for s, o, n in entries)
    body += b"".join(blobs)
    size = 128 + len(body)
    header = (struct.pack(">I", size) + b"\0" * 4 + struct.pack(">I", 0x02100000) + b"mntrRGB XYZ "
              + struct.pack(">6H", 2026, 1, 1, 0, 0, 0) + b"acsp" + b"\0" * 4 + struct.pack(">I", 0)
              + b"\0" * 8 + b"\0" * 8 + struct.pack(">I", 0) + b"".join(_s15f16(v) for v in d50)
              + b"\0" * 4 + b"\0" * 16 + b"\0" * 28)
    assert len(header) == 128
    return header + body


# -- writing ------------------------------------------------------------------------------------

BUILTIN_CICP = {"srgb": (1, 13, 0, 1), "rec709": (1, 1, 0, 1), "display-p3": (12, 13, 0, 1)}
"""cICP code points (ITU-T H.273: colour primaries, transfer characteristics, matrix 0 = RGB,
full range) of :data:`clpost.colorspace.DISPLAYS`; OCIO displays': :data:`clpost.ocio.TAGGABLE`."""


def encode_display(signal, display="srgb", working_space: str = "rec709", chroma=None):
    """(uint8 code values (H, W, 3), ICC display name or None, cICP or None) of a linear image for
    ``display``: a :data:`clpost.colorspace.DISPLAYS` name (clpost's encodings: primaries
    converted, clipped, encoded) or a :class:`clpost.ocio.OcioView` (OCIO's processor from the
    input space — ``chroma``: the input file's chromaticities, see :mod:`clpost.ocio` — then
    clipped to [0, 1] and quantised)."""
    from .colorspace import display_encode, quantise
    from .ocio import OcioView, display_tags

    rgb = np.asarray(signal)[..., :3]
    if isinstance(display, OcioView):
        icc, cicp = display_tags(display)
        return quantise(np.clip(display.encode(rgb, working_space, chroma), 0.0, 1.0), 8), icc, cicp
    return display_encode(rgb, working_space, display, 8), display, BUILTIN_CICP.get(display)


def _png_cicp(cicp) -> object:
    from PIL import PngImagePlugin

    info = PngImagePlugin.PngInfo()
    info.add(b"cICP", bytes(cicp))  # before IDAT, as PNG (3rd edition) requires
    return info


def write_image(path: str | os.PathLike, signal, *, display="srgb", working_space: str = "rec709",
                option: str = "-o", fmt: str | None = None, chroma=None) -> None:
    """Display-encode a linear (H, W, ≥3) image (1.0 = display white; alpha is dropped) for
    ``display`` (:func:`encode_display`) and write it atomically as the format its extension
    names (or ``fmt``), with the display's ICC profile embedded (and a cICP chunk in a PNG)."""
    from PIL import Image

    from .atomic import atomic_path

    fmt = fmt or output_format(path, option)
    if fmt == "EXR":
        raise InputError(f"{option} {path}: an .exr is written linear by clpost.exr, not display-encoded; "
                         "give .png, .jpg or .tif for a viewable image")
    codes, icc, cicp = encode_display(signal, display, working_space, chroma)
    img = Image.fromarray(codes, mode="RGB")
    extra = {"quality": JPEG_QUALITY, "subsampling": 0} if fmt == "JPEG" else {}
    if fmt == "TIFF":
        extra["compression"] = "tiff_deflate"
    if icc is not None:
        extra["icc_profile"] = icc_profile(icc)
    if fmt == "PNG" and cicp is not None:
        extra["pnginfo"] = _png_cicp(cicp)
    with atomic_path(path) as tmp:
        img.save(tmp, format=fmt, **extra)
