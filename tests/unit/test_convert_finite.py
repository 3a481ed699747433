"""``convert.all_finite``: the NaN/inf guard of the node glue, against ``math.isfinite``."""
import math

import numpy as np
import pytest

from adcs_nodes.core.samples import all_finite


def _truth(*arrays) -> bool:
    return all(math.isfinite(float(x)) for a in arrays for x in np.ravel(np.asarray(a, float)))


@pytest.mark.parametrize('arrays', [
    (np.zeros(3),),
    (np.array([1.0, 2.0, np.nan]),),
    (np.array([0.0, 0.0, 0.0, 1.0]), np.array([np.inf, 0.0, 0.0])),
    (np.array([1e308, -1e308, 5e-324]),),
    ([1.0, -np.inf],),
    (np.eye(3), np.ones((2, 2))),
    (np.zeros(36),), (np.r_[np.zeros(40), np.inf],), (np.r_[np.nan, np.zeros(40)],),
    (np.arange(5), np.zeros(16), np.r_[np.zeros(16), np.nan]),
    (np.full((4, 4), -np.inf),), (np.zeros((6, 6)), np.array([1.0])),
    (0.5,),
    (float('nan'),),
    (),
])
def test_all_finite_matches_math_isfinite(arrays):
    assert all_finite(*arrays) is _truth(*arrays)
