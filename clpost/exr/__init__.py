r"""OpenEXR input and output: each renderer's channel layout mapped to clpost's conventions.

Reading gives a :class:`clpost.frame.Frame` whose buffers follow ``docs/conventions.md``:
color linear RGB (H×W×3, optional alpha), depth **planar** camera-space Z in metres with
``+inf`` for sky, velocity **forward** screen-space motion in pixels per frame, **+x right,
+y down**. Every renderer's convention is converted here, at the input boundary, and the
writer inverts the same conversion so each layout round-trips.

Pixel rows in an EXR file are stored top row first (``INCREASING_Y`` in the data window,
y down), exactly like our arrays — a "y up" convention below is about the *sign of vector
components*, never about row order.

Layouts
-------
Auto-detected from the channel names of all parts (:func:`detect_layout`, first match wins in
the order blender, arnold, nuke, clpost); ``layout=`` (CLI ``--channels``) overrides.

**clpost** (native, no conversion)

============  =========================  =====================================================
buffer        channels                   convention in the file → ours
============  =========================  =====================================================
color         ``R, G, B`` (+ ``A``)      linear RGB, unchanged
depth         ``Z``                      planar metres, ``+inf`` sky → unchanged
velocity      ``velocity.X/Y``           forward px/frame, +y down → unchanged
============  =========================  =====================================================

**blender** (multilayer; Blender 5.x writes *one part per pass*, all parts are read; the view
layer prefix — ``ViewLayer`` by default — is detected from ``<layer>.Combined.R``)

============  ================================  ==============================================
buffer        channels                          convention in the file → ours
============  ================================  ==============================================
color         ``<layer>.Combined.R/G/B/A``      linear RGB + alpha, unchanged
depth         ``<layer>.Depth.Z``               planar view distance in metres (verified);
                                                sky is written as ``1e10`` → values ≥ ``1e10``
                                                (or inf) become ``+inf``
velocity      ``<layer>.Vector.X/Y/Z/W``        px/frame, **y up**; XY = previous − current,
                                                ZW = current − next (verified with Blender
                                                5.2 / Cycles). Forward, y down: ``(−Z, +W)``.
                                                Without ZW, ``(−X, +Y)`` (assumes constant
                                                velocity over the two frame intervals).
============  ================================  ==============================================

**nuke** (Foundry Nuke, e.g. ScanlineRender output written by a Write node)

============  ===============================  ===============================================
buffer        channels                         convention in the file → ours
============  ===============================  ===============================================
color         ``R, G, B`` (+ ``A``)            linear RGB, unchanged
depth         ``depth.Z``                      **1/z** by default ("classic" ScanlineRender
                                               depth, its ``1/Z`` output knob on; 0 = no
                                               hit) → ``z = 1/depth.Z``, 0 → ``+inf``. Pass
                                               ``depth="planar"`` if the channel holds metres
                                               (e.g. a renderer's Z shuffled into depth.Z).
velocity      ``forward.u/v``                  px to the next frame ("distance" motion-vector
                                               mode), Nuke's image space is **y up** (origin
                                               bottom-left) → ``(u, −v)``
              ``backward.u/v`` (fallback)      px to the previous frame, y up → forward is
                                               approximated as ``(−u, +v)`` (assumes constant
                                               velocity; used only when forward.u/v is absent)
============  ===============================  ===============================================

Verified vs assumed (Nuke): 1/z depth with 0 for "no hit" is Foundry's documented classic
ScanlineRender output and the reason ZDefocus defaults to ``math = far = 0``; y up is Nuke's
documented image coordinate system; that ``forward`` holds pixels to the next frame is the
VectorGenerator/ScanlineRender documentation. None of this was checked against a file written
by Nuke itself, and whether classic 1/z is of planar or radial distance is assumed planar.

**arnold** (Autodesk Arnold, ``driver_exr``)

============  ===================================  ===========================================
buffer        channels                             convention in the file → ours
============  ===================================  ===========================================
color         ``R, G, B`` (+ ``A``)                linear RGB, unchanged
depth         ``Z``                                **radial** distance along the camera ray
                                                   assumed (NOT verified). Converted to planar
                                                   with ``focal_px``; without it the depth is
                                                   kept radial, ``metadata["depth_kind"]`` says
                                                   ``"radial"`` and :class:`DepthConventionWarning`
                                                   is issued. Values ≥ ``1e10`` → ``+inf``.
velocity      ``motionvector.R/G`` (or ``.X/Y``)   raw pixels over the normalised shutter
                                                   [0, 1] = one frame, forward in time
                                                   (Arnold's motion_vector docs); y **up**
                                                   assumed (NOT verified) → ``(R, −G)``.
                                                   ``velocity_y_up=False`` overrides.
============  ===================================  ===========================================

Verified vs assumed (Arnold): the ``motion_vector`` shader documentation states the vector is
the motion over a normalised shutter [0, 1] and must be rendered with an instantaneous shutter;
the y sign and whether the built-in ``motionvector`` AOV is raw pixels (not normalised by
``max_displace``) are assumptions, as is radial ``Z`` (CONVENTIONS.md: "Arnold Z may be radial
distance rather than planar (not verified)"). Check a frame with :func:`info` before trusting it.

Radial → planar depth: :func:`radial_to_planar` (formula in :mod:`clpost.exr.layouts`).

Modules
-------
:mod:`clpost.exr.layouts` holds one :class:`Layout` object per convention above (channel names,
detection, depth and velocity conversions both ways); :mod:`clpost.exr.io` reads and writes files
(header checks before any allocation, multi-part merge, windows, atomic writes, ``info``).

Windows
-------
Both windows are kept, as Nuke keeps a Read node's format and bounding box: the arrays cover the
bounding box of the data window and the display window (:attr:`clpost.Frame.windows`), pixels
outside the data window are "no data" (color 0, alpha 0, depth ``+inf``, velocity 0; an alpha
plane is created if the file has none), and :func:`write_frame` writes the data window's pixels
back with both windows. A data window larger than the display window is overscan (the
distortion stage samples it); parts with different data windows (each pass's bounding box) are
placed in their union. All parts share one display window (OpenEXR requires it).

Other files
-----------
Luminance/chroma (Y, RY, BY) and luminance-only (Y) images become RGB as OpenEXR's RGBA
interface makes them (:mod:`clpost.exr.yca`, with the file's ``chromaticities``); a lone R, G or
B channel is grey. Multi-view files (``multiView`` attribute, or parts with a ``view``) give one
view, the default unless ``view=``/``--view`` names another. Tiled and mip-mapped files give
level 0. Deep images are flattened front to back (:mod:`clpost.exr.deep`).

Writing
-------
:func:`write_frame` is atomic (temporary file in the output directory, then ``os.replace``),
ZIP-compressed. ``half=True`` stores color, alpha and velocity as float16 but **depth stays
float32** (half tops out at 65504 and has an 11-bit mantissa; Blender also keeps Z full float).
``+inf`` depth is kept as ``+inf`` (clpost, arnold), ``1e10`` (blender) or ``0`` (nuke, 1/z).

References: OpenEXR file layout and multi-part files, https://openexr.com/en/latest/;
Blender manual, "Render Passes" (Depth, Vector); Foundry Nuke reference guide, ScanlineRender,
ZDefocus, VectorBlur; Autodesk Arnold user guide, "AOVs" and the ``motion_vector`` shader.
"""
from .io import (CAMERA_ATTRIBUTES, COMPRESSIONS, MAX_CHANNELS, MAX_SIDE, PartHeader, ReadSpec, check_header,
                 display_size, format_info, info, quiet_openexr, read_attributes, read_frame, read_header, window_str, write_frame)
from .layouts import (BLENDER_VIEW_LAYER, DEPTH_KINDS, LAYOUTS, REGISTRY, SKY_DEPTH_M,
                      ArnoldLayout, BlenderLayout, ClpostLayout, DepthConventionWarning, Layout,
                      NukeLayout, detect_layout, get_layout, planar_to_radial, radial_to_planar)

__all__ = [
    "CAMERA_ATTRIBUTES", "read_attributes", "ArnoldLayout", "BLENDER_VIEW_LAYER", "BlenderLayout", "COMPRESSIONS", "ClpostLayout", "DEPTH_KINDS",
    "DepthConventionWarning", "LAYOUTS", "Layout", "MAX_CHANNELS", "MAX_SIDE", "NukeLayout", "PartHeader",
    "REGISTRY", "ReadSpec", "window_str", "SKY_DEPTH_M", "check_header", "detect_layout", "display_size", "format_info", "get_layout", "info",
    "planar_to_radial", "quiet_openexr", "radial_to_planar", "read_frame", "read_header", "write_frame",
]
