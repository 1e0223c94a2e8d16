r"""What to render so that distortion leaves no output pixel unfilled (``clpost render-size``).

A lens with barrel distortion (OpenCV k1 < 0) pulls the distorted image's border in from beyond
the pinhole render's edges: a render of the calibration's own size and K leaves a black,
pincushion-shaped border (5–10 px at HD for common lenses). Two ways to render enough:

* **overscan** — the same camera (K unchanged) with extra pixels around the image, written as an
  EXR data window beyond the display window (Nuke ScanlineRender's ``overscan``; any renderer or
  ``oiiotool`` that keeps the data window): L, T, R, B px from
  :func:`clpost.calibration.overscan_px`;
* **one larger image** — :func:`clpost.calibration.required_render`'s W′ × H′ at f = max(f_x, f_y)
  with its own principal point (Blender, which writes no data window beyond the display
  window): resolution W′ × H′, sensor width × W′/W (sensor fit horizontal, same focal length in
  mm, so the pixels keep their angular size) and lens shift

  .. math::

      s_x = \frac{(W' - 1)/2 - c'_x}{\max(W', H')}, \qquad s_y = \frac{c'_y - (H' - 1)/2}{\max(W', H')}

  (Blender puts the optical axis at c_x = (W − 1)/2 − s_x max(W, H), c_y = (H − 1)/2 + s_y max(W, H)
  in OpenCV pixel coordinates; checked with ``bpy_extras.object_utils.world_to_camera_view``,
  bpy 5.0).

Both keep a 2 px margin for the resampling filter. clpost recognises both: the first by its
display window (the calibration's size), the second by its size.
"""
from __future__ import annotations

from dataclasses import dataclass

from .calibration import OpenCVModel, overscan_px, required_render


@dataclass(frozen=True)
class RenderSize:
    """The numbers ``clpost render-size`` prints (see the module docstring)."""

    width: int
    height: int
    overscan: tuple[int, int, int, int]
    """(left, top, right, bottom) px at the calibration's K."""
    big: tuple[int, int]
    """(W′, H′) of the one larger image."""
    big_f: float
    big_c: tuple[float, float]
    blender_shift: tuple[float, float]
    sensor_scale: float
    """Sensor width of the larger image / the image's (Blender: sensor width × this)."""

    @property
    def data_window(self) -> tuple[tuple[int, int], tuple[int, int]]:
        left, top, right, bottom = self.overscan
        return (-left, -top), (self.width - 1 + right, self.height - 1 + bottom)


def render_size(model: OpenCVModel, margin_px: float = 2.0) -> RenderSize:
    """:class:`RenderSize` for a calibration (or a traced lens's model)."""
    spec = required_render(model, margin_px)
    big_w, big_h = spec.width, spec.height
    side = max(big_w, big_h)
    shift = (((big_w - 1) / 2 - spec.cx) / side, (spec.cy - (big_h - 1) / 2) / side)
    f_scale = spec.f / model.fx  # the larger image keeps f = max(f_x, f_y)
    return RenderSize(model.width, model.height, overscan_px(model, margin_px), (big_w, big_h), spec.f,
                      (spec.cx, spec.cy), shift, big_w / model.width / f_scale)


def report(model: OpenCVModel, what: str, sensor_width_mm: float | None = None, margin_px: float = 2.0) -> str:
    """The text of ``clpost render-size``."""
    from .calibration import PINHOLE_LIMIT_DEG, max_ray_angle_deg, required_cubemap

    theta = max_ray_angle_deg(model)
    if theta > PINHOLE_LIMIT_DEG:  # no pinhole render covers it: a cubemap (clpost.calibration.cubemap)
        cube = required_cubemap(model)
        return "\n".join([
            f"{what}: {model.width}x{model.height}, {model.distortion_model} model, sees {theta:.1f}° off axis "
            f"({2 * theta:.0f}° field of view, beyond a pinhole render's {2 * PINHOLE_LIMIT_DEG:.0f}°)",
            f"  render a cubemap: six {cube.face} px faces of 90° plus {cube.pad} px each side "
            f"(f={cube.intrinsics()[0]:.6g} px, c=({cube.intrinsics()[2]:.6g}, {cube.intrinsics()[3]:.6g}) px per "
            f"{cube.size}x{cube.size} face), side by side +x -x +y -y +z -z in a {cube.width}x{cube.height} atlas "
            "with metadata['cubemap'] = (face, pad) (PyVistaRenderer.render_cubemap)"])
    r = render_size(model, margin_px)
    (x0, y0), (x1, y1) = r.data_window
    left, top, right, bottom = r.overscan
    nz = ", ".join(f"{n}={getattr(model, n):.6g}" for n in ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")
                   if getattr(model, n))
    lines = [
        f"{what}: {model.width}x{model.height}, f=({model.fx:.6g}, {model.fy:.6g}) px, "
        f"c=({model.cx:.6g}, {model.cy:.6g}) px, {nz or 'no distortion'}",
        f"overscan needed (2 px filter margin included): left {left}, top {top}, right {right}, bottom {bottom} px",
    ]
    if not any(r.overscan):
        lines.append("  the calibration's own K already covers every output pixel: render at "
                     f"{model.width}x{model.height}, no overscan needed")
        return "\n".join(lines)
    sensor = (f"{sensor_width_mm:g} mm x {r.sensor_scale:.6g} = {sensor_width_mm * r.sensor_scale:.6g} mm"
              if sensor_width_mm else f"x {r.sensor_scale:.6g}")
    lines += [
        "  EXR overscan (Nuke ScanlineRender overscan, or any renderer writing a data window): format "
        f"{model.width}x{model.height} = display window (0,0)-({model.width - 1},{model.height - 1}), "
        f"data window ({x0},{y0})-({x1},{y1}), {x1 - x0 + 1}x{y1 - y0 + 1} px rendered",
        f"  or one larger image (Blender): {r.big[0]}x{r.big[1]} px, f={r.big_f:.6g} px, "
        f"c=({r.big_c[0]:.6g}, {r.big_c[1]:.6g}) px — resolution {r.big[0]}x{r.big[1]}, sensor width {sensor} "
        f"(sensor fit horizontal, same focal length), shift x {r.blender_shift[0]:.6g}, shift y {r.blender_shift[1]:.6g}",
        "  without either, clpost process warns and leaves the border black (alpha 0); --fill crop magnifies the "
        "image until it is filled, --fill border keeps the border without a warning",
    ]
    return "\n".join(lines)
