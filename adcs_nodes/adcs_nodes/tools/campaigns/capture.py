"""What a run's capture is measured against: the attitude the scenario's guidance commands.

The capture test (:func:`~adcs_nodes.tools.campaigns.results.series_metrics`) judges::

    angle(t_k) = 2 atan2(|v|, |w|),  [v, w] = q_orbit_target(t_k)^* (x) q_orbit_body(t_k)   [deg]

with ``q_orbit_target(t_k)`` the target the run published last at or before ``t_k``: the
orbit frame (:data:`ORBIT_FRAME`) for a scenario whose guidance holds it, else the guidance
target (:data:`GUIDANCE_TARGET`), a ``maneuver`` segment's samples not judged. Per scenario,
where the target comes from, and results from before it was recorded:
``docs/montecarlo.md``, "What captured means".
"""
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
    """A run's result as a resumed campaign reads it.

    A plain run's ``result.json`` without ``capture_reference`` is from before the plain
    worker recorded the guidance target (its ``series.npz`` has no ``q_orbit_target``): its
    numbers are the angle to the orbit frame. For a scenario whose reference is the orbit
    frame those are the capture test's numbers: returned with ``capture_reference`` added
    (the file is left as it is). Any other result is returned as it is.

    Raises
    ------
    ValueError
        For such a result of a scenario judged against its guidance target (the run is not
        done: the campaign runs it again).
    OSError, KeyError, adcs_nodes.scenario.ScenarioError
        When the run's scenario cannot be read.
    """
    from adcs_nodes.scenario import load_scenario

    if result.get('engine') != 'plain' or 'capture_reference' in result:
        return result
    if capture_reference(load_scenario(os.path.join(run_dir, 'scenario.yaml'))) != ORBIT_FRAME:
        raise ValueError('the run is from before the plain worker recorded the guidance '
                         'target (series.npz has no q_orbit_target) and measured capture to '
                         'the orbit frame; this scenario is judged against its guidance '
                         'target: the run is run again')
    return {**result, 'capture_reference': ORBIT_FRAME}
