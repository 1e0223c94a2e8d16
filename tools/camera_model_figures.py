"""docs/camera_models.md's figures: each camera model family's image of the same scene, made by the
distortion stage.

The scene is a fronto-parallel checkerboard plane at z = 1 (squares of 0.1 normalised units, every
fifth line red/blue for orientation) rendered analytically as the pinhole image that
clpost.calibration.required_render asks for (4 × 4 supersampled), then resampled by the
distortion stage (Pipeline, stages=["distortion"], final quality) into each model's 320 × 240
image. Usage:

    PYTHONPATH=. python tools/camera_model_figures.py docs/figures
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from clpost import Camera, Frame, Pipeline
from clpost.calibration import OpenCVModel, required_render

W, H = 320, 240

MODELS = {
    "opencv": OpenCVModel(W, H, 210.0, 210.0, 159.5, 119.5, k1=-0.3, k2=0.09, p1=1e-3),
    "fisheye": OpenCVModel(W, H, 165.0, 165.0, 159.5, 119.5, k1=0.05, k2=-0.01, distortion_model="fisheye"),
    "thinprism": OpenCVModel(W, H, 165.0, 165.0, 159.5, 119.5, k1=0.02, k2=0.01, p1=0.004, p2=0.002,
                             s1=0.01, s3=0.005, distortion_model="thinprism"),
    "ftheta": OpenCVModel(W, H, 160.0, 160.0, 159.5, 119.5, k1=-0.06, k2=0.02, distortion_model="ftheta"),
    "fov": OpenCVModel(W, H, 160.0, 160.0, 159.5, 119.5, omega=1.0, distortion_model="fov"),
    "ucm": OpenCVModel(W, H, 270.0, 270.0, 159.5, 119.5, xi=0.9, k1=-0.05, distortion_model="ucm"),
    "ds": OpenCVModel(W, H, 130.0, 130.0, 159.5, 119.5, xi=-0.2, alpha=0.59, distortion_model="ds"),
}


def scene(spec, ss: int = 4) -> np.ndarray:
    """The pinhole render of the board at the spec's intrinsics (float32 RGB, ss² box samples)."""
    off = (np.arange(ss) + 0.5) / ss - 0.5
    acc = np.zeros((spec.height, spec.width, 3))
    vv, uu = np.mgrid[0:spec.height, 0:spec.width].astype(np.float64)
    for dy in off:
        for dx in off:
            x, y = (uu + dx - spec.cx) / spec.f, (vv + dy - spec.cy) / spec.f
            ix, iy = np.floor(x / 0.1), np.floor(y / 0.1)
            c = np.where((ix + iy) % 2 == 0, 0.85, 0.1)
            rgb = np.stack([c, c, c], -1)
            line_x = np.abs(x / 0.5 - np.rint(x / 0.5)) * 0.5 < 0.006
            line_y = np.abs(y / 0.5 - np.rint(y / 0.5)) * 0.5 < 0.006
            rgb[line_x] = (0.9, 0.1, 0.05)
            rgb[line_y] = (0.05, 0.2, 0.9)
            acc += rgb
    return (acc / ss**2).astype(np.float32)


def main(out_dir: str) -> None:
    import cv2  # the [test] extra's OpenCV writes the PNGs

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for name, m in MODELS.items():
        spec = required_render(m)
        frame = Frame(scene(spec), metadata={"intrinsics": spec.intrinsics()})
        img = Pipeline(Camera(distortion=m), quality="final", stages=["distortion"]).run(frame).color
        png = np.clip(np.rint(np.clip(img, 0, 1) ** (1 / 2.2) * 255), 0, 255).astype(np.uint8)
        cv2.imwrite(str(out / f"camera_model_{name}.png"), png[..., ::-1])
        print(f"{name}: render {spec.width}x{spec.height} -> {out / f'camera_model_{name}.png'}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "docs/figures")
