r"""Real lenses: prescriptions, paraxial optics, a sequential ray tracer and derived lens curves.

API for the stages (DoF, astigmatism, vignetting, distortion, lateral colour, bokeh) — obtain the
lens from the camera, never by loading files yourself::

    cam = Camera(lens="zeiss-planar-50-f1.4", f_number=2.0, focus_distance_m=3.0)
    lens = cam.optics                      # clpost.optics.Lens, or None for a thin lens
    if lens is not None:
        c = cam.lens_curves()              # LensCurves for (lens, focus, f-number), cached
                                           # on the Lens: lens.curves(focus_m, f_number)
        c.at("distortion_pct", r_mm)       # % vs paraxial image height, 0 on axis
        c.at("relative_illumination", r_mm)  # in [0, 1], 1 on axis (natural + optical vignetting)
        c.at("sagittal_offset_mm", r_mm)   # focal offset along z, + = behind the film
        c.at("tangential_offset_mm", r_mm)
        c.at("lateral_color_mm", r_mm)     # chief-ray height F − C (mm on the film)
        c.pupil_rho, c.lsa_mm, c.sa_transverse_mm   # spherical aberration vs pupil height
        c.pupil_field_mm, c.pupil_grid, c.pupil_masks  # vignetted pupil (cat's eye) per field
        lens.focus(distance_mm, f_number)  # FocusState: extension, thin-lens equivalent, error
        lens.focus_depth(depth_mm, f_number)  # the same for a depth from the entrance pupil
        cam.focus_state                    # = lens.focus_depth(cam.focus_distance_m * 1000, N)
        lens.paraxial                      # EFL, BFL, principal planes, pupils (mm)

Image heights r are in mm on the film, radial from the optical centre. The optics layer takes
lens-scale focus distances, measured from the film plane (``Lens.focus``, ``Lens.curves``,
``lens_curves``); a Camera's ``focus_distance_m`` is a depth from the entrance pupil (the render's
pinhole) and ``cam.focus_from_film_m`` its lens-scale distance (docs/conventions.md "Focus"). For rays, use
:func:`clpost.optics.trace.trace` (numpy) or :func:`clpost.optics.cltrace.trace_cl` (OpenCL,
same results) on ``lens.focused(distance_mm, f_number)``.
"""
from .curves import LensCurves, compute_curves
from .lens import FNumberClampedWarning, FocusState, Lens, get_lens, lens_curves
from .prescription import Prescription, available_lenses, load_prescription, load_prescription_file

__all__ = ["FNumberClampedWarning", "FocusState", "Lens", "LensCurves", "Prescription", "available_lenses",
           "compute_curves", "get_lens", "lens_curves", "load_prescription", "load_prescription_file"]
