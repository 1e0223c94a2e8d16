import numpy as np
import pytest

from clpost import Frame, InputError


def test_accepts_half_and_double_once_as_float32(rng):
    c = rng.random((5, 7, 3))
    for dt in (np.float16, np.float32, np.float64):
        f = Frame(c.astype(dt), depth=np.full((5, 7), np.inf, dt))
        assert f.color.dtype == np.float32 and f.depth.dtype == np.float32
        assert f.color.flags.c_contiguous
        assert np.isinf(f.depth).all()
    assert f.size == (7, 5)


def test_rgba_is_split_into_color_and_alpha(rng):
    c = rng.random((4, 6, 4)).astype(np.float32)
    f = Frame(c)
    assert f.color.shape == (4, 6, 3)
    np.testing.assert_array_equal(f.alpha, c[:, :, 3])


def test_integer_color_is_refused_not_cast():
    with pytest.raises(InputError, match="uint8.*linear float"):
        Frame(np.zeros((4, 4, 3), np.uint8))


@pytest.mark.parametrize("buffer, value, words", [
    ("color", np.nan, "color: 1 pixel\\(s\\) are NaN, first at \\(x=2, y=1\\)"),
    ("color", np.inf, "color: 1 pixel\\(s\\) are ±inf"),
    ("depth", np.nan, "depth: 1 pixel\\(s\\) are NaN"),
    ("depth", -np.inf, "depth: 1 pixel\\(s\\) are <= 0"),
    ("depth", 0.0, "depth: 1 pixel\\(s\\) are <= 0 or -inf, first at \\(x=2, y=1\\)"),
    ("velocity", np.nan, "velocity: 1 pixel\\(s\\) are NaN"),
    ("velocity", np.inf, "velocity: 1 pixel\\(s\\) are ±inf"),
    ("alpha", 1.5, "alpha: 1 pixel\\(s\\) are outside"),
])
def test_each_violation_names_buffer_count_and_first_pixel(buffer, value, words):
    bufs = dict(color=np.ones((3, 4, 3), np.float32), depth=np.ones((3, 4), np.float32),
                velocity=np.zeros((3, 4, 2), np.float32), alpha=np.ones((3, 4), np.float32))
    bufs[buffer][1, 2] = value
    with pytest.raises(InputError, match=words):
        Frame(**bufs)


def test_depth_plus_inf_is_valid_sky():
    f = Frame(np.ones((2, 2, 3)), depth=np.array([[np.inf, 1.0], [2.0, np.inf]]))
    assert np.isposinf(f.depth).sum() == 2


@pytest.mark.parametrize("kw, words", [
    (dict(depth=np.ones((3, 3))), "depth: shape"),
    (dict(velocity=np.ones((2, 3, 3))), "velocity: shape"),
    (dict(alpha=np.ones((2, 2))), "alpha: shape"),
])
def test_shape_mismatch(kw, words):
    with pytest.raises(InputError, match=words):
        Frame(np.ones((2, 3, 3)), **kw)


def test_bad_color_shape_says_channels_last():
    with pytest.raises(InputError, match="channels last"):
        Frame(np.ones((3, 2, 3)).transpose(2, 0, 1))
