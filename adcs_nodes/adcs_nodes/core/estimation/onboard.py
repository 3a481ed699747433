"""The flight software's own reference: orbit state and geomagnetic field in the ORBIT frame.

The estimators compare a measured field (body axes) with a model field in the orbit frame
(paper 000: ``B*``; paper 004: ``a_x0, a_y0, a_z0``). The flight software computes that model
itself from the scenario's configuration (DESIGN section 5: it never reads ``sim/*``); it may
differ from the truth models on purpose.

Equations
---------
Orbit frame (papers 000/004; :mod:`adcs_nodes.core.orbit` (O3)): x along-track, y orbit normal,
z zenith; ``v_eci = R(q_eci_orbit) v_orbit``. The model field in orbit axes::

    b_orbit = R(q_eci_orbit)^T b_eci(r_eci, t)                                       (R1)

Direct (axial) dipole in orbit axes, paper 004 eq. (2) (ref. [4] of that paper)::

    b_orbit = (mu_e / r^3) [cos u sin i,  cos i,  -2 sin u sin i]^T                    (2)

with ``u`` the argument of latitude, ``i`` the inclination, ``r`` the orbit radius and
``mu_e = B0 R^3`` the Earth's dipole moment in T m^3. It equals (R1) for
:class:`~adcs_nodes.core.geomag.DipoleField` with ``pole_colatitude_rad = 0`` (a unit test
pins it). The dipole moment points to the geographic south (``b`` points north on the
equator, down at the north pole).

One reference per stamp: :meth:`OnboardReference.at` keeps its last result and
:func:`make_onboard_reference` shares one instance per configuration in a process (``at(t)``
is a pure function of ``t``; every caller gets its own copies of the arrays).
"""
from __future__ import annotations

import json
import math
from datetime import datetime
from typing import Dict, Mapping, NamedTuple, Optional

import numpy as np

from adcs_nodes.core.geomag import B0_DEFAULT_T, R_REF_M, GeomagneticField, make_field
from adcs_nodes.core.kernels import dcm, jit
from adcs_nodes.core.orbit import OrbitModel, make_orbit

MU_E_DEFAULT = B0_DEFAULT_T * R_REF_M ** 3
"""Default Earth dipole moment ``B0 R^3`` [T m^3] (about 7.76e15; digest 5.2 assumption)."""


@jit
def to_orbit_axes(q_eci_orbit, v_eci):
    """``R(q_eci_orbit)^T v_eci`` (R1), shape (3,): ECI components to orbit axes."""
    r = dcm(q_eci_orbit)
    out = np.empty(3)
    for i in range(3):
        out[i] = r[0, i] * v_eci[0] + r[1, i] * v_eci[1] + r[2, i] * v_eci[2]
    return out


class OnboardState(NamedTuple):
    """Onboard reference at one instant: ``q_eci_orbit`` (4,) (``v_eci = R(q) v_orbit``),
    ``b_orbit`` (3,) [T] ORBIT axes (paper 000's ``B*``), ``omega0`` orbit rate [rad/s] about
    the orbit y axis, ``u`` argument of latitude [rad] in [0, 2 pi), ``r_eci`` (3,) [m]."""

    q_eci_orbit: np.ndarray
    b_orbit: np.ndarray
    omega0: float
    u: float
    r_eci: np.ndarray


class OnboardReference:
    """Orbit plus field model of the flight software, evaluated in the orbit frame (R1).
    ``orbit`` (:mod:`~adcs_nodes.core.orbit`) and ``field`` (:mod:`~adcs_nodes.core.geomag`)
    must share their ``epoch`` (``ValueError``)."""

    def __init__(self, orbit: OrbitModel, field: GeomagneticField) -> None:
        if getattr(orbit, 'epoch', None) != getattr(field, 'epoch', None):
            raise ValueError(f'orbit epoch {getattr(orbit, "epoch", None)} differs from field '
                             f'epoch {getattr(field, "epoch", None)}')
        self.orbit = orbit
        self.field = field
        to_orbit_axes(np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3))   # compiled before a frame
        self._last_t: Optional[float] = None
        self._last: Optional[OnboardState] = None

    def at(self, t: float) -> OnboardState:
        """:class:`OnboardState` at ``t`` seconds after the epoch (the last stamp's result is
        reused; the arrays are the caller's own copies)."""
        t = float(t)
        if self._last is None or self._last_t != t:
            st = self.orbit.state(t)
            b_eci = self.field.field_eci(st.r_eci, t)
            b_orbit = to_orbit_axes(np.asarray(st.q_eci_orbit, dtype=float), b_eci)  # (R1)
            self._last = OnboardState(np.array(st.q_eci_orbit, dtype=float), b_orbit,
                                      float(st.orbit_rate), float(st.argument_of_latitude),
                                      np.array(st.r_eci, dtype=float))
            self._last_t = t
        last = self._last
        return OnboardState(last.q_eci_orbit.copy(), last.b_orbit.copy(), last.omega0, last.u,
                            last.r_eci.copy())


#: One :class:`OnboardReference` per (orbit, field, epoch) configuration in this process.
_SHARED: Dict[str, OnboardReference] = {}


def make_onboard_reference(orbit_cfg: Mapping, field_cfg: Mapping,
                           epoch: datetime) -> OnboardReference:
    """The process's shared :class:`OnboardReference` of the scenario mappings ``orbit_cfg``
    (:func:`~adcs_nodes.core.orbit.make_orbit`) and ``field_cfg``
    (:func:`~adcs_nodes.core.geomag.make_field`) at the aware ``epoch`` (``t = 0``); a bad
    configuration is the factories' ``ValueError``."""
    try:
        key = json.dumps([dict(orbit_cfg), dict(field_cfg), epoch.isoformat()],
                         sort_keys=True, default=repr)
    except (TypeError, ValueError):
        key = None   # not serialisable: a private instance
    ref = _SHARED.get(key) if key is not None else None
    if ref is None:
        ref = OnboardReference(make_orbit(orbit_cfg, epoch), make_field(field_cfg, epoch))
        if key is not None:
            if len(_SHARED) >= 16:   # a long campaign in one process: keep it bounded
                _SHARED.clear()
            _SHARED[key] = ref
    return ref


def b_orbit_direct_dipole(u: float, i: float, r: float, mu_e: float = MU_E_DEFAULT) -> np.ndarray:
    """Direct-dipole ``b_orbit`` (3,) [T], orbit axes, paper 004 eq. (2), of the argument of
    latitude ``u`` [rad], inclination ``i`` [rad], radius ``r`` [m] > 0 and dipole moment
    ``mu_e = B0 R^3`` [T m^3] (``lambda = mu_e / r^3``); ``ValueError`` on a bad input."""
    vals = [float(u), float(i), float(r), float(mu_e)]
    if not all(math.isfinite(v) for v in vals) or vals[2] <= 0.0:
        raise ValueError(f'u, i, r, mu_e must be finite with r > 0, got {vals}')
    lam = mu_e / r ** 3
    return lam * np.array([math.cos(u) * math.sin(i), math.cos(i),
                           -2.0 * math.sin(u) * math.sin(i)])  # (2)
