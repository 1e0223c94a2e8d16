"""Focus at a depth, checked by the Kolb-style backward tracer (docs/measurements.md "Focus at the
depth pass's depth"): for lens_data lenses and depths D, the traced blur of an axial point at depth D
with the lens focused by ``--focus D`` (depth from the entrance pupil) and by the old reading of the
same number as a film distance (``--focus-scale D``), the dof stage's CoC there, and the breathing.

    PYTHONPATH=. python tools/focus_check.py --width 1920
"""
import argparse
import math

from clpost.camera import Camera
from clpost.optics import get_lens
from clpost.render.kolb_trace import axial_blur_px
from clpost.stages.dof import coc_px

CASES = [("zeiss-planar-50-f1.4", 2.0, 0.475), ("zeiss-planar-50-f1.4", 2.0, 1.0), ("zeiss-planar-50-f1.4", 8.0, 0.475),
         ("dgauss-50", 4.0, 0.7), ("telephoto-250", 5.6, 4.0), ("wide-22", 4.0, 0.35),
         ("thorlabs-ac254-050-a", 4.0, 0.6), ("fisheye-10", 5.6, 0.15)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--width", type=int, default=1920, help="image width the px are measured at (36 mm sensor)")
    args = ap.parse_args()
    w = args.width
    print("| lens | f/ | D (m) | film distance for D (m) | traced blur, --focus D (px) | dof CoC at D (px) | "
          "traced blur, old: film distance D (px) | F (mm) | breathing F/F∞ |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for lens, n, d in CASES:
        cam = Camera(lens=lens, f_number=n, focus_distance_m=d)
        old = (f"{axial_blur_px(Camera(lens=lens, f_number=n, focus_scale_m=d), d, w):.2f}"
               if d >= get_lens(lens).min_focus_m else "refused (< min focus)")
        f_inf = cam.with_(focus_distance_m=math.inf).render_focal_length_mm
        print(f"| {lens} | {n:g} | {d:g} | {cam.focus_from_film_m:.4f} | {axial_blur_px(cam, d, w):.2f} | "
              f"{2 * abs(float(coc_px(cam, d, w))):.2f} | {old} | {cam.render_focal_length_mm:.3f} | "
              f"{cam.render_focal_length_mm / f_inf:.4f} |")


if __name__ == "__main__":
    main()
