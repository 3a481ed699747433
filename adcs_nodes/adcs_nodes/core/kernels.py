"""Hot-path math kernels shared by the cores (one definition each; pure numpy, numba-compiled).

Scalar-last Hamilton quaternions ``q = [x, y, z, w]`` (DESIGN section 4)::

    p (x) q = [pw qv + qw pv + pv x qv,  pw qw - pv . qv]                        (K1)
    R(q)    = the rotation matrix of q / |q| (rotates vectors of the frame q maps from) (K2)
    a x b, [v]x (skew: [v]x u = v x u), M v, A B                                  (K3)

These functions take float64 numpy arrays and skip input checks: they are the inner loops of
the integrators and filters. Checked, user-facing versions are in
:mod:`adcs_nodes.core.attitude` (and :func:`finite_vector` here is the one "finite array or
``ValueError``" check). :func:`jit` compiles with numba (``cache=True``, no fastmath: IEEE
arithmetic in the order written); the same functions run as plain Python with
``NUMBA_DISABLE_JIT=1`` or without numba, and give the same bits. A process imports numba only
when it calls a kernel that loads it (the RK4 frame, the filter: ~0.5 s CPU with the first
cache load); until then the small kernels run as plain Python, the same bits.
"""
from __future__ import annotations

import functools
import math
import sys

import numpy as np
from numpy.typing import ArrayLike

#: The kernels not compiled yet (:class:`Lazy`).
_LAZY: list = []
#: ``[numba.njit]`` (``[False]`` without numba) once a kernel loaded numba.
_NJIT: list = []


class Lazy:
    """A kernel before numba is loaded (:func:`jit`): called, it runs as plain Python or
    (``loads_numba``) first loads numba and compiles every kernel (:func:`compile_all`)."""

    def __init__(self, fn, loads_numba: bool) -> None:
        functools.update_wrapper(self, fn)
        self.py_func, self.dispatcher, self.loads_numba = fn, None, loads_numba
        _LAZY.append(self)

    def __call__(self, *args):
        if self.dispatcher is None and self.loads_numba:
            compile_all()
        return (self.py_func if self.dispatcher is None else self.dispatcher)(*args)


def compile_all() -> None:
    """Load numba; every kernel becomes its ``njit(cache=True)`` dispatcher (compiled at its
    first call, or loaded from numba's on-disk cache), also where a module imported it."""
    if not _NJIT:
        try:
            from numba import njit
        except ImportError:  # pragma: no cover - numba is pinned in ros2_ws/requirements.txt
            njit = False
        _NJIT.append(njit)
    done = {}
    for k in _LAZY:
        k.dispatcher = done[id(k)] = _NJIT[0](cache=True)(k.py_func) if _NJIT[0] else k.py_func
    _LAZY.clear()
    for module in list(sys.modules.values()):
        names = getattr(module, '__dict__', None) or {}
        for key, value in list(names.items()):
            if type(value) is Lazy and id(value) in done:
                names[key] = done[id(value)]


def jit(fn=None, *, loads_numba: bool = False):
    """``fn`` compiled by numba ``njit(cache=True)`` (no fastmath) in a process that loaded
    numba, else run as plain Python; ``loads_numba``: its first call loads numba (a kernel
    whose plain Python would cost much more than numba's start, ~0.5 s CPU)."""
    if fn is None:
        return lambda f: jit(f, loads_numba=loads_numba)
    if _NJIT:
        return _NJIT[0](cache=True)(fn) if _NJIT[0] else fn
    return Lazy(fn, loads_numba)


@jit
def qmul(p, q):
    """Hamilton product ``p (x) q`` (K1) of scalar-last quaternions, shape (4,)."""
    out = np.empty(4)
    out[0] = p[3] * q[0] + p[0] * q[3] + p[1] * q[2] - p[2] * q[1]
    out[1] = p[3] * q[1] - p[0] * q[2] + p[1] * q[3] + p[2] * q[0]
    out[2] = p[3] * q[2] + p[0] * q[1] - p[1] * q[0] + p[2] * q[3]
    out[3] = p[3] * q[3] - p[0] * q[0] - p[1] * q[1] - p[2] * q[2]
    return out


@jit
def dcm(q):
    """``R(q)`` (3, 3) (K2) of ``q`` normalised here: ``v_A = R(q_A_B) v_B``."""
    nrm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    x, y, z, w = q[0] / nrm, q[1] / nrm, q[2] / nrm, q[3] / nrm
    r = np.empty((3, 3))
    r[0, 0] = 1 - 2 * (y * y + z * z)
    r[0, 1] = 2 * (x * y - z * w)
    r[0, 2] = 2 * (x * z + y * w)
    r[1, 0] = 2 * (x * y + z * w)
    r[1, 1] = 1 - 2 * (x * x + z * z)
    r[1, 2] = 2 * (y * z - x * w)
    r[2, 0] = 2 * (x * z - y * w)
    r[2, 1] = 2 * (y * z + x * w)
    r[2, 2] = 1 - 2 * (x * x + y * y)
    return r


@jit
def cross(a, b):
    """``a x b`` (K3) of two (3,) arrays (``np.cross`` costs ~10x more per call)."""
    out = np.empty(3)
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out


@jit
def skew(v):
    """``[v]x`` (3, 3) (K3): ``skew(v) @ u == cross(v, u)``."""
    out = np.zeros((3, 3))
    out[0, 1], out[0, 2] = -v[2], v[1]
    out[1, 0], out[1, 2] = v[2], -v[0]
    out[2, 0], out[2, 1] = -v[1], v[0]
    return out


@jit
def mv(m, v):
    """``M v`` (3,) of a (3, 3) matrix and a (3,) vector, summed in index order."""
    out = np.empty(3)
    for i in range(3):
        out[i] = m[i, 0] * v[0] + m[i, 1] * v[1] + m[i, 2] * v[2]
    return out


@jit
def matmul(a, b):
    """``A B`` of 2-D arrays, summed in index order (no BLAS: the same bits everywhere)."""
    n, k = a.shape
    m = b.shape[1]
    out = np.zeros((n, m))
    for i in range(n):
        for j in range(m):
            s = 0.0
            for r in range(k):
                s += a[i, r] * b[r, j]
            out[i, j] = s
    return out


def finite_vector(value: ArrayLike, name: str, shape: tuple) -> np.ndarray:
    """Return ``value`` as a finite float array of ``shape``, else raise ``ValueError``."""
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be numeric with shape {shape}, got {value!r}') from None
    if arr.shape != shape:
        raise ValueError(f'{name} must have shape {shape}, got {arr.shape}')
    if not math.isfinite(sum(arr.ravel().tolist())) and not np.isfinite(arr).all():
        raise ValueError(f'{name} must be finite, got {arr}')    # a finite sum: all finite
    return arr


#: Environment variables that set the thread count of BLAS/OpenMP libraries at load time.
BLAS_THREAD_ENV = ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS',
                   'BLIS_NUM_THREADS', 'VECLIB_MAXIMUM_THREADS', 'NUMEXPR_NUM_THREADS')


def limit_blas_threads() -> None:
    """One BLAS thread: in the libraries already loaded, and (environment) in later ones (tiny
    LAPACK calls: extra threads cost CPU, same bits; DESIGN section 6)."""
    import os
    for key in BLAS_THREAD_ENV:
        os.environ[key] = '1'
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - pinned in ros2_ws/requirements.txt
        return
    threadpool_limits(limits=1)
