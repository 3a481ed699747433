"""The environment's frame step: orbit state and geomagnetic field at t -> ``sim/environment``.

Models: :mod:`adcs_nodes.core.orbit` and :mod:`adcs_nodes.core.geomag`, configured by the
``orbit.*`` and ``field.*`` sections (the scenario's keys).
"""
from __future__ import annotations

from datetime import datetime, timedelta
from typing import Any, Dict

from std_msgs.msg import Header

from adcs_msgs.msg import Environment
from adcs_nodes.components.base import FrameClock
from adcs_nodes.core.geomag import make_field
from adcs_nodes.core.lockstep import ns_to_seconds
from adcs_nodes.core.orbit import make_orbit, q_eci_ecef
from adcs_nodes.nodes.convert import to_quat, to_vec3
from adcs_nodes.nodes.messages import make


class EnvironmentComponent:
    """Orbit and field of the simulated world (truth models)."""

    def __init__(self, orbit_cfg: Dict[str, Any], field_cfg: Dict[str, Any], epoch: datetime,
                 clock: FrameClock) -> None:
        self.epoch = epoch
        self.orbit = make_orbit(orbit_cfg, epoch)
        self.field = make_field(field_cfg, epoch)
        self.clock = clock

    def step(self, t_ns: int) -> Environment:
        """``sim/environment`` of elapsed sim time ``t_ns``."""
        t = ns_to_seconds(t_ns)
        st = self.orbit.state(t)
        b_eci, b_dot_eci = self.field.field_and_rate(self.orbit, t, st.r_eci)
        return make(Environment, header=make(Header, stamp=self.clock.stamp(t_ns), frame_id='eci'),
                    r_eci=to_vec3(st.r_eci), v_eci=to_vec3(st.v_eci),
                    q_eci_orbit=to_quat(st.q_eci_orbit),
                    omega_orbit_eci_eci=to_vec3(st.omega_orbit_eci_eci),
                    orbit_rate=float(st.orbit_rate),
                    argument_of_latitude=float(st.argument_of_latitude),
                    b_eci=to_vec3(b_eci), b_dot_eci=to_vec3(b_dot_eci),
                    q_eci_ecef=to_quat(q_eci_ecef(self.epoch + timedelta(seconds=t))))
