"""Animated camera sources: flags > --camera-from > --camera-track > EXR attributes > defaults,
the OpenEXR standard attributes in and out, --camera-from round trips, --explain's sources."""
import json
import math

import numpy as np
import pytest

from clpost import Camera, Frame, InputError, exr
from clpost.camera_sources import (CameraSources, camera_from_file, exr_values, explain_sources,
                                   standard_attributes)
from clpost.camera_track import load_track
from clpost.cli import main


def _frame(depth=True, velocity=False):
    rng = np.random.default_rng(3)
    return Frame((rng.random((12, 16, 3)) + 0.1).astype(np.float32),
                 depth=np.full((12, 16), 2.0, np.float32) if depth else None,
                 velocity=np.full((12, 16, 2), 1.5, np.float32) if velocity else None)


def test_exr_attributes_map_to_camera_fields():
    base = {"lens": "thin:50", "transmittance": 0.9}
    v = {k: val for k, (val, _) in exr_values(
        {"focus": 2.5, "aperture": 4.0, "expTime": 0.01, "isoSpeed": 400.0, "nominalFocalLength": 35.0}, base, Camera).items()}
    assert v == {"focus_distance_m": 2.5, "f_number": 4.0, "shutter_s": 0.01, "iso": 400.0, "lens": "thin:35"}
    # T-stop with the f-number: the transmittance, T = N / sqrt(tau)
    v = exr_values({"aperture": 2.0, "tStop": 2.2}, base, Camera)
    assert v["transmittance"][0] == pytest.approx((2.0 / 2.2) ** 2) and v["f_number"][0] == 2.0
    # T-stop alone: the f-number that gives it with the camera's transmittance
    assert exr_values({"tStop": 2.0}, base, Camera)["f_number"][0] == pytest.approx(2.0 * math.sqrt(0.9))
    # shutter angle at the capture rate; expTime wins when both are there
    assert exr_values({"shutterAngle": 180.0, "captureRate": 24.0}, base, Camera)["shutter_s"][0] == pytest.approx(1 / 48)
    assert exr_values({"shutterAngle": 180.0, "captureRate": 24.0, "expTime": 0.01}, base, Camera)["shutter_s"][0] == 0.01
    # a lens_data lens keeps its own focal length
    assert "lens" not in exr_values({"nominalFocalLength": 35.0}, {**base, "lens": "zeiss-planar-50-f1.4"}, Camera)
    # 0 / non-finite / absent: not a value
    assert exr_values({"focus": 0.0, "aperture": float("nan")}, base, Camera) == {}


def test_standard_attributes_written_and_read_back(tmp_path):
    cam = Camera(focus_distance_m=2.5, f_number=4.0, shutter_s=1 / 48, iso=400, transmittance=0.81,
                 frame_rate_fps=24.0)
    a = standard_attributes(cam)
    assert a == pytest.approx({"focus": 2.5, "aperture": 4.0, "tStop": 4.0 / 0.9, "expTime": 1 / 48,
                               "shutterAngle": 180.0, "isoSpeed": 400.0, "nominalFocalLength": 50.0})
    exr.write_frame(tmp_path / "a.exr", _frame(), header=a)
    back = exr.read_attributes(tmp_path / "a.exr")[0]
    assert back == pytest.approx(a, rel=1e-6)
    assert exr.read_frame(tmp_path / "a.exr").metadata["attributes"] == back
    d = exr.info(tmp_path / "a.exr")
    assert d["camera_attributes"] == back  # `clpost info` shows what `process` will read
    assert "camera attributes: focus 2.5 m, aperture 4, expTime 0.0208333 s" in exr.format_info(d)


def _track(tmp_path, keys):
    p = tmp_path / "t.json"
    p.write_text(json.dumps(keys))
    return load_track(p)


def test_priority_flag_over_camera_from_over_track_over_exr_over_default(tmp_path):
    track = _track(tmp_path, [{"frame": 1, "focus": 5.0, "f-number": 5.6, "iso": 800, "ev": 1.0}])
    cf = {"focus_distance_m": 7.0, "f_number": 11.0}
    attrs = {"focus": 9.0, "aperture": 16.0, "isoSpeed": 1600.0, "expTime": 0.01}
    src = CameraSources(flags={"focus_distance_m": 3.3}, camera_from=cf, camera_from_path="o.exr",
                        track=track)
    r = src.resolve(1, attrs)
    c = r.camera
    assert c.focus_distance_m == 3.3 and r.sources["focus_distance_m"] == "flag --focus"
    assert c.f_number == 11.0 and r.sources["f_number"] == "camera-from o.exr"
    assert c.iso == 800 and r.sources["iso"].startswith("track ")
    assert c.exposure_compensation_ev == 1.0
    assert c.shutter_s == 0.01 and r.sources["shutter_s"] == "EXR expTime"
    assert c.transmittance == 0.9 and r.sources["transmittance"] == "default"
    # each source only where the higher ones are silent
    r = CameraSources(track=track).resolve(1, attrs)
    assert r.camera.focus_distance_m == 5.0 and r.camera.f_number == 5.6
    r = CameraSources().resolve(1, attrs)
    assert r.camera.focus_distance_m == 9.0 and r.sources["focus_distance_m"] == "EXR focus"
    r = CameraSources(use_exr=False).resolve(1, attrs)
    assert r.camera == Camera() and set(r.sources.values()) == {"default"}


def test_a_shutter_angle_flag_beats_an_exr_exposure_time():
    src = CameraSources(flags={"shutter_angle_deg": 90.0, "frame_rate_fps": 24.0})
    r = src.resolve(1, {"expTime": 0.01})
    assert r.camera.shutter_s == pytest.approx(1 / 96) and r.sources["shutter_s"] == "flag --shutter-angle"


def test_the_lens_scale_focus_is_the_same_quantity_as_the_focus_depth(tmp_path):
    # --focus and --focus-scale (or a track's focus_scale_m) set one focus: the highest source of
    # either wins, and --explain names the source that set it
    track = _track(tmp_path, [{"frame": 1, "focus_scale_m": 2.0}])
    r = CameraSources(flags={"focus_distance_m": 5.0}, track=track).resolve(1, {"focus": 9.0})
    assert r.camera.focus_distance_m == 5.0 and r.sources["focus_distance_m"] == "flag --focus"
    r = CameraSources(track=track).resolve(1, {"focus": 9.0})
    assert r.camera.focus_from_film_m == pytest.approx(2.0) and r.sources["focus_distance_m"].startswith("track ")
    r = CameraSources(flags={"focus_scale_m": 3.0}).resolve(1, {"focus": 9.0})
    assert r.camera.focus_from_film_m == pytest.approx(3.0) and r.sources["focus_distance_m"] == "flag --focus-scale"


def test_inconsistent_values_from_sources_name_the_frame_and_sources(tmp_path):
    track = _track(tmp_path, [{"frame": 1, "focus": 0.01}])  # inside the focal length
    with pytest.raises(InputError, match=r"frame 1: Camera\.focus_distance_m=0\.01 .*\(values from track "):
        CameraSources(track=track).resolve(1)


def test_explain_names_each_source_and_the_range(tmp_path):
    track = _track(tmp_path, [{"frame": 1, "f-number": 2.0}, {"frame": 3, "f-number": 4.0}])
    src = CameraSources(flags={"iso": 200.0}, track=track)
    res = [(n, src.resolve(n, {"focus": float(n)})) for n in (1, 2, 3)]
    lines = {ln.split()[0]: ln for ln in explain_sources(res)}
    assert "[flag --iso]" in lines["iso"] and "200" in lines["iso"]
    assert "2 … 4 (varies over frames 1–3: 3 values)" in lines["f_number"] and "[track " in lines["f_number"]
    assert "1 … 3" in lines["focus_distance_m"] and "[EXR focus]" in lines["focus_distance_m"]
    assert "[default]" in lines["transmittance"]


def test_a_structural_parameter_that_changes_gets_a_plan_per_value(tmp_path):
    from clpost import Pipeline

    track = _track(tmp_path, [{"frame": 1, "blades": 5}, {"frame": 3, "blades": 7}])
    src = CameraSources(flags={"depth_of_field": True, "f_number": 1.4, "focus_distance_m": 1.0}, track=track)
    pipe = Pipeline(src.resolve(1).camera)
    for n in (1, 2, 3, 4):
        pipe.run(_frame(), src.resolve(n).camera)
    assert len(pipe._plans) == 2


# -- the command line -----------------------------------------------------------------------------

def _seq(tmp_path, attrs_per_frame):
    (tmp_path / "in").mkdir()
    for n, attrs in enumerate(attrs_per_frame, 1):
        exr.write_frame(tmp_path / "in" / f"s.{n:04d}.exr", _frame(), header=attrs)
    return str(tmp_path / "in" / "s.####.exr")


def test_cli_track_beats_exr_attributes_and_outputs_record_what_was_used(tmp_path):
    src = _seq(tmp_path, [{"focus": 1.0, "aperture": 2.0}, {"focus": 2.0, "aperture": 2.0}, {"focus": 3.0}])
    t = tmp_path / "t.csv"
    t.write_text("frame,f-number:step\n2,8\n")
    assert main(["process", src, "-o", str(tmp_path / "o.####.exr"), "--camera-track", str(t), "--iso", "200",
                 "--quiet"]) == 0
    for n, (focus, n_) in enumerate([(1.0, 8.0), (2.0, 8.0), (3.0, 8.0)], 1):
        a, s = exr.read_attributes(tmp_path / f"o.{n:04d}.exr")
        assert a["focus"] == focus and a["aperture"] == n_ and a["isoSpeed"] == 200.0
        assert s["clpost.focusDistance_m"] == f"{focus:g}" and s["clpost.fNumber"] == "8"


def test_cli_explain_prints_the_sources(tmp_path, capsys):
    src = _seq(tmp_path, [{"focus": 1.0}, {"focus": 2.5}])
    assert main(["process", src, "-o", str(tmp_path / "o.####.exr"), "--explain", "--f-number", "4"]) == 0
    out = capsys.readouterr().out
    assert "camera over 2 frame(s)" in out
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("focus_distance_m"))
    assert "1 … 2.5" in line and "[EXR focus]" in line
    assert "[flag --f-number]" in next(ln for ln in out.splitlines() if ln.strip().startswith("f_number"))
    assert main(["process", src, "-o", str(tmp_path / "o.####.exr"), "--explain", "--exr-camera", "off"]) == 0
    out = capsys.readouterr().out
    assert "[default]" in next(ln for ln in out.splitlines() if ln.strip().startswith("focus_distance_m"))


ODD = dict(lens="thin:47.3", f_number=2.0 / 3.0 * 5, focus_distance_m=1 / 3 + 2, shutter_s=1 / 47,
           iso=123.456, transmittance=0.8765, sensor_mm=(35.9, 23.9), noise_seed=7, depth_of_field=True,
           blades=7, blade_rotation_deg=12.5, aperture_roundness=0.3, frame_rate_fps=24000 / 1001,
           readout_time_s=0.0123, white_balance_k=5600.0, vignetting="natural",
           astigmatism_mm=0.05, coma_mm=0.02, lateral_color_mm=0.01, spherical_aberration=0.1)


def test_camera_from_an_output_gives_the_identical_camera(tmp_path):
    cam = Camera(**ODD)
    inp = tmp_path / "in.exr"
    exr.write_frame(inp, _frame(velocity=True))
    argv = ["process", str(inp), "-o", str(tmp_path / "o.exr"), "--quiet", "--exr-camera", "off"]
    for s in Camera.param_specs():
        if s.name in ODD:
            v = ODD[s.name]
            text = "x".join(f"{x!r}" for x in v) if isinstance(v, tuple) else ("on" if v is True else
                                                                                repr(v) if isinstance(v, float) else str(v))
            argv += [s.meta.flag, text]
    assert main(argv) == 0
    assert Camera(**camera_from_file(tmp_path / "o.exr")) == cam
    # and through the command line: processing again with --camera-from alone reproduces the output
    assert main(["process", str(inp), "-o", str(tmp_path / "o2.exr"), "--quiet", "--exr-camera", "off",
                 "--camera-from", str(tmp_path / "o.exr")]) == 0
    a, b = exr.read_frame(tmp_path / "o.exr"), exr.read_frame(tmp_path / "o2.exr")
    np.testing.assert_array_equal(a.color, b.color)
    assert {k: v for k, v in a.metadata["header"].items() if k.startswith("clpost.") and k != "clpost.source"} == \
           {k: v for k, v in b.metadata["header"].items() if k.startswith("clpost.") and k != "clpost.source"}


def test_camera_from_a_metered_output_gives_the_same_image(tmp_path):
    # the metered shutter already holds --ev: read back as a manual camera it must not apply it again
    inp = tmp_path / "in.exr"
    exr.write_frame(inp, _frame())
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    assert main(["process", str(inp), "-o", str(a), "--quiet", "--luminance-scale", "1000", "--shutter", "auto",
                 "--ev", "1", "--nd", "2"]) == 0
    assert main(["process", str(inp), "-o", str(b), "--quiet", "--camera-from", str(a)]) == 0
    np.testing.assert_array_equal(exr.read_frame(b).color, exr.read_frame(a).color)
    assert exr.read_frame(a).metadata["header"]["clpost.meteredCompensation_ev"] == "1"


def test_a_defaulted_iso_is_recorded_as_the_rule_not_as_a_number(tmp_path):
    # Camera(): ISO 100 by rule, and a film's box speed; read back or changed, the rule applies again
    assert Camera().describe()["clpost.iso"] == "box speed" and "isoSpeed" not in standard_attributes(Camera())
    assert Camera().with_(film="fuji-superia-400").iso == 400.0
    assert Camera(iso=200.0).with_(film="fuji-superia-400").iso == 200.0       # a given ISO stays
    inp = tmp_path / "in.exr"
    exr.write_frame(inp, _frame())
    a = tmp_path / "a.exr"
    assert main(["process", str(inp), "-o", str(a), "--quiet", "--film", "kodak-gold-200"]) == 0
    assert camera_from_file(a).get("iso") is None
    r = CameraSources(flags={"film": "fuji-superia-400"}, camera_from=camera_from_file(a),
                      camera_from_path=str(a)).resolve(0, exr.read_frame(a).metadata.get("attributes", {}))
    assert r.camera.iso == 400.0


def test_a_lens_traced_distortion_is_not_recorded_as_a_calibration():
    # the traced model belongs to the lens and the frame size: --camera-from traces it again at the
    # size of the frame it is used on, instead of pinning the first output's size as a calibration
    from clpost import Pipeline

    cam = Camera(lens="zeiss-planar-50-f1.4", f_number=2.0)
    traced = Pipeline(cam).camera_for(Frame(np.full((24, 40, 3), 0.2, np.float32)))
    assert traced.distortion is not None
    assert "clpost.distortion" not in traced.describe() and "clpost.distortion" not in cam.describe()


def test_camera_from_keeps_a_calibration_exactly(tmp_path):
    from clpost.calibration import OpenCVModel
    from clpost.camera_sources import values_from_header

    model = OpenCVModel(width=640, height=480, fx=501.123456789012, fy=500.5, cx=319.25, cy=239.75,
                        k1=-0.1234567890123, p1=1e-4)
    cam = Camera(distortion=model)
    assert Camera(**values_from_header(cam.describe(), "x.exr", Camera)) == cam


def test_camera_from_is_below_flags_and_above_tracks_and_attributes(tmp_path):
    inp = tmp_path / "in.exr"
    exr.write_frame(inp, _frame(), header={"focus": 9.0, "aperture": 16.0})
    assert main(["process", str(inp), "-o", str(tmp_path / "ref.exr"), "--quiet", "--focus", "2", "--f-number",
                 "2.8", "--iso", "400"]) == 0
    t = tmp_path / "t.json"
    t.write_text(json.dumps([{"frame": 0, "focus": 5.0, "iso": 50}]))
    assert main(["process", str(inp), "-o", str(tmp_path / "o.exr"), "--quiet", "--camera-from",
                 str(tmp_path / "ref.exr"), "--camera-track", str(t), "--iso", "800"]) == 0
    a, s = exr.read_attributes(tmp_path / "o.exr")
    assert a["focus"] == 2.0 and a["aperture"] == 2.8 and a["isoSpeed"] == 800.0


def test_camera_from_a_file_without_a_camera_is_one_line_exit_2(tmp_path, capsys):
    inp = tmp_path / "in.exr"
    exr.write_frame(inp, _frame())
    rc = main(["process", str(inp), "-o", str(tmp_path / "o.exr"), "--camera-from", str(inp)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "records no clpost camera" in err and str(inp) in err
    exr.write_frame(inp, _frame(), header={"clpost.fNumber": "fast"})
    rc = main(["process", str(inp), "-o", str(tmp_path / "o.exr"), "--camera-from", str(inp)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "clpost.fNumber='fast'" in err and "--f-number" in err
    rc = main(["process", str(inp), "-o", str(tmp_path / "o.exr"), "--camera-from", str(tmp_path / "nope.exr")])
    assert rc == 2 and "--camera-from" in capsys.readouterr().err and not (tmp_path / "o.exr").exists()


def test_a_zoom_from_nominal_focal_length_builds_one_plan_per_focal_length(tmp_path):
    from clpost import Pipeline
    from clpost.batch import FrameJob, process_sequence

    jobs = []
    for n, f in enumerate((35.0, 35.0, 50.0), 1):
        exr.write_frame(tmp_path / f"z.{n}.exr", _frame(), header={"nominalFocalLength": f, "focus": 2.0})
        jobs.append(FrameJob(n, tmp_path / f"z.{n}.exr", tmp_path / f"o.{n}.exr"))
    src = CameraSources(flags={"depth_of_field": True, "f_number": 1.4})
    pipe = Pipeline(src.resolve(1, {"nominalFocalLength": 35.0}).camera)
    rep = process_sequence(pipe, jobs, sources=src)
    assert rep.done == [1, 2, 3] and len(pipe._plans) == 2
    got = [exr.read_attributes(j.dst) for j in jobs]
    assert [a["nominalFocalLength"] for a, _ in got] == [35.0, 35.0, 50.0]
    assert [s["clpost.lens"] for _, s in got] == ["thin:35", "thin:35", "thin:50"]
