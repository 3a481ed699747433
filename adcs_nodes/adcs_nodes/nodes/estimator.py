"""``estimator`` node: attitude and rate estimate from the sensors (flight software).

The algorithm is a registered estimator (parameter ``algorithm``; ``adcs list`` shows them);
the node subscribes to the topics of its entry's ``inputs`` (magnetometer, horizon sensor,
star tracker, gyro, the applied command), converts each message to its core sample (the
records' converters), and the component checks them and steps the core
(:mod:`adcs_nodes.components.estimator`). Never ``sim/*``: the reference field and orbit are
the flight software's own models (``onboard_orbit.*``, ``onboard_field.*``).

Publishes ``adcs/attitude_estimate``, ``adcs/estimator/diagnostics`` and ``/tf`` (``eci ->
body_estimate``; ``docs/topics.md``). Bad input is rejected with a warning and counted; a
non-finite estimate is never published.
"""
from __future__ import annotations

from typing import Any, Dict, List

from adcs_msgs.msg import AttitudeState, FilterDiagnostics
from adcs_nodes import registry
from adcs_nodes.inputs import lockstep_inputs as node_inputs
from adcs_nodes.core.geomag import FIELD
from adcs_nodes.core.orbit import ORBIT
from adcs_nodes.components.estimator import (  # noqa: F401 (the node's names, re-exported)
    CONTEXT_PARAMS, build_estimator)
from adcs_nodes.msgs.convert import ATTITUDE_STATE, DIAGNOSTICS
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.adapter import node_log, records_to_core
from adcs_nodes.nodes.managed import ManagedLockstepNode
from adcs_nodes.nodes.tf import MountTable, TfPublisher, estimate_transforms


class EstimatorNode(ManagedLockstepNode):
    """Attitude estimator (see module docstring); a managed node (:mod:`.managed`)."""

    def __init__(self, name: str = 'estimator', **kwargs: Any) -> None:
        super().__init__(name, **kwargs)

    def configure(self) -> None:
        """Parameters, onboard models, filter core and endpoints (lifecycle configure)."""
        registry.load_plugins(self.param('plugins', []))
        p = node_params.declare_all(self, CONTEXT_PARAMS)
        self.entry = registry.get('estimator', p['algorithm'])
        self.algorithm = self.entry.name
        own = node_params.declare_all(self, self.entry.params)
        self.mounts = MountTable(self)    # sensor mounts from /tf_static, by header.frame_id
        self.add_ready_check(lambda: self.mounts.missing(p['expected_mounts']))
        self.tf_pub = TfPublisher(self)   # /tf: eci -> body_estimate
        orbit = self.section('onboard_orbit', ORBIT)
        field = self.section('onboard_field', FIELD)
        node_params.refuse_unknown(self)
        node_params.install_validator(self)
        self.component = build_estimator(self.entry, p, own, orbit, field, self.epoch,
                                         self.seed, self.mounts, log=node_log(self))
        self.to_core = records_to_core(self.entry.inputs, self.epoch_ns)
        self.core, self.reference = self.component.core, self.component.reference
        self.field_range = self.component.field_range
        # the command applied over [t_k-1, t_k] is the one stamped t_k-1: awaited (determinism)
        inputs = node_inputs(self.entry.inputs, p)
        self.est_pub = self.publisher(AttitudeState, 'adcs/attitude_estimate')
        self.diag_pub = self.publisher(FilterDiagnostics, 'adcs/estimator/diagnostics')
        self.lockstep_inputs(inputs, p['period_s'], self.on_frame)
        self.start_handshake()

    # the counters /diagnostics and the tests read
    update_count = property(lambda self: self.component.update_count)
    rejected_count = property(lambda self: self.component.rejected_count)
    last_rejection = property(lambda self: self.component.last_rejection)
    #: filter restarts (a diverged filter reset to its initial estimate), on /diagnostics
    resets = property(lambda self: int(getattr(self.component.core, 'resets', 0)))
    #: the component's rejections by kind (check, late, timeout, filter), in the run summary
    rejected_by = property(lambda self: self.component.rejected_by)

    def used_counts(self) -> Dict[str, int]:
        """Samples that reached the filter, per input (the run summary)."""
        return dict(self.component.samples_used)

    def last_usable_ns(self, name: str):
        """A sample is usable when it reached the filter (timing and conditioning passed)."""
        return self.component.last_used_ns.get(name)

    # ------------------------------------------------------------------ frame
    def on_frame(self, t_ns: int, msgs: Dict[str, Any], missing: List[str]) -> None:
        """One estimator step at elapsed sim time ``t_ns`` (the component's), published."""
        fresh = {k for k, m in msgs.items() if self.fresh(k, m, t_ns)}
        samples = [(s, k, self.to_core.one(k, m)) for s, k, m in
                   self.external_samples(t_ns)] if self.external else ()
        est = self.component.step(t_ns, self.to_core(msgs), fresh.__contains__, missing,
                                  samples, tuple(self.external))
        if est is None:
            return
        msg = ATTITUDE_STATE.to_msg(est, self.epoch_ns)
        self.est_pub.publish(msg)
        if self.tf_pub.wanted():          # /tf and the filter diagnostics: only when read
            self.tf_pub.send(estimate_transforms(msg.header.stamp,
                                                 self.component.last_ref.r_eci, est.q_eci_body))
        if self.diag_pub.get_subscription_count() > 0:
            self.diag_pub.publish(DIAGNOSTICS.to_msg(self.component.diagnostics(t_ns),
                                                     self.epoch_ns))


def main(args=None) -> int:
    """``ros2 run adcs_nodes estimator``."""
    return runtime.run(EstimatorNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
