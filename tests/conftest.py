import os

import numpy as np
import pytest

# Keep hypothesis quick and deterministic on the 2-core CI machine.
from hypothesis import settings

settings.register_profile("ci", max_examples=25, deadline=None, derandomize=True)
settings.load_profile("ci")


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def odd_frame(rng, w=37, h=23, scale=10.0, depth=True):
    """A small odd-sized HDR frame (odd sizes catch x/y and stride mix-ups)."""
    from clpost import Frame

    color = (rng.random((h, w, 3)) * scale).astype(np.float32)
    d = rng.uniform(0.2, 50.0, (h, w)).astype(np.float32) if depth else None
    return Frame(color, depth=d)
