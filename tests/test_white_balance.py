"""white_balance: the Planckian white of the setting renders neutral; kernel vs the float64 oracle."""
import colour
import numpy as np
import pytest

from clpost import Camera, Frame, Pipeline
from clpost.errors import InputError
from clpost.stages.white_balance import white_balance_matrix

from conftest import assert_planned, odd_frame


def planckian_rgb(t_k, space="ITU-R BT.709"):
    """A blackbody's white in linear working RGB, by colour-science's own path (not the stage's)."""
    cs = colour.RGB_COLOURSPACES[space]
    xyz = colour.xy_to_XYZ(colour.temperature.CCT_to_xy(t_k, method="Kang 2002"))
    return np.linalg.solve(cs.matrix_RGB_to_XYZ, xyz)


@pytest.mark.parametrize("t_k", [1900.0, 3200.0, 5500.0, 10000.0])
@pytest.mark.parametrize("working_space, cs", [("rec709", "ITU-R BT.709"), ("acescg", "ACEScg")])
def test_the_setting_white_renders_neutral_as_the_working_white(t_k, working_space, cs):
    out = white_balance_matrix(t_k, working_space) @ planckian_rgb(t_k, cs)
    np.testing.assert_allclose(out / out[1], [1.0, 1.0, 1.0], atol=1e-9)
    assert np.all(out > 0)


def test_tungsten_setting_in_daylight_is_blue_and_daylight_under_tungsten_orange(rng):
    grey = np.full((1, 1, 3), 0.18, np.float32)
    frame = Frame(grey)
    blue = Pipeline(Camera(white_balance_k=3200.0), stages=["white_balance"]).run(frame).color[0, 0]
    assert blue[2] > blue[1] > blue[0]
    lit = Frame(np.asarray(planckian_rgb(3200.0), np.float32)[None, None] * np.float32(0.18))
    orange = Pipeline(Camera(white_balance_k=6500.0), stages=["white_balance"]).run(lit).color[0, 0]
    assert orange[0] > orange[1] > orange[2]


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_kernel_matches_reference_on_odd_sizes(rng, quality):
    frame = odd_frame(rng, w=37, h=23, scale=20.0)
    pipe = Pipeline(Camera(white_balance_k=4100.0, working_space="acescg"), stages=["white_balance"],
                    quality=quality)
    assert_planned(pipe, frame, "white_balance")
    np.testing.assert_allclose(pipe.run(frame).color, pipe.reference(frame), rtol=2e-6, atol=1e-6)


def test_unset_is_not_planned_and_the_image_is_unchanged(rng):
    frame = odd_frame(rng)
    pipe = Pipeline(Camera(), stages=["white_balance"])
    assert "white_balance" not in pipe.plan(frame)
    np.testing.assert_array_equal(pipe.run(frame).color, frame.color)


def test_a_white_balance_pull_changes_only_scalars(rng):
    frame = odd_frame(rng)
    pipe = Pipeline(Camera(white_balance_k=3000.0), stages=["white_balance"])
    plan = pipe.plan_for(frame)
    for t in (3000.0, 4000.0, 6000.0):
        cam = pipe.camera.with_(white_balance_k=t)
        assert pipe.plan_for(frame, cam) is plan
        np.testing.assert_allclose(plan.run(frame, cam).color, Pipeline(cam, stages=["white_balance"]).reference(frame),
                                   rtol=2e-6, atol=1e-6)


@pytest.mark.parametrize("bad", [500.0, 40000.0, float("nan"), "warm"])
def test_out_of_range_or_not_a_number_is_one_line(bad):
    with pytest.raises(InputError) as e:
        Camera(white_balance_k=bad)
    msg = str(e.value)
    assert "\n" not in msg and "white_balance_k" in msg and "e.g. 3200" in msg
