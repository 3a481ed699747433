"""The random torque's draw (D3) on one reseeded PCG64 gives numpy's ``default_rng`` bits.

Truth: ``numpy.random.default_rng([seed, key]).standard_normal(3)``, numpy's own SeedSequence
and PCG64, for seeds and keys of one and two 32-bit words, the edges of each, 64-bit seeds as
``derive_seed`` makes them, and the values the fallback path takes (>= 2**64).
"""
import numpy as np
import pytest

from adcs_nodes.core.lockstep import derive_seed
from sim_node.models.disturbances import RandomTorque, pcg64_seed_words, standard_normal3


def cases():
    rng = np.random.default_rng(2026)
    edges = [0, 1, 2**32 - 1, 2**32, 2**63 - 1, 2**63, 2**64 - 1]
    out = [(a, b) for a in edges for b in edges]
    out += [(int(a), int(b)) for a, b in zip(rng.integers(0, 2**31, 300),
                                             rng.integers(0, 2**40, 300))]
    out += [(int(a), int(b)) for a, b in zip(
        rng.integers(0, 2**64 - 1, 300, dtype=np.uint64, endpoint=True),
        rng.integers(0, 2**64 - 1, 300, dtype=np.uint64, endpoint=True))]
    out += [(derive_seed(21, 'dynamics/disturbance'), k) for k in range(300)]
    out += [(2**64, 3), (5, 2**70)]                      # beyond two words: numpy itself
    return out


def bits(x):
    return np.asarray(x, dtype=np.float64).view(np.uint64)


def test_standard_normal3_equals_default_rng_bit_for_bit():
    for seed, key in cases():
        want = np.random.default_rng([seed, key]).standard_normal(3)
        np.testing.assert_array_equal(bits(standard_normal3(seed, key)), bits(want),
                                      err_msg=f'seed {seed}, key {key}')


def test_seed_words_compiled_and_python_agree_with_seedsequence():
    python = getattr(pcg64_seed_words, 'py_func', pcg64_seed_words)
    for seed, key in cases()[:200]:
        words = []
        for v in (seed, key):
            words += [v & 0xFFFFFFFF] + ([v >> 32] if v >> 32 else [])
        ent = np.zeros(4, np.int64)
        ent[:len(words)] = words
        want = np.random.SeedSequence([seed, key]).generate_state(8, np.uint32)
        for fn in (pcg64_seed_words, python):
            np.testing.assert_array_equal(fn(ent, len(words)), want.astype(np.int64))


def test_random_torque_draw_is_the_documented_default_rng_draw():
    std = np.array([1e-5, 2e-5, 5e-6])
    d = RandomTorque(std, 0.1, seed=derive_seed(21, 'dynamics/disturbance'))
    for j in (-3, -1, 0, 1, 2, 12345, 354840):
        key = 2 * j if j >= 0 else -2 * j - 1
        want = std * np.random.default_rng([d.seed, key]).standard_normal(3)
        np.testing.assert_array_equal(bits(d.draw(j)), bits(want))
        assert d.torque((j + 0.5) * 0.1) == pytest.approx(want, abs=0.0)
