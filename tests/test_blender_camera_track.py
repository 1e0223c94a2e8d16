"""tools/blender_camera_track.py: the conversion (clpost.blender_track, fake Blender objects), a track Blender 5.0.1
exported (tests/data/blender_pull_track.json, made by tests/data/make_blender_pull.py), and —
where $CLPOST_BPY_PYTHON names a Python with bpy — the whole export."""
import json
import math
import os
import subprocess
from pathlib import Path
from types import SimpleNamespace as NS

import pytest

from clpost import Camera
from clpost.camera_sources import CameraSources
from clpost.camera_track import load_track

from clpost import blender_track as bct

ROOT = Path(__file__).resolve().parents[1]


def _matrix(pos, look_down_minus_z_towards):
    """A camera world matrix (rows) at ``pos`` whose −Z axis is the unit vector given."""
    z = [-v for v in look_down_minus_z_towards]
    return [[1, 0, z[0], pos[0]], [0, 0, z[1], pos[1]], [0, 1, z[2], pos[2]], [0, 0, 0, 1]]


def _scene(**render):
    r = dict(resolution_x=1920, resolution_y=1080, pixel_aspect_x=1.0, pixel_aspect_y=1.0, fps=24, fps_base=1.0,
             motion_blur_shutter=0.5, use_motion_blur=False)
    r.update(render)
    return NS(render=NS(**r), unit_settings=NS(scale_length=1.0))


def _cam(focus_object=None, **data):
    d = dict(type="PERSP", lens=35.0, sensor_width=36.0, sensor_height=24.0, sensor_fit="AUTO")
    d.update(data)
    dof = NS(use_dof=True, focus_distance=2.5, aperture_fstop=2.8, focus_object=focus_object)
    return NS(name="Camera", data=NS(dof=dof, **d), matrix_world=_matrix((0, -5, 1), (0, 1, 0)))


def test_focus_object_depth_is_along_the_view_axis():
    m = _matrix((0, -5, 1), (0, 1, 0))
    assert bct.focus_from_object(m, (0.5, -2.0, 1.3)) == pytest.approx(3.0)  # off-axis: planar depth
    target = NS(matrix_world=NS(translation=(0.5, -2.0, 1.3)))
    assert bct.camera_keys(1, _cam(focus_object=target), _scene())["focus"] == pytest.approx(3.0)


def test_camera_keys_convert_units_fit_and_shutter():
    k = bct.camera_keys(7, _cam(), _scene())
    assert k == {"frame": 7, "focus": 2.5, "f-number": 2.8, "depth-of-field": "on", "lens": "thin:35",
                 "sensor": "36x20.25", "shutter": pytest.approx(1 / 48)}
    # portrait with AUTO fit: the sensor width spans the image height
    assert bct.camera_keys(1, _cam(), _scene(resolution_x=1080, resolution_y=1920))["sensor"] == "20.25x36"
    assert bct.camera_keys(1, _cam(sensor_fit="VERTICAL"), _scene())["sensor"] == "42.6667x24"
    # motion blur on: the frame rate too (23.976 fps as fps / fps_base)
    k = bct.camera_keys(1, _cam(), _scene(use_motion_blur=True, fps=24000, fps_base=1001))
    assert k["fps"] == pytest.approx(24000 / 1001) and k["shutter"] == pytest.approx(0.5 * 1001 / 24000)
    # scene units in centimetres
    s = _scene()
    s.unit_settings.scale_length = 0.01
    assert bct.camera_keys(1, _cam(), s)["focus"] == pytest.approx(0.025)


def test_a_blender_export_drives_the_camera():
    t = load_track(ROOT / "tests" / "data" / "blender_pull_track.json")
    src = CameraSources(track=t, use_exr=False)
    # the .blend animates focus 1 → 4 m and f/2.8 → f/5.6 linearly over frames 1–5
    for n in range(1, 6):
        c = src.resolve(n).camera
        assert c.focus_distance_m == pytest.approx(1 + 0.75 * (n - 1), rel=1e-6)
        assert c.f_number == pytest.approx(2.8 + 0.7 * (n - 1), rel=1e-6)
        assert c.lens == "thin:35" and c.sensor_mm == (36.0, 20.25) and c.depth_of_field
        assert c.shutter_s == pytest.approx(1 / 48)
    assert isinstance(c, Camera)


@pytest.mark.skipif(not os.environ.get("CLPOST_BPY_PYTHON"), reason="set CLPOST_BPY_PYTHON to a Python with bpy")
def test_export_with_blender(tmp_path):
    py = os.environ["CLPOST_BPY_PYTHON"]
    make = (ROOT / "tests" / "data" / "make_blender_pull.py").read_text().replace("/tmp/i18-anim/blender", str(tmp_path))
    (tmp_path / "make.py").write_text(make)
    subprocess.run([py, str(tmp_path / "make.py")], check=True, cwd=tmp_path, capture_output=True)
    out = tmp_path / "t.json"
    subprocess.run([py, str(ROOT / "tools" / "blender_camera_track.py"), str(tmp_path / "pull.blend"), "-o", str(out)],
                   check=True, capture_output=True)
    got = json.loads(out.read_text())["keys"]
    want = json.loads((ROOT / "tests" / "data" / "blender_pull_track.json").read_text())["keys"]
    assert got == want
    subprocess.run([py, str(ROOT / "tools" / "blender_camera_track.py"), str(tmp_path / "focus_object.blend"),
                    "-o", str(out), "--frames", "1-1"], check=True, capture_output=True)
    assert math.isclose(json.loads(out.read_text())["keys"][0]["focus"], 3.0, rel_tol=1e-6)
