"""Kernels compiled only in a process that needs numba (``adcs_nodes.core.kernels.jit``).

A kernel is a :class:`~adcs_nodes.core.kernels.Lazy` until a kernel that loads numba is called
(``jit(loads_numba=True)``): before, it runs as its plain Python function; then every kernel
becomes its numba dispatcher, also where a module imported it, so compiled kernels call
compiled kernels. The bits of the two ways: ``tests/graph/test_fresh_interpreters.py``.
"""
import importlib
import sys

import numpy as np
import pytest

from adcs_nodes.core import kernels

numba = pytest.importorskip('numba')

MODULE = '''
import numpy as np
from adcs_nodes.core.kernels import Lazy



def _twice(x):
    return 2.0 * x


def _quad(v):
    out = np.empty(v.shape[0])
    for i in range(v.shape[0]):
        out[i] = twice(v[i]) * v[i]
    return out


twice = Lazy(_twice, loads_numba=False)
quad = Lazy(_quad, loads_numba=True)
'''


@pytest.fixture
def module(tmp_path, monkeypatch):
    (tmp_path / 'lazy_kernels_probe.py').write_text(MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    mod = importlib.import_module('lazy_kernels_probe')
    yield mod
    sys.modules.pop('lazy_kernels_probe', None)


def test_a_small_kernel_runs_as_python_until_numba_is_loaded(module):
    assert isinstance(module.twice, kernels.Lazy)
    assert module.twice(1.5) == 3.0 and module.twice.dispatcher is None     # plain Python
    assert module.twice.__name__ == '_twice' and module.twice.py_func is module._twice


def test_a_kernel_that_loads_numba_compiles_every_kernel_and_replaces_them(module):
    lazy_twice = module.twice
    v = np.array([1.0, -2.0, 0.5])
    out = module.quad(v)                     # loads numba: every kernel becomes a dispatcher
    np.testing.assert_array_equal(out, 2.0 * v * v)
    for name in ('twice', 'quad'):
        assert isinstance(getattr(module, name), numba.core.registry.CPUDispatcher), name
    # quad's compiled code calls the compiled twice (numba types only dispatchers)
    assert module.twice.signatures
    # a reference taken before goes on to the dispatcher
    assert lazy_twice.dispatcher is module.twice


def test_once_numba_is_loaded_jit_returns_the_dispatcher():
    kernels.compile_all()
    compiled = kernels.jit(lambda x: x + 1.0)
    assert isinstance(compiled, numba.core.registry.CPUDispatcher)
    assert kernels.jit(loads_numba=True)(lambda x: x)(2.0) == 2.0
