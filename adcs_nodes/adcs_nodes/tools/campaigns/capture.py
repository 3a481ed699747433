"""What a run's capture is measured against: the guidance target last published
(``docs/montecarlo.md``, "What captured means")."""
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
    """:data:`ORBIT_FRAME` when the scenario's guidance (or none) holds the identity in the
    orbit frame from start to end, else :data:`GUIDANCE_TARGET`."""
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
    """An old plain result (to the orbit frame) labelled so if right, else ValueError."""
    from adcs_nodes.scenario import load_scenario

    if result.get('engine') != 'plain' or 'capture_reference' in result:
        return result
    if capture_reference(load_scenario(os.path.join(run_dir, 'scenario.yaml'))) != ORBIT_FRAME:
        raise ValueError('the run is from before the plain worker recorded the guidance '
                         'target (series.npz has no q_orbit_target) and measured capture to '
                         'the orbit frame; this scenario is judged against its guidance '
                         'target: the run is run again')
    return {**result, 'capture_reference': ORBIT_FRAME}
