"""What a run's capture is measured against: the attitude the scenario's guidance commands,
``angle(t_k) = 2 atan2(|v|, |w|)`` of ``q_orbit_target(t_k)^* (x) q_orbit_body(t_k)`` [deg]
with the target published last at or before ``t_k`` (``docs/montecarlo.md``, "What captured
means")."""
from __future__ import annotations

import os
from typing import Any, Dict

from adcs_nodes.tools.analyse import metrics

#: ``capture_reference`` of a scenario whose guidance holds the orbit frame.
ORBIT_FRAME = 'orbit frame'
#: ``capture_reference`` of any other guidance profile.
GUIDANCE_TARGET = 'guidance target'
_GUIDANCE_MODULE = 'adcs_nodes.nodes.guidance'


def capture_reference(sc: Dict[str, Any]) -> str:
    """:data:`ORBIT_FRAME` when the validated scenario ``sc``'s guidance holds the identity in
    the orbit frame from start to end (or there is no guidance: no controller), else
    :data:`GUIDANCE_TARGET`. The guidance is the component the run steps, built from the
    parameters :func:`~adcs_nodes.graph.build_graph` gives the guidance node."""
    from adcs_nodes.components.base import param_values
    from adcs_nodes.components.guidance import PARAMS, GuidanceComponent
    from adcs_nodes.core.guidance import Guidance
    from adcs_nodes.graph import build_graph

    specs = [s for s in build_graph(sc, sc['duration_s']) if s.module == _GUIDANCE_MODULE]
    if not specs:
        return ORBIT_FRAME
    g = GuidanceComponent(param_values(PARAMS, specs[0].params)).guidance
    if isinstance(g, Guidance) and g.frame == 'orbit' and all(
            s.type == 'hold' and metrics.angle_to_identity_deg(s.q)[0] == 0.0
            for s in g.segments):
        return ORBIT_FRAME
    return GUIDANCE_TARGET


def label_old_result(run_dir: str, result: Dict[str, Any]) -> Dict[str, Any]:
    """A run's result as a resumed campaign reads it: a plain ``result.json`` without
    ``capture_reference`` (it measured to the orbit frame) labelled so when that is its
    scenario's reference, else ValueError (run again); OSError, KeyError or ScenarioError for
    an unreadable scenario."""
    from adcs_nodes.scenario import load_scenario

    if result.get('engine') != 'plain' or 'capture_reference' in result:
        return result
    if capture_reference(load_scenario(os.path.join(run_dir, 'scenario.yaml'))) != ORBIT_FRAME:
        raise ValueError('the run is from before the plain worker recorded the guidance '
                         'target (series.npz has no q_orbit_target) and measured capture to '
                         'the orbit frame; this scenario is judged against its guidance '
                         'target: the run is run again')
    return {**result, 'capture_reference': ORBIT_FRAME}
