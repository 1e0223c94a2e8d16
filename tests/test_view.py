"""clpost view without a browser: controls generated from the declarations, scalar changes reuse
the plan and structural ones rebuild it, tap-to-focus reads the depth pass, the command line and
the camera track reproduce the camera, exposure tools, and the command's input checks."""
from __future__ import annotations

import json
import shlex

import numpy as np
import pytest

from clpost.camera import Camera
from clpost.camera_track import load_track
from clpost.cli import build_parser, camera_from_args
from clpost.errors import InputError
from clpost.frame import Frame
from clpost.view.controls import controls, parse_text
from clpost.view.session import ViewSession, ab_split, false_colour, histogram, zebras


def scene(w=96, h=64):
    """A checker texture: near (1 m) on the left half, far (20 m) on the right half."""
    yy, xx = np.mgrid[0:h, 0:w]
    tex = (((xx // 4) + (yy // 4)) % 2).astype(np.float32) * 0.8 + 0.1
    color = np.repeat(tex[..., None], 3, axis=2)
    depth = np.where(xx < w // 2, 1.0, 20.0).astype(np.float32)
    return Frame(color=color, depth=depth)


def session(**cam):
    f = scene()
    camera = Camera(**{"lens": "thin:50", "depth_of_field": True, "f_number": 1.4, "focus_distance_m": 20.0,
                       "exposure_compensation_ev": 0.5, **cam})
    return ViewSession([1], lambda i: f, camera, "in.####.exr", final_quality="draft")


def test_every_flagged_parameter_has_a_control_with_its_declaration():
    by_name = {c.name: c for c in controls()}
    for s in Camera.param_specs():
        if s.meta.flag is None or s.meta.input_only:
            assert s.name not in by_name
            continue
        c = by_name[s.name]
        assert c.flag == s.meta.flag and c.scalar == s.meta.scalar
    assert by_name["depth_of_field"].kind == "switch"
    assert by_name["working_space"].kind == "select" and set(by_name["working_space"].choices) == {"rec709", "acescg"}
    # bounds come from the check: transmittance is in (0, 1]
    t = by_name["transmittance"]
    assert t.kind == "slider" and (t.lo, t.hi) == (0.0, 1.0) and not t.log
    f = by_name["f_number"]
    assert f.kind == "slider" and f.log and f.from_slider(f.to_slider(4.0)) == 4.0
    assert by_name["blades"].integer and by_name["sensor_mm"].kind == "text"


def test_text_is_read_as_the_flag_reads_it():
    assert parse_text("shutter_s", "1/50") == pytest.approx(0.02)
    assert parse_text("shutter_s", "auto") is None
    assert parse_text("sensor_mm", "36x24") == (36.0, 24.0)
    with pytest.raises(InputError, match="--f-number"):
        parse_text("f_number", "f2")


def test_scalar_change_reuses_the_plan_and_structural_rebuilds():
    s = session()
    first = s.render(0, "draft")
    assert first.built and "dof" in first.stages
    s.set_camera(s.with_values({"f_number": 2.0, "focus_distance_m": 5.0, "exposure_compensation_ev": 1.0}))
    again = s.render(0, "draft")
    assert not again.built, (first.stages, again.stages)
    assert not np.array_equal(again.display, first.display)
    s.set_camera(s.with_values({"blades": 6}))
    assert s.render(0, "draft").built


def test_tap_to_focus_reads_the_depth_pass_and_sharpens_there():
    s = session()
    assert s.focus_at(0, 10, 30) == pytest.approx(1.0)
    assert s.focus_at(0, 80, 30) == pytest.approx(20.0)
    far = s.render(0, "draft").linear
    s.set_camera(s.with_values({"focus_distance_m": s.focus_at(0, 10, 30)}))
    near = s.render(0, "draft").linear

    def contrast(img):  # the left (near) half's checker edges: gradient energy (a blur of k px
        a = img[8:-8, 8:40, 1]  # spreads each step over k px and divides it by about k)
        return float((np.diff(a, axis=1) ** 2).mean())

    assert contrast(near) > 2 * contrast(far)
    s_nodepth = ViewSession([1], lambda i: Frame(color=scene().color), s.camera, "x.exr")
    with pytest.raises(InputError, match="no depth pass"):
        s_nodepth.focus_at(0, 1, 1)


def test_command_line_gives_the_same_camera():
    s = session(blades=7, shutter_s=1 / 100)
    s.set_camera(s.with_values({"f_number": 2.8}))
    line = s.command()
    args = build_parser().parse_args(shlex.split(line)[1:])
    assert args.input == "in.####.exr"
    assert camera_from_args(args) == s.camera


def test_camera_track_round_trips(tmp_path):
    s = session(blades=7)
    s.set_camera(s.with_values({"focus_distance_m": 2.5}))
    s.add_key(0)
    p = s.save_track(tmp_path / "t.json", 0)
    track = load_track(p)
    got = track.values_at(1)
    for k in ("focus_distance_m", "blades", "f_number", "depth_of_field"):
        assert got[k] == getattr(s.camera, k)
    with pytest.raises(InputError, match="exists"):
        s.save_track(p, 0)
    assert json.loads(p.read_text())["keys"][0]["frame"] == 1


def test_exposure_tools():
    disp = np.zeros((20, 30, 3), np.uint8)
    disp[:, 15:] = 250
    z = zebras(disp)
    assert (z[:, :15] == 0).all() and set(np.unique(z[:, 15:])) == {0, 255}
    lin = np.full((4, 4, 3), 0.18, np.float32)
    lin[0] = 4.0
    fc = false_colour(lin)
    assert tuple(fc[1, 1]) == (150, 150, 150) and tuple(fc[0, 0]) == (230, 20, 20)
    h1, h2 = histogram(disp), histogram(disp // 2)
    assert h1.shape == (100, 256, 3) and not np.array_equal(h1, h2)
    a, b = np.zeros((4, 10, 3), np.uint8), np.full((4, 10, 3), 9, np.uint8)
    ab = ab_split(a, b, 0.5)
    assert (ab[:, :5] == 0).all() and (ab[:, 6:] == 9).all()


@pytest.mark.parametrize("name", ["missing.exr", "missing.####.exr", "nodir/in.####.exr", "."])
def test_bad_input_fails_like_process(name, tmp_path, capsys):
    """The same one line and exit status 2 as `clpost process` for the same input."""
    from clpost.cli import main

    src = str(tmp_path / name)
    out = str(tmp_path / ("out.####.exr" if "#" in name else "out.exr"))
    assert main(["process", src, "-o", out]) == 2
    expected = capsys.readouterr().err.strip()
    assert main(["view", src, "--no-browser", "--port", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err == expected


def test_binds_loopback_only():
    from clpost.view.command import HOST, _check_port

    assert HOST == "127.0.0.1"
    port = _check_port(0)
    import socket

    with socket.socket() as s:
        s.bind((HOST, port))
        s.listen()
        with pytest.raises(InputError, match="in use"):
            _check_port(port)


@pytest.mark.parametrize("working_space, display", [("rec709", "srgb"), ("acescg", "srgb"), ("rec709", "display-p3")])
def test_table_display_encoding_matches_the_exact_one(working_space, display):
    from clpost.colorspace import display_encode
    from clpost.view.session import fast_display_encode

    rng = np.random.default_rng(3)
    lin = (rng.random((64, 64, 3)) ** 3 * 1.3).astype(np.float32)  # darks densely, and over 1
    exact = display_encode(lin, working_space, display, 8).astype(int)
    fast = fast_display_encode(lin, working_space, display).astype(int)
    assert np.abs(fast - exact).max() <= 1
    assert (fast == exact).mean() > 0.99


def test_a_camera_that_fails_to_render_is_put_back(monkeypatch):
    """The page keeps working after a setting the pipeline refuses: one line, the last camera back."""
    pytest.importorskip("trame")
    import asyncio

    from clpost.view.app import ViewApp

    app = ViewApp(session())
    good = app.session.camera

    async def show():
        await app._show(asyncio.get_running_loop(), "draft")

    def fail(*a):
        raise InputError("Camera.blades=7: refused for this test")

    app.apply({"blades": 7}, "blades")
    monkeypatch.setattr(app, "_render_page", fail)
    asyncio.run(show())
    assert "refused for this test" in app.server.state.error and "last working" not in app.server.state.error
    app._good = good
    app.apply({"blades": 8}, "blades")
    asyncio.run(show())
    assert app.session.camera == good and "last working settings" in app.server.state.error
    assert app.server.state["p_blades"] == "0"
    app.close()


def test_sequence_frames_are_scrubbed_and_cached():
    frames = [scene(), scene().replace(color=scene().color * 0.25)]
    loads = []

    def load(i):
        loads.append(i)
        return frames[i]

    camera = Camera(lens="thin:50", exposure_compensation_ev=0.5)
    s = ViewSession([101, 102], load, camera, "in.####.exr")
    a, b = s.render(0, "draft"), s.render(1, "draft")
    assert not np.array_equal(a.display, b.display)
    s.render(0, "draft")
    assert loads == [0, 1]
    s.add_key(1)
    assert json.loads(s.track_json(1))["keys"][0]["frame"] == 102


@pytest.mark.slow
def test_lens_datasheet_for_traced_lenses_only():
    pytest.importorskip("matplotlib")
    import base64

    from clpost.view.session import lens_datasheet

    assert lens_datasheet(Camera(lens="thin:50")) is None
    url = lens_datasheet(Camera(lens="zeiss-planar-50-f1.4", focus_distance_m=3.0))
    assert url.startswith("data:image/png;base64,")
    assert base64.b64decode(url.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"
