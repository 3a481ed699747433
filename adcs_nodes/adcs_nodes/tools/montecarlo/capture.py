"""What a run's capture is measured against: the attitude the scenario's guidance commands.

The capture test (:func:`~adcs_nodes.tools.montecarlo.results.series_metrics`) judges the
angle between the body and the guidance target, ``adcs/attitude_target``, the attitude the
controllers track::

    angle(t_k) = 2 atan2(|v|, |w|),  [v, w] = q_orbit_target(t_k)^* (x) q_orbit_body(t_k)   [deg]

with ``q_orbit_target(t_k)`` the target of the latest guidance frame at or before ``t_k``.

* **Orbit frame** (:data:`ORBIT_FRAME`): a scenario whose guidance holds the identity in the
  orbit frame for the whole run (no ``guidance`` section, as paper 000; paper 003's hold). The
  angle is the angle to the orbit frame, exactly as before the guidance target was used (the
  same numbers, bit for bit).
* **Guidance target** (:data:`GUIDANCE_TARGET`): any other profile (paper 001's maneuvers,
  holds and tracking; the demo's slew). Samples where the target is a maneuver's end state
  are not judged: during a paper 001 ``maneuver`` segment (``profile`` ``'maneuver'``,
  ``time_to_go_s > 0``) the guidance commands the attitude due at the segment's end, which
  the MPI law reaches by then, not the attitude for now (judging them would make every
  run's capture time the end of its last maneuver). A quaternion ``slew`` segment commands
  the attitude for now (the path) and is judged.

Where the target comes from: the graph engine's bag records it (read by
:func:`~adcs_nodes.tools.montecarlo.results.read_truth`). The plain worker's ``series.npz``
(:func:`sim_node.engine.run_series`) holds no target, so :func:`score_plain_result` rebuilds it
from the run's ``scenario.yaml`` with the guidance component the run stepped (the guidance
node's parameters from :func:`~adcs_nodes.tools.graph.build_graph`; the plain engine has no
slew action, the only other source of a target). A ``series.npz`` that carries
``q_orbit_target`` (and ``target_judged``) is used as it is. An ECI-frame profile cannot be
judged from ``series.npz`` (it holds the attitude to the orbit frame only): the plain engine
refuses it (:func:`plain_capture_problem`).
"""
from __future__ import annotations

import json
import os
from typing import Any, Dict, Optional, Tuple

import numpy as np

from adcs_nodes.tools import metrics

#: ``capture_reference`` of a scenario whose guidance holds the orbit frame.
ORBIT_FRAME = 'orbit frame'
#: ``capture_reference`` of any other guidance profile.
GUIDANCE_TARGET = 'guidance target'
_GUIDANCE_MODULE = 'adcs_nodes.nodes.guidance'


def scenario_guidance(sc: Dict[str, Any]) -> Tuple[Any, float]:
    """The guidance a run of the validated scenario ``sc`` steps, and its period [s].

    Returns
    -------
    tuple
        ``(guidance, period_s)``: an object with ``at(t) ->``
        :class:`~adcs_nodes.core.guidance.TargetSample` (the guidance component's profile,
        built from the parameters :func:`~adcs_nodes.tools.graph.build_graph` gives the
        guidance node), and the guidance period; ``(None, 0.0)`` for a scenario without
        controllers (no guidance node).
    """
    from adcs_nodes.components.base import param_values
    from adcs_nodes.components.guidance import PARAMS, GuidanceComponent
    from adcs_nodes.tools.graph import build_graph

    specs = [s for s in build_graph(sc, sc['duration_s']) if s.module == _GUIDANCE_MODULE]
    if not specs:
        return None, 0.0
    p = param_values(PARAMS, specs[0].params)
    return GuidanceComponent(p, clock=None).guidance, float(p['period_s'])


def capture_reference(sc: Dict[str, Any]) -> str:
    """:data:`ORBIT_FRAME` when the scenario's guidance holds the identity in the orbit frame
    from start to end (or there is no guidance: no controller), else :data:`GUIDANCE_TARGET`."""
    from adcs_nodes.core.guidance import Guidance

    g, _ = scenario_guidance(sc)
    if g is None or isinstance(g, Guidance) and g.frame == 'orbit' and all(
            s.type == 'hold' and metrics.angle_to_identity_deg(s.q)[0] == 0.0
            for s in g.segments):
        return ORBIT_FRAME
    return GUIDANCE_TARGET


def plain_capture_problem(sc: Dict[str, Any]) -> Optional[str]:
    """Why the plain engine's series cannot judge capture for ``sc``; None when they can."""
    g, _ = scenario_guidance(sc)
    if getattr(g, 'frame', 'orbit') != 'orbit':
        return (f'the guidance profile is in the {g.frame} frame and the plain engine\'s '
                'series.npz holds the attitude to the orbit frame only: run this campaign '
                'with --engine graph (its bag records the target and the ECI attitude)')
    return None


def guidance_targets(sc: Dict[str, Any], t_s: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """The guidance target at each sample time of a run of ``sc``.

    Parameters
    ----------
    sc : dict
        The run's validated scenario (a profile in the orbit frame).
    t_s : numpy.ndarray, shape (n,)
        Frame times since the start [s].

    Returns
    -------
    q_orbit_target : numpy.ndarray, shape (n, 4)
        Target attitude (target body -> orbit frame, scalar last) of the latest guidance
        frame at or before each time.
    judged : numpy.ndarray of bool, shape (n,)
        False where the target is a maneuver's end state (module docstring).

    Raises
    ------
    ValueError
        For a profile in another frame than the orbit frame.
    """
    problem = plain_capture_problem(sc)
    if problem is not None:
        raise ValueError(problem)
    g, period_s = scenario_guidance(sc)
    period_ns = int(round(period_s * 1e9))
    t_ns = np.rint(np.asarray(t_s, dtype=float) * 1e9).astype(np.int64)
    fired_ns, index = np.unique(t_ns - t_ns % period_ns, return_inverse=True)
    samples = [g.at(t / 1e9) for t in fired_ns.tolist()]   # as the component: t_ns / 1e9
    q = np.array([s.q_ref_body for s in samples], dtype=float)
    judged = np.array([s.profile != 'maneuver' for s in samples], dtype=bool)
    return q[index], judged[index]


def score_plain_result(run_dir: str, result: Dict[str, Any]) -> Dict[str, Any]:
    """A plain run's result with its capture judged against its scenario's guidance target.

    The plain worker measures the angle to the orbit frame. For a scenario whose guidance
    holds the orbit frame that is the capture test (only ``capture_reference`` is added);
    otherwise the metrics of :func:`~adcs_nodes.tools.montecarlo.results.series_metrics` are
    computed again from ``series.npz`` against the target (:func:`guidance_targets`, or the
    series' own ``q_orbit_target``). The result is written back to ``result.json``
    (atomically), so this runs once per run; a result that has ``capture_reference``, or is
    not a plain run's, is returned as it is.

    Raises
    ------
    OSError, ValueError, KeyError, adcs_nodes.tools.scenario.ScenarioError
        When the run's files cannot be read or its guidance is not in the orbit frame.
    """
    from adcs_nodes.tools.montecarlo.files import RESULT_FILE, SERIES_FILE, write_json_atomic
    from adcs_nodes.tools.montecarlo.results import angle_to_target_deg, series_metrics
    from adcs_nodes.tools.scenario import load_scenario

    if result.get('engine') != 'plain' or 'capture_reference' in result:
        return result
    sc = load_scenario(os.path.join(run_dir, 'scenario.yaml'))
    reference = capture_reference(sc)
    out = dict(result)
    if reference == GUIDANCE_TARGET:
        with open(os.path.join(run_dir, 'job.json'), encoding='utf-8') as fh:
            capture_deg = float(json.load(fh)['capture_deg'])
        with np.load(os.path.join(run_dir, SERIES_FILE)) as s:
            series = {k: s[k] for k in s.files}
        t = series['t_s']
        if 'q_orbit_target' in series:         # recorded by the worker
            q_target = series['q_orbit_target']
            judged = series.get('target_judged', np.ones(t.size, dtype=bool))
        else:
            q_target, judged = guidance_targets(sc, t)
        out.update(series_metrics(
            t, series['q_orbit_body'], series['w_eci'], series['w_orbit'], capture_deg,
            result.get('period_s'),
            angle_deg=angle_to_target_deg(series['q_orbit_body'], q_target), judged=judged))
    out['capture_reference'] = reference
    write_json_atomic(os.path.join(run_dir, RESULT_FILE), out)
    return out
