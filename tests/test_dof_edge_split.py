"""gather_reference's two-source form (``split``), the measurement behind docs/fidelity.md,
"Splitting the edge pixels into two layers" (tools/dof_edge_split.py): zero shares are the
one-source gather to the bit, and an anti-aliased edge pixel's foreground share spreads with the
foreground's CoC while its background share stays sharp."""
import numpy as np

from clpost.stages import dof as D


def gather(color, coc, split=None):
    return D.gather_reference(color, coc, 64, 8, 0, 0.0, 0.0, 0.0, 0.0, split=split)


def test_zero_shares_are_the_one_source_gather(rng):
    color = rng.uniform(0, 1, (40, 52, 3))
    coc = np.where(rng.uniform(size=(40, 52)) < 0.3, -5.0, 0.2) + rng.normal(0, 0.3, (40, 52))
    other = rng.uniform(0, 1, (40, 52, 3))
    out, alpha = gather(color, coc)
    out2, alpha2 = gather(color, coc, (color, other, np.zeros_like(coc), coc - 3.0))
    np.testing.assert_array_equal(out2, out)
    np.testing.assert_array_equal(alpha2, alpha)


def test_edge_pixels_foreground_share_spreads_with_the_foreground_coc():
    # a black bar (CoC -5 px) over an in-focus white wall; the column beside the bar holds the
    # bar's anti-aliased edge: colour (1 - a) white, depth (hence CoC) the wall's
    h, w, a, r_fg = 48, 64, 0.4, -5.0
    color = np.ones((h, w, 3))
    coc = np.zeros((h, w))
    color[:, :24] = 0.0
    coc[:, :24] = r_fg
    color[:, 24] = 1.0 - a
    one, alpha1 = gather(color, coc)
    b = np.zeros((h, w))
    b[:, 24] = a
    dsrc = color.copy()
    dsrc[:, 24] = 1.0  # the edge pixel's own (wall) share: the wall's colour
    two, alpha2 = gather(color, coc, (dsrc, np.zeros((h, w, 3)), b, np.full((h, w), r_fg)))
    rows = slice(12, 36)  # away from the bar's ends
    # one source: the edge pixel's mix stays a sharp grey line in the wall (bg pool = its own colour)
    bg1 = one[rows, 24, 1] / (1 - alpha1[rows, 24])
    np.testing.assert_allclose(bg1, 1.0 - a, atol=1e-9)
    # split: behind the bar's blur the wall at the edge column is white again ...
    bg2 = two[rows, 24, 1] / (1 - alpha2[rows, 24])
    np.testing.assert_allclose(bg2, 1.0, atol=0.01)
    # ... and the share a of the column became front coverage spread over the bar's disc: on the
    # wall's side (the bar's own pixels see a source at their own depth, not in front) that is the
    # disc's part at x >= 23.5, 0.5-0.65 of it (a 5-px disc and its 1-px ramp), reaching 4 px out
    gain = (alpha2 - alpha1)[rows].sum(axis=1)
    assert np.all((gain > 0.5 * a) & (gain < 0.65 * a)), gain
    assert np.all((alpha2 - alpha1)[rows, 24 + 4] > 0.01)
    assert np.all(alpha2[rows, 24 + 7:] == alpha1[rows, 24 + 7:])
