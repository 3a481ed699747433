"""The compiled random-torque draw (D3): PCG64 and numpy's ziggurat in numba give
``default_rng([seed, key]).standard_normal(3)`` bit for bit, on both rejection paths of the
ziggurat (the wedge and the tail), and :meth:`RandomTorque.add_to` fills a frame's substeps
with the same bits as :meth:`RandomTorque.torque` at each midpoint."""
import numpy as np
import pytest

from adcs_nodes.core.lockstep import derive_seed
from sim_node.models import disturbances as dist
from sim_node.models.disturbances import RandomTorque, standard_normal3

pytestmark = pytest.mark.skipif(not dist._compiled(), reason='numba JIT off: the Python path')

SEED = derive_seed(21, 'dynamics/disturbance')


def bits(x):
    return np.asarray(x, dtype=np.float64).view(np.uint64)


def _paths(seed, key):
    """Which ziggurat paths the first normal of (seed, key) takes: 'fast', 'wedge', 'tail'."""
    st = dist.pcg64_seeded(np.uint64(seed), np.uint64(key))
    r = int(dist.pcg64_next64(st))
    idx, rabs = r & 0xFF, (r >> 9) & 0x000FFFFFFFFFFFFF
    if rabs < int(dist._KI[idx]):
        return 'fast'
    return 'tail' if idx == 0 else 'wedge'


def test_pcg64_state_and_words_are_numpys():
    for seed, key in ((0, 0), (1, 2**32), (2**64 - 1, 2**63), (SEED, 12345)):
        want = np.random.default_rng([seed, key]).bit_generator
        st = dist.pcg64_seeded(np.uint64(seed), np.uint64(key))
        state = want.state['state']
        assert (int(st[0]) << 64) | int(st[1]) == state['state']
        assert (int(st[2]) << 64) | int(st[3]) == state['inc']
        words = want.random_raw(5)
        assert [int(dist.pcg64_next64(st)) for _ in range(5)] == [int(w) for w in words]


def test_every_ziggurat_path_equals_default_rng():
    seen = set()
    for key in range(30000):
        seen.add(_paths(SEED, key))
        np.testing.assert_array_equal(bits(standard_normal3(SEED, key)),
                                      bits(np.random.default_rng([SEED, key])
                                           .standard_normal(3)), err_msg=f'key {key}')
    assert seen == {'fast', 'wedge', 'tail'}


@pytest.mark.parametrize('period, h, t0', [(0.1, 0.1, 0.0), (0.7, 0.1, 3.0), (0.05, 0.1, 1.0),
                                           (2.0, 0.1, -0.35), (0.1, 0.1, 35480.0)])
def test_add_to_is_torque_at_each_midpoint(period, h, t0):
    std = np.array([1e-5, 2e-5, 5e-6])
    fast, slow = RandomTorque(std, period, SEED), RandomTorque(std, period, SEED)
    for frame in range(6):
        t = t0 + frame * 10 * h
        table = np.full((10, 3), 1e-6)          # a constant torque added first
        fast.add_to(table, t, h)
        want = np.full((10, 3), 1e-6)
        for i in range(10):
            want[i] += slow.torque(t + i * h + 0.5 * h)
        np.testing.assert_array_equal(bits(table), bits(want))
