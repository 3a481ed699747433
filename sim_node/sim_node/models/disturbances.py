"""Environmental and residual disturbance torques on the simulated spacecraft.

Equations
---------
Gravity gradient of a central field (paper 000 eq. (3), ``3 w0^2 e_R x I e_R`` on a circular
orbit, written for any orbit)::

    r_hat_body = R(q_eci_body)^T r_eci / |r_eci|
    tau_gg_body = 3 mu / |r_eci|^3  r_hat_body x (I r_hat_body)                          (D1)

Residual torques, body axes (paper 000 section 4: constant ``M_r`` and a Gaussian torque of
std up to 1e-5 N m)::

    tau_const_body(t) = M_r                                                              (D2)
    tau_rand_body(t)  = sigma * n_j,  j = floor(t / T),  n_j ~ N(0, I3)                  (D3)

(D3) is a zero-order hold redrawn every period ``T``; ``n_j`` is
``default_rng([seed, j]).standard_normal(3)``, a function of ``(seed, j)`` only, so a
trajectory does not depend on the number of substeps. The draw is a compiled copy of numpy's
``SeedSequence`` hash (:func:`pcg64_seed_words`, ``bit_generator.pyx``), PCG64 seeding and
XSL-RR output (:func:`pcg64_seeded`, :func:`pcg64_next64`) and ziggurat
``random_standard_normal`` (:func:`pcg64_normal`, ``distributions.c``): the same bits as
``default_rng`` (``tests/unit/test_random_draw.py``), about 1 us a draw instead of 8.
"""
from __future__ import annotations

import math
import threading
from typing import Protocol, runtime_checkable

import numpy as np

from adcs_nodes.core import attitude
from adcs_nodes.core.control import finite, integer, positive
from adcs_nodes.core.kernels import jit
from adcs_nodes.core.orbit import MU_EARTH  # one value for the whole project

_INDEX_TOL = 1e-9   # [periods]: t = j T minus a rounding error still belongs to period j
_NO_INDEX = -2**62  # no period drawn yet


@runtime_checkable
class Disturbance(Protocol):
    """Anything with ``torque(t) -> (3,)`` [N m], body axes, ``t`` in s since the epoch."""

    def torque(self, t: float) -> np.ndarray:
        ...


def check_inertia(inertia, name: str = 'inertia') -> np.ndarray:
    """The inertia (3, 3) [kg m^2], body axes, as a float array; ``ValueError`` unless finite,
    symmetric (relative 1e-9), positive definite, with ``I1 + I2 >= I3``."""
    m = np.array(inertia, dtype=float)
    if m.shape != (3, 3):
        raise ValueError(f'{name} must have shape (3, 3), got {m.shape}')
    if not np.all(np.isfinite(m)):
        raise ValueError(f'{name} is not finite: {m.tolist()}')
    scale = np.max(np.abs(m))
    if scale == 0.0 or np.max(np.abs(m - m.T)) > 1e-9 * scale:
        raise ValueError(f'{name} must be symmetric and non-zero, got {m.tolist()}')
    m = 0.5 * (m + m.T)
    moments = np.linalg.eigvalsh(m)
    if moments[0] <= 0.0:
        raise ValueError(f'{name} must be positive definite, principal moments {moments}')
    if moments[0] + moments[1] < moments[2] * (1.0 - 1e-9):
        raise ValueError(f'{name} principal moments {moments} break the triangle inequality '
                         'I1 + I2 >= I3 of a rigid body')
    return m


def gravity_gradient_torque(q_eci_body, r_eci, inertia, mu: float = MU_EARTH) -> np.ndarray:
    """``tau_gg_body`` (3,) [N m], (D1), of ``q_eci_body`` (4,), the non-zero position
    ``r_eci`` (3,) [m], ECI, the inertia (3, 3) [kg m^2], body axes, and ``mu`` [m^3/s^2]."""
    inertia = check_inertia(inertia)
    r = np.array(r_eci, dtype=float)
    if r.shape != (3,) or not np.all(np.isfinite(r)):
        raise ValueError(f'r_eci must be a finite (3,) vector, got {r}')
    radius = math.sqrt(float(r @ r))
    if radius == 0.0:
        raise ValueError('r_eci must not be zero')
    if not (mu > 0.0 and math.isfinite(mu)):
        raise ValueError(f'mu must be > 0 and finite, got {mu}')
    r_hat_body = attitude.to_matrix(q_eci_body).T @ (r / radius)
    return 3.0 * mu / radius ** 3 * np.cross(r_hat_body, inertia @ r_hat_body)


class ConstantTorque:
    """Constant body-fixed disturbance torque (D2), ``torque_body`` (3,) [N m]."""

    def __init__(self, torque_body) -> None:
        tau = np.array(torque_body, dtype=float)
        if tau.shape != (3,) or not np.all(np.isfinite(tau)):
            raise ValueError(f'torque_body must be a finite (3,) vector, got {tau}')
        self.torque_body = tau

    def torque(self, t: float) -> np.ndarray:
        """Torque [N m], body axes, shape (3,), at any time ``t`` [s]."""
        return self.torque_body.copy()


class RandomTorque:
    """Gaussian body-fixed torque held over each period (D3): ``std_Nm`` (float or (3,))
    [N m] >= 0, ``period_s`` ``T`` [s] > 0, ``seed`` >= 0."""

    def __init__(self, std_Nm, period_s: float, seed: int) -> None:
        std = np.array(std_Nm, dtype=float)
        if std.shape not in ((), (3,)) or not np.all(np.isfinite(std)) or np.any(std < 0.0):
            raise ValueError(f'std_Nm must be a finite scalar or (3,) vector >= 0, got {std}')
        period = positive(period_s, 'period_s', 's')
        self.seed = integer(seed, 'seed', 0)
        self.std_Nm = np.broadcast_to(std, (3,)).copy()
        self.period_s = period
        self._last_index: int | None = None
        self._last_value = np.zeros(3)

    def index(self, t: float) -> int:
        """Period index ``j = floor(t / T)`` of time ``t`` [s] (rounding-tolerant)."""
        return math.floor(t / self.period_s + _INDEX_TOL)

    def draw(self, j: int) -> np.ndarray:
        """Torque (3,) [N m] of period ``j``: ``std default_rng([seed, key]).standard_normal(3)``,
        ``key = 2 j`` for ``j >= 0``, else ``-2 j - 1`` (the entropy must be >= 0)."""
        key = 2 * j if j >= 0 else -2 * j - 1
        return self.std_Nm * standard_normal3(self.seed, key)

    def torque(self, t: float) -> np.ndarray:
        """Torque [N m], body axes, shape (3,), held over the period containing ``t`` [s]."""
        j = self.index(t)
        if j != self._last_index:   # cache only: the value is the same either way
            self._last_value = self.draw(j)
            self._last_index = j
        return self._last_value.copy()

    def add_to(self, table: np.ndarray, t: float, h: float) -> None:
        """Add the torque at each substep midpoint ``t + i h + h/2`` to row ``i`` of ``table``
        (substeps, 3) [N m]: ``table[i] += torque(t + i h + 0.5 h)``, the same bits."""
        if self.seed < 2**64 and _compiled():
            last = _NO_INDEX if self._last_index is None else self._last_index
            self._last_index = random_torque_rows(_U(self.seed), self.std_Nm, self.period_s,
                                                  float(t), float(h), last, self._last_value,
                                                  table)
            return
        for i in range(table.shape[0]):
            table[i] += self.torque(t + i * h + 0.5 * h)


_M128 = (1 << 128) - 1
_PCG64_MULT = (2549297995355413924 << 64) + 4865540595714422341   # PCG_DEFAULT_MULTIPLIER_128
_LOCAL = threading.local()            # one reseeded PCG64 per thread (module docstring)


@jit(loads_numba=True)
def pcg64_seed_words(ent, n):
    """``SeedSequence(entropy).generate_state(4, np.uint64)`` as eight 32-bit words (int64
    (8,); 64-bit word ``k`` is ``w[2k] + 2**32 w[2k + 1]``) of the ``n`` (1 to 4) entropy
    words ``ent`` (4,) (each integer split into 32-bit words, low first, zero padded)."""
    m32 = 0xFFFFFFFF
    pool = np.zeros(4, np.int64)
    h = 0x43b0d7e5                       # INIT_A
    for i in range(4 + 12 + 4 * max(n - 4, 0)):
        if i < 4:                        # hashmix of the entropy (or 0) into the pool
            src, dst = (int(ent[i]) if i < n else 0), -1
        elif i < 16:                     # every pool word into every other one
            i_src, k = divmod(i - 4, 3)
            dst = k if k < i_src else k + 1
            src = int(pool[i_src])
        else:                            # entropy beyond the pool size
            i_src, dst = divmod(i - 16, 4)
            src = int(ent[4 + i_src])
        value = src ^ h
        h = (h * 0x931e8875) & m32       # MULT_A
        value = (value * h) & m32
        value ^= value >> 16
        if dst < 0:
            pool[i] = value
        else:                            # mix(x, y)
            r = (0xca01f9dd * int(pool[dst]) - 0x4973f715 * value) & m32
            pool[dst] = r ^ (r >> 16)
    out = np.zeros(8, np.int64)
    h = 0x8b51f9dd                       # INIT_B
    for i in range(8):
        value = int(pool[i % 4]) ^ h
        h = (h * 0x58f38ded) & m32       # MULT_B
        value = (value * h) & m32
        out[i] = value ^ (value >> 16)
    return out


def standard_normal3(seed: int, key: int) -> np.ndarray:
    """``numpy.random.default_rng([seed, key]).standard_normal(3)``, bit for bit, shape (3,)."""
    if not 0 <= seed < 2**64 or not 0 <= key < 2**64:
        return np.random.default_rng([seed, key]).standard_normal(3)
    if _compiled():
        return pcg64_normal3(np.uint64(seed), np.uint64(key))
    ent = np.zeros(4, np.int64)
    n = 0
    for v in (seed, key):
        ent[n] = v & 0xFFFFFFFF
        n += 1
        if v >> 32:
            ent[n] = v >> 32
            n += 1
    w0, w1, w2, w3, w4, w5, w6, w7 = pcg64_seed_words(ent, n).tolist()
    initstate = (((w1 << 32) | w0) << 64) | ((w3 << 32) | w2)
    initseq = (((w5 << 32) | w4) << 64) | ((w7 << 32) | w6)
    inc = ((initseq << 1) | 1) & _M128
    state = ((inc + initstate) * _PCG64_MULT + inc) & _M128
    gen = getattr(_LOCAL, 'gen', None)
    if gen is None:
        gen = _LOCAL.gen = np.random.Generator(np.random.PCG64(0))
    gen.bit_generator.state = {'bit_generator': 'PCG64', 'state': {'state': state, 'inc': inc},
                               'has_uint32': 0, 'uinteger': 0}
    return gen.standard_normal(3)


# ------------------------------------------------------------ compiled PCG64 and ziggurat
# uint64 words throughout (numba types a mix of signed and unsigned integers as float)
_U = np.uint64
_MULT_HI, _MULT_LO = _U(_PCG64_MULT >> 64), _U(_PCG64_MULT & (2**64 - 1))
#: numpy's ziggurat tables (ziggurat_constants.h) as numba carries them, loaded with numba by
#: :func:`_compiled` (the kernels below read them when they compile)
_KI = _WI = _FI = None
_NOR_R = _NOR_INV_R = 0.0
_COMPILED: list = []


def _compiled() -> bool:
    """True when the draw runs compiled (numba there, its JIT not disabled)."""
    global _KI, _WI, _FI, _NOR_R, _NOR_INV_R
    if not _COMPILED:
        try:
            from numba import config
            from numba.np.random import _constants as z
        except ImportError:  # pragma: no cover - numba is pinned
            config = None
        else:
            _KI, _WI, _FI = (np.asarray(z.ki_double, dtype=np.uint64),
                             np.asarray(z.wi_double, dtype=float), np.asarray(z.fi_double))
            _NOR_R, _NOR_INV_R = float(z.ziggurat_nor_r), float(z.ziggurat_nor_inv_r)
        _COMPILED.append(config is not None and not config.DISABLE_JIT)
    return _COMPILED[0]


@jit(loads_numba=True)
def _mulhi64(a, b):
    """High 64 bits of the 128-bit product of two uint64."""
    m32, s32 = _U(0xFFFFFFFF), _U(32)
    a_lo, a_hi = a & m32, a >> s32
    b_lo, b_hi = b & m32, b >> s32
    lo_lo, hi_lo, lo_hi = a_lo * b_lo, a_hi * b_lo, a_lo * b_hi
    cross = (lo_lo >> s32) + (hi_lo & m32) + lo_hi
    return (hi_lo >> s32) + (cross >> s32) + a_hi * b_hi


@jit(loads_numba=True)
def _pcg64_step(st):
    """``state = state a + inc`` mod 2^128; ``st = [state_hi, state_lo, inc_hi, inc_lo]``."""
    hi, lo = st[0], st[1]
    p_lo = lo * _MULT_LO
    p_hi = _mulhi64(lo, _MULT_LO) + hi * _MULT_LO + lo * _MULT_HI
    n_lo = p_lo + st[3]
    st[0] = p_hi + st[2] + (_U(1) if n_lo < p_lo else _U(0))
    st[1] = n_lo


@jit(loads_numba=True)
def pcg64_seeded(seed, key):
    """PCG64 state ``[state_hi, state_lo, inc_hi, inc_lo]`` (uint64) of ``default_rng([seed,
    key])``, ``seed``, ``key`` uint64."""
    ent = np.zeros(4, np.int64)
    n = 0
    for v in (seed, key):
        ent[n] = np.int64(v & _U(0xFFFFFFFF))
        n += 1
        if v >> _U(32):
            ent[n] = np.int64(v >> _U(32))
            n += 1
    w = pcg64_seed_words(ent, n).astype(np.uint64)
    s32 = _U(32)
    init_hi, init_lo = (w[1] << s32) | w[0], (w[3] << s32) | w[2]
    seq_hi, seq_lo = (w[5] << s32) | w[4], (w[7] << s32) | w[6]
    st = np.empty(4, np.uint64)
    st[2] = (seq_hi << _U(1)) | (seq_lo >> _U(63))          # inc = 2 initseq + 1
    st[3] = (seq_lo << _U(1)) | _U(1)
    st[1] = st[3] + init_lo                                  # state = inc + initstate
    st[0] = st[2] + init_hi + (_U(1) if st[1] < st[3] else _U(0))
    _pcg64_step(st)
    return st


@jit(loads_numba=True)
def pcg64_next64(st):
    """PCG64's next uint64 (``pcg_setseq_128_xsl_rr_64_random_r``: step, then XSL-RR)."""
    _pcg64_step(st)
    v = st[0] ^ st[1]
    rot = st[0] >> _U(58)
    return (v >> rot) | (v << ((_U(64) - rot) & _U(63)))


@jit(loads_numba=True)
def _next_double(st):
    return float(pcg64_next64(st) >> _U(11)) * (1.0 / 9007199254740992.0)


@jit(loads_numba=True)
def pcg64_normal(st):
    """numpy's ``random_standard_normal`` (ziggurat, 256 layers) on the PCG64 state ``st``."""
    while True:
        r = pcg64_next64(st)
        idx = np.int64(r & _U(0xFF))
        r = r >> _U(8)
        rabs = (r >> _U(1)) & _U(0x000FFFFFFFFFFFFF)
        x = float(rabs) * _WI[idx]
        if r & _U(1):
            x = -x
        if rabs < _KI[idx]:
            return x                      # 99.3 % of the draws
        if idx == 0:                      # the tail
            while True:
                xx = -_NOR_INV_R * math.log1p(-_next_double(st))
                yy = -math.log1p(-_next_double(st))
                if yy + yy > xx * xx:
                    return -(_NOR_R + xx) if (rabs >> _U(8)) & _U(1) else _NOR_R + xx
        elif (_FI[idx - 1] - _FI[idx]) * _next_double(st) + _FI[idx] < math.exp(-0.5 * x * x):
            return x


@jit(loads_numba=True)
def pcg64_normal3(seed, key):
    """``default_rng([seed, key]).standard_normal(3)`` (``seed``, ``key`` uint64)."""
    st = pcg64_seeded(seed, key)
    out = np.empty(3)
    for i in range(3):
        out[i] = pcg64_normal(st)
    return out


@jit(loads_numba=True)
def random_torque_rows(seed, std, period, t, h, last, value, table):
    """(D3) at the substep midpoints added to ``table`` (substeps, 3), as
    :meth:`RandomTorque.torque` gives it: ``j = floor(t_mid / T + tol)``, ``value = std n_j``
    (kept in ``value`` while ``j`` stays ``last``). Returns the last ``j``."""
    for i in range(table.shape[0]):
        j = math.floor((t + i * h + 0.5 * h) / period + _INDEX_TOL)
        if j != last:
            key = 2 * j if j >= 0 else -2 * j - 1
            value[:] = std * pcg64_normal3(seed, _U(key))
            last = j
        for k in range(3):
            table[i, k] += value[k]
    return last


def _vec3_nonneg(value, name: str) -> np.ndarray:
    arr = np.array(value, dtype=float)
    if arr.shape not in ((), (3,)) or not np.all(np.isfinite(arr)) or np.any(arr < 0.0):
        raise ValueError(f'{name} must be a finite scalar or (3,) vector >= 0, got {arr}')
    return np.broadcast_to(arr, (3,)).copy()


class HarmonicTorque:
    """Body-fixed periodic torque with seeded phases (paper 001's environmental torques)::

        tau_i(t) = a_i sin(w t + phi_i),   phi_i ~ U[0, 2 pi) from default_rng(seed)        (D4)

    ``amplitude_Nm`` ``a`` (float or (3,)) [N m] >= 0, ``omega_rad_s`` ``w`` >= 0, ``seed``
    >= 0, or fixed ``phase_rad`` (3,) [rad].
    """

    def __init__(self, amplitude_Nm, omega_rad_s: float, seed: int = 0,
                 phase_rad=None) -> None:
        self.amplitude_Nm = _vec3_nonneg(amplitude_Nm, 'amplitude_Nm')
        self.omega_rad_s = positive(omega_rad_s, 'omega_rad_s', zero=True)
        if phase_rad is None:
            rng = np.random.default_rng(integer(seed, 'seed', 0))
            self.phase_rad = rng.uniform(0.0, 2.0 * math.pi, 3)
        else:
            ph = np.array(phase_rad, dtype=float)
            if ph.shape != (3,) or not np.all(np.isfinite(ph)):
                raise ValueError(f'phase_rad must be a finite (3,) vector, got {ph}')
            self.phase_rad = ph

    def torque(self, t: float) -> np.ndarray:
        """(D4) [N m], body axes, shape (3,)."""
        return self.amplitude_Nm * np.sin(self.omega_rad_s * t + self.phase_rad)


class PeriodicPulseTorque:
    """Constant body torque switched on for ``duration_s`` every ``period_s`` (momentum
    unloading; paper 001: 1e-3 N m)::

        tau(t) = s o a  if (t - t_start) mod T < d  and t >= t_start, else 0               (D5)

    ``amplitude_Nm`` ``a`` (float or (3,)) [N m] >= 0, ``period_s`` ``T > 0``, ``duration_s``
    ``0 <= d <= T``, ``start_s`` [s]; per-axis signs ``s`` in {-1, +1}^3 from
    ``default_rng(seed)`` or fixed ``signs`` (3,).
    """

    def __init__(self, amplitude_Nm, period_s: float, duration_s: float, start_s: float = 0.0,
                 seed: int = 0, signs=None) -> None:
        self.amplitude_Nm = _vec3_nonneg(amplitude_Nm, 'amplitude_Nm')
        period, dur = positive(period_s, 'period_s', 's'), float(duration_s)
        if not (math.isfinite(dur) and 0.0 <= dur <= period):
            raise ValueError(f'duration_s must be in [0, period_s], got {duration_s!r}')
        self.period_s, self.duration_s, self.start_s = period, dur, finite(start_s, 'start_s')
        if signs is None:
            rng = np.random.default_rng(integer(seed, 'seed', 0))
            self.signs = np.where(rng.random(3) < 0.5, -1.0, 1.0)
        else:
            sg = np.array(signs, dtype=float)
            if sg.shape != (3,) or not np.all(np.abs(sg) == 1.0):
                raise ValueError(f'signs must be three values of +1 or -1, got {sg}')
            self.signs = sg

    def torque(self, t: float) -> np.ndarray:
        """(D5) [N m], body axes, shape (3,)."""
        if t < self.start_s:
            return np.zeros(3)
        phase = (t - self.start_s) % self.period_s
        on = phase < self.duration_s or self.duration_s >= self.period_s
        return self.signs * self.amplitude_Nm if on else np.zeros(3)
