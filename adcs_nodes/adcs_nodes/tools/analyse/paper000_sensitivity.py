"""Paper 000's hold accuracy against the random torque's correlation time and the magnetometer
misalignment (``study sensitivity``); :data:`MEASURED`: the last run, shown by the report."""
from __future__ import annotations

import json
import os
from typing import Any, Dict, Optional

#: The last run of :func:`sensitivity` (2026-12-02, alpha 2e-3: the gain map's).
MEASURED = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'paper000_sensitivity.json')

#: Sensitivity cases: the random torque's correlation time [s] and the misalignment [deg].
CORRELATION_S = (0.1, 0.5, 2.0)
MISALIGNMENT_DEG = (0.0, 0.5, 1.0, 2.0)
#: Hold-only runs: on the target, the filter on the truth with a converged covariance (the
#: acquisition P0 would tumble the satellite again), this many orbits, hold statistics from
#: HOLD_ONLY_FROM orbits on.
HOLD_ONLY_ORBITS = 3.0
HOLD_ONLY_FROM = 1.0
ON_TARGET = {'initial.q_orbit_body_wxyz': [1.0, 0.0, 0.0, 0.0], 'initial.q_orbit_body_xyzw': None,
             'initial.omega_body_eci_body_deg_s': None,
             'initial.omega_body_orbit_body_deg_s': [0.0, 0.0, 0.0],
             'estimator.p0_diag': [1e-4] * 3 + [1e-8] * 3 + [1e-14] * 3}


def summarize(s: Dict[str, Any]) -> Dict[str, Any]:
    """``run_metrics`` and the estimation error from half an orbit on, of a ``run_series``."""
    from adcs_nodes.tools.analyse import metrics
    out = metrics.run_metrics(s['t_s'], s['angle_deg'], s['period_s'])
    est = metrics.hold_stats(s['t_s'], s['est_err_deg'], s['t_s'][0] + 0.5 * s['period_s'])
    out.update({'est_err_median_deg': est.median, 'est_err_p95_deg': est.p95,
                'duration_s': float(s['t_s'][-1] - s['t_s'][0])})
    return out


def _series(sc: Dict[str, Any], changes: Dict[str, Any], duration_s: Optional[float]):
    from adcs_nodes.scenario import apply_overrides
    from adcs_nodes.tools.campaigns.worker import run_series
    from sim_node.engine import FrameLoop
    return run_series(FrameLoop.from_scenario(apply_overrides(sc, changes), duration_s))


def hold_only(sc: Dict[str, Any], changes: Dict[str, Any]) -> Dict[str, Any]:
    """Hold accuracy started on the target (:data:`ON_TARGET`): no chaotic acquisition."""
    from adcs_nodes.tools.analyse import metrics
    from adcs_nodes.tools.analyse.papers.series import orbit_period_s
    period = orbit_period_s(sc)
    frame = float(sc['timing']['frame_s'])
    s = _series(sc, {**changes, **ON_TARGET}, int(HOLD_ONLY_ORBITS * period / frame) * frame)
    hs = metrics.hold_stats(s['t_s'], s['angle_deg'], HOLD_ONLY_FROM * period)
    est = metrics.hold_stats(s['t_s'], s['est_err_deg'], HOLD_ONLY_FROM * period)
    return {'rms_deg': hs.rms, 'median_deg': hs.median, 'p95_deg': hs.p95, 'max_deg': hs.max,
            'est_err_median_deg': est.median}


def sensitivity(sc: Dict[str, Any], duration_s: Optional[float] = None,
                log=print) -> Dict[str, Any]:
    """Hold accuracy, one parameter changed at a time (the shape of :data:`MEASURED`)."""
    import time

    import numpy as np

    from adcs_nodes.tools.analyse.papers.paper000 import misalignment_vector, orbits_text
    base_corr = float(sc['spacecraft']['disturbance']['random_period_s'])
    mis = sc['sensors']['magnetometer'].get('misalignment_deg', [0.0, 0.0, 0.0])
    base_mis = float(np.linalg.norm(mis))
    cases = [('random_period_s', tc, {'spacecraft.disturbance.random_period_s': tc})
             for tc in CORRELATION_S]
    cases += [('misalignment_deg', m,
               {'sensors.magnetometer.misalignment_deg': misalignment_vector(m)})
              for m in MISALIGNMENT_DEG]
    out: Dict[str, Any] = {
        'scenario': sc.get('name'), 'seed': int(sc['seed']),
        'duration_s': float(duration_s or sc['duration_s']),
        'hold_only_orbits': HOLD_ONLY_ORBITS, 'hold_only_from_orbits': HOLD_ONLY_FROM,
        'baseline': {'random_period_s': base_corr, 'misalignment_deg': base_mis},
        'engine': 'FrameLoop (plain engine)', 'cases': []}
    done: Dict[tuple, Dict[str, Any]] = {}
    for what, value, changes in cases:
        key = (base_corr if what != 'random_period_s' else value,
               base_mis if what != 'misalignment_deg' else value)
        if key in done:            # the baseline appears in both sweeps: run it once
            res = done[key]
        else:
            t0 = time.monotonic()
            m = summarize(_series(sc, changes, duration_s))
            res = {k: m[k] for k in ('capture_orbits', 'last_exit_orbits', 'first_entry_s',
                                     'hold_rms_deg', 'hold_median_deg', 'hold_p95_deg',
                                     'hold_max_deg', 'est_err_median_deg')}
            res['hold_only'] = hold_only(sc, changes)
            res['wall_s'] = time.monotonic() - t0
            done[key] = res
        h = res['hold_only']
        log(f'[sensitivity] {what} = {value:g}: from the paper state: capture '
            f'{orbits_text(res["capture_orbits"])} orbits, last exit '
            f'{orbits_text(res["last_exit_orbits"])}, hold RMS {res["hold_rms_deg"]:.2f} / '
            f'median {res["hold_median_deg"]:.2f} / p95 {res["hold_p95_deg"]:.2f} deg; on '
            f'target: RMS {h["rms_deg"]:.2f} / median {h["median_deg"]:.2f} / p95 '
            f'{h["p95_deg"]:.2f} deg, estimation median {h["est_err_median_deg"]:.2f} deg '
            f'({res["wall_s"]:.0f} s wall)')
        out['cases'].append({'parameter': what, 'value': value, **res})
    return out


_PARAM_NAMES = {'random_period_s': 'random torque correlation [s]',
                'misalignment_deg': 'magnetometer misalignment [deg]'}


def sensitivity_markdown(data: Optional[Dict[str, Any]] = None) -> str:
    """Markdown table of :func:`sensitivity`'s ``data`` (default :data:`MEASURED`)."""
    from adcs_nodes.tools.analyse.papers.paper000 import orbits_text
    if data is None:
        with open(MEASURED, encoding='utf-8') as fh:
            data = json.load(fh)
    base = data['baseline']
    lines = [
        f'Scenario `{data["scenario"]}`, seed {data["seed"]}, one parameter changed at a time '
        f'from the scenario (random-torque correlation {base["random_period_s"]:g} s, '
        f'misalignment {base["misalignment_deg"]:g} deg). "From the paper state": '
        f'{data["duration_s"] / 5913.8:.1f} orbits from the paper\'s initial tumble, hold from '
        f'4 orbits. "On target": started on the orbital frame, '
        f'{data["hold_only_orbits"]:g} orbits, hold from {data["hold_only_from_orbits"]:g} '
        'orbit (the hold alone, without the acquisition, which is chaotic: one run of it is '
        'one sample of the Monte Carlo). FrameLoop runs (the plain engine: the graph\'s '
        'series to the last bit) with scenario overrides (`python -m '
        'adcs_nodes.tools.analyse.study '
        'sensitivity`).', '',
        '| parameter | value | capture [orbits] | last exit 5 deg [orbits] | hold RMS / median '
        '/ 95 % [deg] | on target: RMS / median / 95 % [deg] | on target: estimation error '
        'median [deg] |',
        '|---|---:|---:|---:|---|---|---:|']
    for c in data['cases']:
        name = _PARAM_NAMES.get(c['parameter'], c['parameter'])
        h = c['hold_only']
        lines.append(f'| {name} | {c["value"]:g} | {orbits_text(c["capture_orbits"])} | '
                     f'{orbits_text(c["last_exit_orbits"])} | {c["hold_rms_deg"]:.2f} / '
                     f'{c["hold_median_deg"]:.2f} / {c["hold_p95_deg"]:.2f} | '
                     f'{h["rms_deg"]:.2f} / {h["median_deg"]:.2f} / {h["p95_deg"]:.2f} | '
                     f'{h["est_err_median_deg"]:.2f} |')
    if data.get('note'):
        lines += ['', data['note']]
    return '\n'.join(lines) + '\n'
