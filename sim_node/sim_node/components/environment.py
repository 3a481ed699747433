"""The environment's frame step: orbit state and geomagnetic field at t -> ``sim/environment``.

Models: :mod:`adcs_nodes.core.orbit` and :mod:`adcs_nodes.core.geomag`, configured by the
``orbit.*`` and ``field.*`` sections (the scenario's keys).
"""
from __future__ import annotations

from datetime import datetime, timedelta
from typing import Any, Dict

import numpy as np

from adcs_nodes.core.geomag import make_field
from adcs_nodes.core.lockstep import ns_to_seconds
from adcs_nodes.core.orbit import make_orbit, q_eci_ecef
from adcs_nodes.core.samples import EnvironmentSample


def _f(a: Any) -> np.ndarray:
    return np.asarray(a, dtype=float)     # the models return fresh arrays: no copy


class EnvironmentComponent:
    """Orbit and field of the simulated world (truth models)."""

    def __init__(self, orbit_cfg: Dict[str, Any], field_cfg: Dict[str, Any],
                 epoch: datetime) -> None:
        self.epoch = epoch
        self.orbit = make_orbit(orbit_cfg, epoch)
        self.field = make_field(field_cfg, epoch)

    def step(self, t_ns: int) -> EnvironmentSample:
        """``sim/environment`` of elapsed sim time ``t_ns``."""
        t = ns_to_seconds(t_ns)
        st = self.orbit.state(t)
        b_eci, b_dot_eci = self.field.field_and_rate(self.orbit, t, st.r_eci)
        return EnvironmentSample(
            t_ns, _f(st.r_eci), _f(st.v_eci), _f(st.q_eci_orbit), _f(st.omega_orbit_eci_eci),
            float(st.orbit_rate), float(st.argument_of_latitude), _f(b_eci), _f(b_dot_eci),
            _f(q_eci_ecef(self.epoch + timedelta(seconds=t))))
