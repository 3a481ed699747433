"""The plain engine's Monte Carlo run (:func:`mc_worker`, in a worker process of
:mod:`.runner`), and the per-frame series a study or a campaign reads (:func:`run_series`)."""
from __future__ import annotations

import itertools
import os
import time
from typing import Any, Dict, Iterator, List

from sim_node.engine import FrameLoop


def run_series(loop: FrameLoop) -> Dict[str, Any]:
    """Run ``loop`` to the end: its per-frame series (NaN before a topic's first sample): truth
    ``q_orbit_body``, ``w_eci``, ``w_orbit`` [rad/s]; latest estimate ``q_est``, ``w_est``;
    ``angle_deg``, ``est_err_deg``, ``rate_err_deg_s``; ``active``; ``period_s``; the latest
    target in the orbit frame ``q_orbit_target`` and ``target_judged``; ``dipole_body_Am2``,
    ``b_body_T`` (body axes), ``wheel_momentum_Nms``, ``wheel_torque_Nm`` (n, wheels)."""
    import math

    import numpy as np

    from adcs_nodes.core import attitude
    from adcs_nodes.tools.analyse import metrics
    rows: Dict[str, List[Any]] = {k: [] for k in ('t_s', 'q_orbit_body', 'w_eci', 'w_orbit',
                                                  'q_est', 'w_est', 'active', 'q_orbit_target',
                                                  'target_judged', 'dipole_body_Am2',
                                                  'b_body_T', 'wheel_momentum_Nms',
                                                  'wheel_torque_Nm')}
    q_est, w_est, dipole = np.full(4, np.nan), np.full(3, np.nan), np.zeros(3)
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
                active, dipole = x.source, x.dipole_body_Am2
            elif topic == 'sim/environment':
                rate, b_eci = float(x.orbit_rate_rad_s), x.b_eci_T
            elif topic == 'sim/wheels':
                wheels = x
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
        rows['dipole_body_Am2'].append(dipole)
        rows['b_body_T'].append(attitude.to_matrix(state.q_eci_body).T @ b_eci)
        rows['wheel_momentum_Nms'].append(wheels.momentum_Nms)
        rows['wheel_torque_Nm'].append(wheels.torque_Nm)
    out = {k: np.asarray(v) for k, v in rows.items()}
    out['angle_deg'] = metrics.angle_to_identity_deg(out['q_orbit_body'])
    out['est_err_deg'] = metrics.angle_between_deg(out['q_est'], out['q_orbit_body'])
    out['rate_err_deg_s'] = np.degrees(np.linalg.norm(out['w_est'] - out['w_eci'], axis=1))
    out['period_s'] = 2.0 * math.pi / rate if rate > 0 else float('nan')
    return out


def mc_worker(run_dir: str) -> int:
    """One plain-engine Monte Carlo run in a prepared run directory; 130 on SIGINT."""
    import json
    import uuid

    import numpy as np

    from adcs_nodes.tools.analyse import metrics
    from adcs_nodes.tools.campaigns.capture import ORBIT_FRAME, capture_reference
    from adcs_nodes.tools.campaigns.files import (RESULT_FILE, SERIES_FILE, fail, result_head,
                                                  write_json_atomic)
    from adcs_nodes.tools.campaigns.results import series_metrics
    from adcs_nodes.scenario import ScenarioError, load_scenario

    t0, cpu0 = time.monotonic(), time.process_time()
    with open(os.path.join(run_dir, 'job.json'), encoding='utf-8') as fh:
        job = json.load(fh)
    try:
        sc = load_scenario(os.path.join(run_dir, 'scenario.yaml'))
        reference = capture_reference(sc)
        loop = CpuTimed(lambda: FrameLoop.from_scenario(sc, job['duration_s']))
        s = run_series(loop)
    except KeyboardInterrupt:
        return 130
    except (ScenarioError, ValueError) as exc:
        return fail(run_dir, job, 2, str(exc), time.monotonic() - t0)
    tmp = os.path.join(run_dir, f'series.tmp-{uuid.uuid4().hex}.npz')   # unique per attempt
    np.savez(tmp, **{k: s[k] for k in ('t_s', 'q_orbit_body', 'angle_deg', 'est_err_deg',
                                       'rate_err_deg_s', 'w_eci', 'w_orbit', 'q_orbit_target',
                                       'target_judged', 'active', 'dipole_body_Am2',
                                       'b_body_T', 'wheel_momentum_Nms', 'wheel_torque_Nm')})
    os.replace(tmp, os.path.join(run_dir, SERIES_FILE))
    angle = judged = None                 # the orbit frame
    if reference != ORBIT_FRAME:          # the target the run published
        angle = metrics.angle_between_deg(s['q_orbit_target'], s['q_orbit_body'])
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
              'frameloop_cpu_s': loop.cpu_s, 'cpu_s': time.process_time() - cpu0,
              'message': 'plain engine (sim_node.engine.FrameLoop)'}
    write_json_atomic(os.path.join(run_dir, RESULT_FILE), result)
    return 0


class CpuTimed:
    """The FrameLoop ``build()`` returns, with the CPU time [s] of building and stepping it."""

    CHUNK = 64

    def __init__(self, build: Any) -> None:
        cpu0 = time.process_time()
        self.loop = build()
        self.cpu_s = time.process_time() - cpu0

    def __getattr__(self, name: str) -> Any:
        return getattr(self.loop, name)

    def run(self, *args: Any, **kwargs: Any) -> Iterator[Any]:
        frames = self.loop.run(*args, **kwargs)
        while True:
            cpu0 = time.process_time()
            chunk = list(itertools.islice(frames, self.CHUNK))
            self.cpu_s += time.process_time() - cpu0
            if not chunk:
                return
            yield from chunk
