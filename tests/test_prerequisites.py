"""Stage prerequisites (``Stage.requires``): a stage whose input is another stage's output never runs
without it — the planner refuses with one line naming the missing stage and the fix."""
from __future__ import annotations

import numpy as np
import pytest

from clpost import Camera, Frame, Pipeline, exr
from clpost.cli import main
from clpost.errors import InputError
from clpost.stages import registry

# cameras for which the stages with a prerequisite, and their prerequisites, change the image (a
# camera records on film or on a sensor, not both)
FILM = Camera(luminance_scale=1.0, f_number=4.0, shutter_s=1 / 100, iso=200.0, film="kodak-ektar-100")
SENSOR = Camera(luminance_scale=1.0, f_number=4.0, shutter_s=1 / 100, iso=200.0, sensor_preset="apsc-cmos")
RAW = Camera(luminance_scale=1.0, f_number=4.0, shutter_s=1 / 100, iso=200.0, raw_calibration="a7s2-like", isp=True)
HALATION = FILM.with_(halation=True)
DOF = Camera(luminance_scale=1.0, f_number=1.4, focus_distance_m=2.0, depth_of_field=True, sensor_mm=(0.3, 0.2))


def _camera(name):
    closure = _closure(name)
    if "halation" in closure:
        return HALATION
    if "dof" in closure:  # front_layer: composites over dof's background
        return DOF
    return SENSOR if "sensor" in closure else RAW if "raw" in closure else FILM


def _pairs():
    return [(name, req) for name, cls in registry().items() for req in cls.requires]


def _closure(name: str) -> set[str]:
    """``name`` and everything it requires, transitively."""
    out, todo = set(), [name]
    while todo:
        n = todo.pop()
        if n not in out:
            out.add(n)
            todo.extend(registry()[n].requires)
    return out


def _frame(w=7, h=5, highlight=False, front=False):
    """A dim frame; ``highlight``: with one lamp bright enough for halation to be planned;
    ``front``: with depth (out of focus) and a front layer."""
    from clpost.frame import front_layer

    rng = np.random.default_rng(3)
    color = (rng.random((h, w, 3)) * 0.5 + 0.05).astype(np.float32)
    if highlight:
        color[h // 2, w // 2] = 5000.0
    if not front:
        return Frame(color)
    a = np.zeros((h, w), np.float32)
    a[1:3, 1:4] = 1.0
    return Frame(color, depth=rng.uniform(0.5, 20.0, (h, w)).astype(np.float32),
                 front=front_layer(color * a[..., None], a, np.full((h, w), 0.5, np.float32)))


def test_the_declared_prerequisites():
    """What the stages' docstrings presuppose: grain and print work on film densities, film and
    sensor on the exposure stage's normalised signal; every name is a stage."""
    pairs = set(_pairs())
    assert {("grain", "film"), ("print", "film"), ("film", "exposure"), ("sensor", "exposure")} <= pairs
    for name, req in pairs:
        assert req in registry(), f"{name} requires unknown stage {req!r}"
        assert registry()[req].order < registry()[name].order, f"{req} must come before {name}"


@pytest.mark.parametrize("name,req", _pairs())
def test_a_stage_without_its_prerequisite_is_refused(name, req):
    frame, cam = _frame(highlight="halation" in _closure(name), front="front_layer" in _closure(name)), _camera(name)
    selected = sorted(_closure(name) - {req}, key=lambda n: registry()[n].order)
    with pytest.raises(InputError) as exc:
        Pipeline(cam, stages=selected).plan(frame)
    msg = str(exc.value)
    assert "\n" not in msg and f"'{name}'" in msg and f"'{req}'" in msg
    fix = msg.rsplit("--stages ", 1)[1].split(",")
    assert req in fix and set(selected) <= set(fix)  # the fix: the selection plus the missing stage
    # the fix works, and so does declaring that the input already carries the prerequisite
    assert name in Pipeline(cam, stages=fix).plan(frame)
    assert name in Pipeline(cam, stages=selected, already_applied=(req,)).plan(frame)


def test_a_prerequisite_that_is_an_identity_for_this_camera_need_not_be_selected():
    """grain without film selected, for a camera without film: grain is not planned, no error."""
    cam = Camera(luminance_scale=1.0, f_number=4.0, shutter_s=1 / 100)
    assert Pipeline(cam, stages=["grain"]).plan(_frame()) == []


def test_library_run_refuses_grain_without_film():
    with pytest.raises(InputError, match=r"'grain'.*'film'.*--stages exposure,film,grain"):
        Pipeline(Camera(luminance_scale=1.0, film="kodak-ektar-100"), stages=["grain"]).run(_frame())


def test_unknown_already_applied_stage():
    with pytest.raises(InputError, match="already_applied: unknown stage"):
        Pipeline(FILM, already_applied=("negative",))


def test_cli_grain_with_film_but_without_the_film_stage(tmp_path, capsys):
    src, out = tmp_path / "grey.exr", tmp_path / "out.exr"
    exr.write_frame(src, Frame(np.full((4, 6, 3), 0.18, np.float32)))
    rc = main(["process", str(src), "-o", str(out), "--stages", "grain", "--film", "kodak-ektar-100",
               "--luminance-scale", "1"])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert "'film'" in err and "--stages exposure,film,grain" in err
    assert not out.exists() and not list(tmp_path.glob(".out*"))
    # the fix the message gives runs
    assert main(["process", str(src), "-o", str(out), "--stages", "exposure,film,grain", "--film",
                 "kodak-ektar-100", "--luminance-scale", "1", "--quiet"]) == 0
    assert out.exists()
