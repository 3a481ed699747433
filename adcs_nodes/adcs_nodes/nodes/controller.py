"""Generic controller node: runs any registered controller, chosen by parameter ``controller``.

One process per controller. Every controller computes every frame of its period ("shadow
mode", so a switch is bumpless) and publishes ``adcs/controllers/<name>/command``
(``adcs_msgs/ActuatorCommand``, stamped with the frame it was computed for); the controller
manager forwards the active one.

What the node subscribes to comes from the registry entry's ``inputs`` (their records in
:mod:`adcs_nodes.inputs`: topic, type, converter), nothing else, so B-dot, whose entry declares
only the magnetometer, keeps working when the estimator dies (the safe-mode rule); the
conditioning is the component's (:mod:`adcs_nodes.components.controller`). The parameters
are the entry's own (``ros2 param describe`` shows each with unit and range) plus the
spacecraft context, all declared from typed specs.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Dict, List, Optional

from adcs_msgs.msg import ActuatorCommand
from adcs_nodes import registry
from adcs_nodes.inputs import lockstep_inputs as node_inputs
from adcs_nodes.core.geomag import FIELD
from adcs_nodes.core.orbit import ORBIT
from adcs_nodes.components.controller import (  # noqa: F401 (the node's names, re-exported)
    CONTEXT_PARAMS, ControllerComponent, controller_context, inertia_matrix,
    plugin_period_params)
from adcs_nodes.msgs.convert import COMMAND
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.adapter import records_to_core
from adcs_nodes.nodes.managed import ManagedLockstepNode
from adcs_nodes.nodes.tf import MountTable


#: The controller of a generic ``controller`` node given none (``CONTEXT_PARAMS``).
DEFAULT = next(p.default for p in CONTEXT_PARAMS if p.name == 'controller')


class ControllerNode(ManagedLockstepNode):
    """A registered controller core wrapped as a lockstep node (see module docstring); a
    managed node (:mod:`adcs_nodes.nodes.managed`)."""

    def __init__(self, name: Optional[str] = None, controller: Optional[str] = None,
                 **kwargs: Any) -> None:
        """Named ``<controller>_controller`` after the controller it runs (``controller``,
        else the ``controller`` parameter given, else the default); ``-r __node:=`` wins."""
        self._fixed_controller = controller   # (configure runs inside super().__init__)
        given = {p.name: p.value for p in kwargs.get('parameter_overrides') or []}
        super().__init__(name or f'{controller or given.get("controller") or DEFAULT}_controller',
                         **kwargs)

    def configure(self) -> None:
        """Parameters, controller core and endpoints (lifecycle configure)."""
        controller = self._fixed_controller
        registry.load_plugins(self.param('plugins', []))
        specs = {s.name: s for s in CONTEXT_PARAMS}
        if controller is not None:   # the class fixes the controller: that is its default
            specs['controller'] = replace(specs['controller'], default=controller)
        ctx_p = node_params.declare_all(self, specs.values())
        self.entry = registry.get('controller', ctx_p['controller'])
        self.controller_name = self.entry.name
        own = node_params.declare_all(self, self.entry.params)
        ctx_p.update(node_params.declare_all(self, plugin_period_params(self.entry)))
        self.mounts = MountTable(self)    # sensor mounts from /tf_static, by header.frame_id
        self.add_ready_check(lambda: self.mounts.missing(ctx_p['expected_mounts']))
        self.ctx = controller_context(
            self.entry, ctx_p, self.epoch, self.seed,
            self.section('onboard_orbit', ORBIT), self.section('onboard_field', FIELD))
        node_params.refuse_unknown(self)
        node_params.install_validator(self)
        self.core = self.entry.build(own, self.ctx)
        inputs = node_inputs(self.entry.inputs, ctx_p)
        self.pub = self.publisher(ActuatorCommand,
                                  f'adcs/controllers/{self.controller_name}/command')
        self.component = ControllerComponent(self.core, self.controller_name, self.ctx,
                                             self.mounts)
        self.to_core = records_to_core(self.entry.inputs, self.epoch_ns)
        self.lockstep_inputs(inputs, ctx_p['period_s'], self.on_frame)
        self.start_handshake()

    def on_frame(self, t_ns: int, msgs: Dict[str, Any], missing: List[str]) -> None:
        """Compute and publish this controller's command for frame ``t_ns``."""
        fresh = {k for k, m in msgs.items() if self.fresh(k, m, t_ns)}
        self.pub.publish(COMMAND.to_msg(self.component.step(
            t_ns, self.to_core(msgs), fresh.__contains__), self.epoch_ns))


def main(args=None) -> int:
    """``ros2 run adcs_nodes controller --ros-args -p controller:=NAME``: the node is named
    ``NAME_controller`` (two generic controllers never share a name)."""
    name = f'{runtime.given_parameter("controller", args) or DEFAULT}_controller'
    return runtime.run(lambda: ControllerNode(name), args)


def main_magnetic(args=None) -> int:
    """``ros2 run adcs_nodes magnetic_controller``."""
    return runtime.run(lambda: ControllerNode(controller='magnetic'), args)


def main_bdot(args=None) -> int:
    """``ros2 run adcs_nodes bdot_controller``."""
    return runtime.run(lambda: ControllerNode(controller='bdot'), args)


if __name__ == '__main__':
    raise SystemExit(main())
