"""The plain engine's Monte Carlo run: one prepared run directory through the FrameLoop
(``python -m adcs_nodes.tools.campaigns.worker RUN_DIR``), and the per-frame series a study or
a campaign reads (:func:`run_series`)."""
from __future__ import annotations

import os
from typing import Any, Dict, List, Optional, Sequence

from adcs_nodes.tools.run.plain import one_blas_thread
from sim_node.engine import FrameLoop


def run_series(loop: FrameLoop) -> Dict[str, Any]:
    """Run ``loop`` to the end and return the per-frame series a study or a Monte Carlo run
    needs (numpy arrays, one row per frame).

    ``t_s`` [s]; ``q_orbit_body`` (n, 4) truth; ``w_eci``, ``w_orbit`` (n, 3) true
    ``omega_body_eci_body``, ``omega_body_orbit_body`` [rad/s]; ``q_est`` (n, 4) and
    ``w_est`` (n, 3) the latest estimate (NaN before the first); ``angle_deg`` truth angle
    body to orbit frame; ``est_err_deg``, ``rate_err_deg_s`` estimate errors; ``active``
    the controller whose command was forwarded (``source`` of ``adcs/actuator_command``);
    ``period_s`` the orbital period at the end.

    ``q_orbit_target`` (n, 4): the guidance target the run published (``q_ref_body`` of the
    latest ``adcs/attitude_target``, held between guidance frames; NaN before the first, and
    throughout a run without guidance) in the orbit frame: a target in the ECI frame
    (``header.frame_id`` ``'eci'``) is converted with the frame's truth,
    ``q_orbit_target = q_orbit_body (x) q_eci_body^* (x) q_eci_target``. ``target_judged``
    (n,) bool: False while that target is a paper 001 maneuver's end state (``profile``
    ``'maneuver'``; the capture test leaves those samples out,
    :mod:`adcs_nodes.tools.campaigns.capture`), else True.
    """
    import math

    import numpy as np

    from adcs_nodes.core import attitude
    from adcs_nodes.tools.analyse import metrics
    rows: Dict[str, List[Any]] = {k: [] for k in ('t_s', 'q_orbit_body', 'w_eci', 'w_orbit',
                                                  'q_est', 'w_est', 'active', 'q_orbit_target',
                                                  'target_judged')}
    q_est, w_est = np.full(4, np.nan), np.full(3, np.nan)
    q_target, eci, judged = np.full(4, np.nan), False, True    # the latest target
    active, rate = 'zero', 0.0
    for frame in loop.run():
        state = None
        for topic, x in frame.outputs:                # core samples (adcs_nodes.core.samples)
            if topic == 'sim/state':
                state = x
            elif topic == 'adcs/attitude_estimate':
                q_est, w_est = x.q_orbit_body, x.omega_body_eci_body
            elif topic == 'adcs/actuator_command':
                active = x.source
            elif topic == 'sim/environment':
                rate = float(x.orbit_rate_rad_s)
            elif topic == 'adcs/attitude_target':
                q_target, eci = x.q_ref_body, x.frame == 'eci'
                judged = x.profile != 'maneuver'
        q_body = state.q_orbit_body
        rows['t_s'].append(frame.t_ns / 1e9)
        rows['q_orbit_body'].append(q_body)
        rows['w_eci'].append(state.omega_body_eci_body)
        rows['w_orbit'].append(state.omega_body_orbit_body)
        rows['q_est'].append(q_est)
        rows['w_est'].append(w_est)
        rows['active'].append(active)
        rows['q_orbit_target'].append(attitude.multiply(attitude.multiply(
            q_body, attitude.conjugate(state.q_eci_body)), q_target) if eci else q_target)
        rows['target_judged'].append(judged)
    out = {k: np.asarray(v) for k, v in rows.items()}
    out['angle_deg'] = metrics.angle_to_identity_deg(out['q_orbit_body'])
    out['est_err_deg'] = metrics.angle_between_deg(out['q_est'], out['q_orbit_body'])
    out['rate_err_deg_s'] = np.degrees(np.linalg.norm(out['w_est'] - out['w_eci'], axis=1))
    out['period_s'] = 2.0 * math.pi / rate if rate > 0 else float('nan')
    return out


def mc_worker(run_dir: str) -> int:
    """One Monte Carlo run on the plain engine (``adcs montecarlo``, any scenario).

    Reads ``job.json`` and ``scenario.yaml`` of the prepared run directory, runs the
    FrameLoop, writes ``series.npz`` (per-frame truth, estimate error and the guidance target
    the run published, :func:`run_series`) and ``result.json`` with
    :func:`adcs_nodes.tools.campaigns.results.series_metrics` (the same result as a graph
    run): capture judged against the recorded target, or the orbit frame, as the scenario's
    ``capture_reference`` says (:mod:`adcs_nodes.tools.campaigns.capture`); or
    ``failed.json``. Exit code 130 on SIGINT (nothing written).
    """
    import json
    import time
    import uuid

    import numpy as np

    from adcs_nodes.tools.analyse import metrics
    from adcs_nodes.tools.campaigns.capture import ORBIT_FRAME, capture_reference
    from adcs_nodes.tools.campaigns.files import RESULT_FILE, SERIES_FILE, write_json_atomic
    from adcs_nodes.tools.campaigns.results import angle_to_target_deg, series_metrics
    from adcs_nodes.tools.campaigns.runner import fail, result_head
    from adcs_nodes.scenario import ScenarioError, load_scenario

    t0 = time.monotonic()
    with open(os.path.join(run_dir, 'job.json'), encoding='utf-8') as fh:
        job = json.load(fh)
    try:
        sc = load_scenario(os.path.join(run_dir, 'scenario.yaml'))
        reference = capture_reference(sc)
        s = run_series(FrameLoop.from_scenario(sc, job['duration_s']))
    except KeyboardInterrupt:
        return 130
    except (ScenarioError, ValueError) as exc:
        return fail(run_dir, job, 2, str(exc), time.monotonic() - t0)
    tmp = os.path.join(run_dir, f'series.tmp-{uuid.uuid4().hex}.npz')   # unique per attempt
    np.savez_compressed(tmp, **{k: s[k] for k in ('t_s', 'q_orbit_body', 'angle_deg',
                                                  'est_err_deg', 'rate_err_deg_s', 'w_eci',
                                                  'w_orbit', 'q_orbit_target',
                                                  'target_judged')})
    os.replace(tmp, os.path.join(run_dir, SERIES_FILE))
    angle = judged = None                 # the orbit frame
    if reference != ORBIT_FRAME:          # the target the run published
        angle = angle_to_target_deg(s['q_orbit_body'], s['q_orbit_target'])
        judged = s['target_judged']
    m = series_metrics(s['t_s'], s['q_orbit_body'], s['w_eci'], s['w_orbit'],
                       job['capture_deg'], job.get('period_s') or s['period_s'],
                       angle_deg=angle, judged=judged)
    est = metrics.hold_stats(s['t_s'], s['est_err_deg'], 0.5 * s['period_s'])
    result = {**result_head(job), **m, 'capture_reference': reference, 'engine': 'plain',
              'bag': None,
              'est_err_median_deg': est.median if est.samples else None,
              'sim_time_s': float(s['t_s'][-1]), 'wall_time_s': time.monotonic() - t0,
              'frames': int(s['t_s'].size), 'missed_frames': 0, 'compose': False,
              'message': 'plain engine (sim_node.engine.FrameLoop)'}
    write_json_atomic(os.path.join(run_dir, RESULT_FILE), result)
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``python -m adcs_nodes.tools.campaigns.worker RUN_DIR`` (the Monte Carlo's plain
    worker)."""
    import sys
    argv = sys.argv[1:] if argv is None else list(argv)
    if len(argv) == 1:
        return mc_worker(argv[0])
    print('usage: python -m adcs_nodes.tools.campaigns.worker RUN_DIR (adcs run --engine '
          'plain runs a scenario)', file=sys.stderr)
    return 2


if __name__ == '__main__':
    import signal
    # a Monte Carlo run started under ``--dask-local`` inherits an ignored SIGINT: the
    # supervisor's SIGINT must stop it
    signal.signal(signal.SIGINT, signal.default_int_handler)
    one_blas_thread()
    raise SystemExit(main())
