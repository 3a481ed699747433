"""The whole closed loop of a scenario in one plain Python loop (no ROS): fast studies.

What it runs, per frame ``t_k`` (the lockstep order of the graph, README "Timing"):

1. environment at ``t_k`` (orbit, truth field), as the ``environment`` node;
2. truth state at ``t_k``; magnetometer sample when ``t_k`` is a multiple of its period, as
   the ``magnetometer`` node (same model, same seed ``derive_seed(seed, 'magnetometer')``);
3. estimator (``magnetic_filter``): predict from ``t_{k-1}`` with the command applied since
   then, update with the fresh sample, as the ``estimator`` node;
4. every controller (shadow mode) on the estimate and the fresh sample, else the onboard
   model field; the controller manager picks and checks one command;
5. dynamics: the command held over ``[t_k, t_{k+1}]``, RK4 substeps, as ``dynamics``.

Every model and law is the project's own core class built from the parameters the launcher
gives the nodes (:func:`adcs_nodes.tools.graph.build_graph`), so a run gives the graph's
trajectory without the message passing (numbers agree with the graph to the rounding of
the float64 messages). Only the ``magnetic_filter`` estimator and the ``magnetic`` / ``bdot``
controllers are wired here (paper 000); another estimator or controller raises ValueError.

Command line::

    python -m sim_node.tools.closed_loop run SCENARIO [--duration S] [--set KEY=VALUE ...]
    python -m sim_node.tools.closed_loop sensitivity SCENARIO [--duration S] [--out FILE.json]

``sensitivity`` writes the hold accuracy of ``paper000_control`` against the random torque's
correlation time (0.1, 0.5, 2 s) and the magnetometer misalignment (0, 0.5, 1, 2 deg), the
table that ``adcs report`` shows (:mod:`adcs_nodes.tools.paper000_sensitivity`).
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import os
import signal
import sys
import time
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from adcs_nodes.core import attitude as att
from adcs_nodes.core.control import ControlInputs, Estimate
from adcs_nodes.core.lockstep import derive_seed
from adcs_nodes.tools import metrics


def _section(params: dict, prefix: str, default: Optional[dict] = None) -> dict:
    n = len(prefix) + 1
    out = {k[n:]: v for k, v in params.items() if k.startswith(prefix + '.')}
    return out if out or default is None else dict(default)


def _values(specs, params: dict) -> Dict[str, Any]:
    """``{name: value}`` of registry parameter specs: the node parameter, else the default."""
    return {spec.name: params.get(spec.name, spec.default) for spec in specs}


class ClosedLoop:
    """One scenario's world, sensors and flight software in a plain loop.

    Parameters
    ----------
    sc : dict
        Validated scenario (:func:`adcs_nodes.tools.scenario.load_scenario`).
    duration_s : float, optional
        Simulated duration [s] (default: the scenario's ``duration_s``).
    estimator : str
        ``'paper'`` (the scenario's estimator) or ``'truth'`` (the controllers get the true
        state: an ideal-knowledge reference run).
    """

    def __init__(self, sc: Dict[str, Any], duration_s: Optional[float] = None,
                 estimator: str = 'paper') -> None:
        from adcs_nodes import registry
        from adcs_nodes.core.estimation.onboard import make_onboard_reference
        from adcs_nodes.core.manager import AutoSequence, ControllerManagerCore
        from adcs_nodes.nodes import controller as controller_node
        from adcs_nodes.nodes import estimator as estimator_node
        from adcs_nodes.tools.graph import build_graph

        from adcs_nodes.tools.montecarlo.engine import plain_engine_problem

        problem = plain_engine_problem(sc)
        if problem is not None:
            raise ValueError(f'closed loop: {problem}')
        self.sc = sc
        self.duration_s = float(sc['duration_s'] if duration_s is None else duration_s)
        self.frame_s = float(sc['timing']['frame_s'])
        self.substeps = int(sc['timing']['substeps'])
        nodes = {n.name: n.params for n in build_graph(sc, self.duration_s)}
        self.nodes = nodes
        for params in nodes.values():
            registry.load_plugins(params.get('plugins', []))
        self.world = _World(sc, nodes)
        epoch = self.world.epoch
        if estimator not in ('paper', 'truth'):
            raise ValueError(f"estimator must be 'paper' or 'truth', got {estimator!r}")
        self.ideal = estimator == 'truth'
        # magnetometer: the sensor's registry entry, as the magnetometer node builds it
        mp = nodes.get('magnetometer')
        if mp is None:
            raise ValueError('closed loop: the scenario has no magnetometer')
        entry = registry.get('sensor', 'magnetometer')
        self.mag_period = float(mp.get('period_s', 1.0))
        self.mag = entry.build(_values(entry.params, mp),
                               {'seed': derive_seed(int(sc['seed']), 'magnetometer')})
        self.q_body_mag = att.normalize(mp.get('q_body_sensor_xyzw', [0.0, 0.0, 0.0, 1.0]))
        # estimator: its registry entry with the estimator node's context
        ep = nodes.get('estimator')
        if ep is None:
            raise ValueError('closed loop: the scenario has no estimator')
        ectx = _values(estimator_node.CONTEXT_PARAMS, ep)
        entry = registry.get('estimator', ectx['algorithm'])
        if 'magnetometer' not in entry.inputs:
            raise ValueError(f'closed loop: estimator {entry.name} does not use the magnetometer')
        self.est_period = float(ectx['period_s'])
        self.field_range = (float(ectx['min_field_T']), float(ectx['max_field_T']))
        self.reference = make_onboard_reference(
            _section(ep, 'onboard_orbit', estimator_node.DEFAULT_ORBIT),
            _section(ep, 'onboard_field', estimator_node.DEFAULT_FIELD), epoch)
        self.estimator = entry.build(_values(entry.params, ep), {
            'inertia_kgm2': controller_node.inertia_matrix(ectx['inertia_kgm2']),
            'period_s': ectx['period_s'], 'epoch': epoch, 'seed': int(sc['seed']),
            'reference': self.reference})
        self.estimator.initialise(att.normalize(ectx['initial_q_orbit_body']),
                                  np.asarray(ectx['initial_omega_body_orbit_body'], float))
        # controllers: registry entries with the controller node's context
        self.controllers: Dict[str, Any] = {}
        self.ctrl_period: Dict[str, float] = {}
        self.ctrl_ref: Dict[str, Any] = {}
        for name, p in nodes.items():
            if not name.endswith('_controller'):
                continue
            cctx = _values(controller_node.CONTEXT_PARAMS, p)
            entry = registry.get('controller', cctx['controller'])
            if set(entry.inputs) - {'estimate', 'target', 'magnetometer'}:
                raise ValueError(f'closed loop: controller {entry.name} needs inputs this loop '
                                 f'does not have: {entry.inputs}')
            n_wheels = len(cctx['wheel_max_torque_Nm'])
            axes = np.asarray(cctx['wheel_axes_body'], dtype=float).reshape(n_wheels, 3)
            ref = None
            if {'estimate', 'magnetometer'} <= set(entry.inputs):
                ref = make_onboard_reference(
                    _section(p, 'onboard_orbit', controller_node.DEFAULT_ORBIT),
                    _section(p, 'onboard_field', controller_node.DEFAULT_FIELD), epoch)
            ctx = {'inertia_kgm2': controller_node.inertia_matrix(cctx['inertia_kgm2']),
                   'max_dipole_Am2': cctx['max_dipole_Am2'] if any(cctx['max_dipole_Am2'])
                   else None,
                   'wheel_axes_body': axes, 'wheel_max_torque_Nm': cctx['wheel_max_torque_Nm'],
                   'wheel_max_momentum_Nms': cctx['wheel_max_momentum_Nms'],
                   'wheel_inertia_kgm2': cctx['wheel_inertia_kgm2'],
                   'period_s': cctx['period_s'], 'epoch': epoch, 'seed': int(sc['seed']),
                   'reference': ref}
            self.controllers[entry.name] = entry.build(_values(entry.params, p), ctx)
            self.ctrl_period[entry.name] = float(cctx['period_s'])
            self.ctrl_ref[entry.name] = ref
        mg = nodes['controller_manager']
        sched = [(float(t), str(n)) for t, n in zip(mg.get('schedule_t_s', []),
                                                    mg.get('schedule_controller', [])) if n]
        auto_cfg = _section(mg, 'auto')
        self.auto = bool(auto_cfg)
        self.manager = ControllerManagerCore(
            [n for n in mg['controllers'] if n], str(mg['safe']),
            initial=str(mg.get('initial', '')) or None,
            max_dipole_Am2=list(mg['max_dipole_Am2']),
            max_torque=list(mg.get('max_torque_Nm', [0.0, 0.0, 0.0])),
            stale_after_s=float(mg.get('stale_after_s', 0.0)), schedule=sched,
            auto=AutoSequence.from_dict(auto_cfg) if auto_cfg else None)
        self.man_period = float(mg['period_s'])

    # ------------------------------------------------------------------ one run
    def run(self, progress: bool = False) -> Dict[str, np.ndarray]:
        """Run to the end; returns the per-frame series (see :meth:`series`).

        Returns
        -------
        dict
            ``t_s`` (n,) [s]; ``angle_deg`` (n,) truth angle body to orbit frame; ``est_err_deg``
            (n,) angle between estimated and true ``q_orbit_body``; ``rate_err_deg_s`` (n,);
            ``rate_deg_s`` (n,) true ``|omega_body_eci_body|``; ``w_eci``, ``w_orbit`` (n, 3)
            true ``omega_body_eci_body``, ``omega_body_orbit_body`` [rad/s]; ``active`` (n,)
            forwarded controller names; ``q_orbit_body`` (n, 4); ``period_s``; ``wall_s``.
        """
        from sim_node.models.dynamics import ActuatorCommand, FrameEnvironment
        from sim_node.models.spacecraft_config import initial_state

        w = self.world
        sc = w.spacecraft
        frame_ns = int(round(self.frame_s * 1e9))
        n_frames = int(round(self.duration_s / self.frame_s))
        rec: Dict[str, List[Any]] = {k: [] for k in (
            't_s', 'angle_deg', 'est_err_deg', 'rate_err_deg_s', 'rate_deg_s', 'active',
            'q_orbit_body', 'q_est', 'w_eci', 'w_orbit')}
        state = None
        applied = np.zeros(3)                 # dipole held over the previous frame
        last_est_t: Optional[float] = None
        est: Optional[Estimate] = None
        ctrl_cmds: Dict[str, tuple] = {}
        cmd_model = sc.zero_command()
        start = time.perf_counter()
        period_s = None
        active = 'zero'
        for k in range(n_frames + 1):
            t_ns = k * frame_ns
            t = t_ns / 1e9
            st = w.orbit.state(t)
            period_s = 2.0 * math.pi / float(st.orbit_rate)
            b_eci, b_dot_eci = w.field.field_and_rate(w.orbit, t, st.r_eci)
            if state is None:
                state = initial_state(w.initial, st.q_eci_orbit, st.omega_orbit_eci_eci, sc,
                                      w.wheel_h0)
            q_orbit_body = att.multiply(att.conjugate(st.q_eci_orbit), state.q_eci_body)
            omega = np.asarray(state.omega_body_eci_body, float)
            # 2. magnetometer
            b_body_meas = None
            if _due(t_ns, self.mag_period):
                b_sensor = self.mag.measure(att.to_matrix(state.q_eci_body).T @ b_eci)
                if b_sensor is not None and np.all(np.isfinite(b_sensor)):
                    norm = float(np.linalg.norm(b_sensor))
                    if self.field_range[0] <= norm <= self.field_range[1]:
                        b_body_meas = att.rotate(self.q_body_mag, b_sensor)
            # 3. estimator
            ref = self.reference.at(t)
            if _due(t_ns, self.est_period):
                est = self._estimate(t, last_est_t, ref, applied, b_body_meas)
                last_est_t = t
            if self.ideal:
                est = Estimate(q_orbit_body, omega, float(st.orbit_rate), True,
                               np.asarray(state.q_eci_body, float))
            # 4. controllers (shadow mode) and manager
            for name, core in self.controllers.items():
                if not _due(t_ns, self.ctrl_period[name]):
                    continue
                dt = 0.0 if k == 0 else self.ctrl_period[name]
                model, cref = None, self.ctrl_ref[name]
                if cref is not None and est is not None and est.is_usable():
                    model = att.to_matrix(est.q_orbit_body).T @ cref.at(t).b_orbit
                cmd = core.update(ControlInputs(estimate=est, b_body=b_body_meas,
                                                b_body_model=model), t, dt)
                ctrl_cmds[name] = (t, cmd)
            if _due(t_ns, self.man_period):
                out, status = self.manager.step(t, ctrl_cmds, est if self.auto else None)
                cmd_model = ActuatorCommand(dipole_body=np.asarray(out.dipole_body, float),
                                            wheel_torque=np.zeros(sc.n_wheels),
                                            torque_body=np.asarray(out.torque_body, float))
                active = status.get('source') or 'zero'
            # record frame k
            rec['t_s'].append(t)
            rec['q_orbit_body'].append(q_orbit_body)
            rec['rate_deg_s'].append(math.degrees(float(np.linalg.norm(omega))))
            rec['w_eci'].append(omega)
            rec['w_orbit'].append(omega - att.to_matrix(state.q_eci_body).T
                                  @ np.asarray(st.omega_orbit_eci_eci, float))
            rec['active'].append(active)
            if est is not None:
                rec['q_est'].append(np.asarray(est.q_orbit_body, float))
                rec['rate_err_deg_s'].append(math.degrees(float(np.linalg.norm(
                    np.asarray(est.omega_body_eci_body) - omega))))
            else:
                rec['q_est'].append(np.array([np.nan] * 4))
                rec['rate_err_deg_s'].append(np.nan)
            if k == n_frames:
                break
            # 5. dynamics
            applied = np.asarray(cmd_model.dipole_body, float)
            env = FrameEnvironment(r_eci=st.r_eci, v_eci=st.v_eci, b_eci=b_eci,
                                   b_dot_eci=b_dot_eci)
            state, _ = sc.step(state, t, self.frame_s, env, cmd_model, self.substeps)
            if progress and k % 1000 == 0:
                print(f'  t = {t / period_s:.2f} orbits', file=sys.stderr, flush=True)
        q = np.asarray(rec['q_orbit_body'])
        q_est = np.asarray(rec['q_est'])
        return {'t_s': np.asarray(rec['t_s']), 'q_orbit_body': q,
                'angle_deg': metrics.angle_to_identity_deg(q),
                'est_err_deg': metrics.angle_between_deg(q_est, q),
                'rate_err_deg_s': np.asarray(rec['rate_err_deg_s']),
                'rate_deg_s': np.asarray(rec['rate_deg_s']),
                'w_eci': np.asarray(rec['w_eci']), 'w_orbit': np.asarray(rec['w_orbit']),
                'active': np.asarray(rec['active']), 'period_s': period_s,
                'wall_s': time.perf_counter() - start}

    def _estimate(self, t: float, last_t: Optional[float], ref, dipole: np.ndarray,
                  b_body: Optional[np.ndarray]) -> Optional[Estimate]:
        """The estimator node's step and the estimate its message gives the controllers."""
        from adcs_nodes.core.estimation.algorithms import EstimatorInputs

        dt = 0.0 if last_t is None else t - last_t
        step = self.estimator.step(EstimatorInputs(ref, b_body=b_body,
                                                   dipole_body=np.asarray(dipole, float)), t, dt)
        if step.estimate is None:
            return None
        q = np.asarray(step.estimate.q_orbit_body, float)
        w_abs = np.asarray(step.estimate.omega_body_eci_body, float)
        w_rel = w_abs - att.to_matrix(q).T @ np.array([0.0, ref.omega0, 0.0])
        return Estimate(q, w_abs, float(np.linalg.norm(w_abs - w_rel)), True,
                        att.multiply(ref.q_eci_orbit, q))


class _World:
    """Orbit, truth field and spacecraft, as the environment and dynamics nodes build them."""

    def __init__(self, sc: Dict[str, Any], nodes: Dict[str, dict]) -> None:
        from adcs_nodes.core.geomag import make_field
        from adcs_nodes.core.orbit import make_orbit
        from adcs_nodes.nodes.lockstep_node import parse_epoch
        from sim_node.models.spacecraft_config import DEFAULT_INITIAL, spacecraft_from_config

        env, dyn = nodes['environment'], nodes['dynamics']
        self.epoch = parse_epoch(sc['epoch'])
        self.orbit = make_orbit(_section(env, 'orbit'), self.epoch)
        self.field = make_field(_section(env, 'field'), self.epoch)
        cfg = _section(dyn, 'spacecraft')
        self.spacecraft = spacecraft_from_config(
            cfg, seed=derive_seed(int(sc['seed']), 'dynamics/disturbance'))
        self.initial = {**DEFAULT_INITIAL, **_section(dyn, 'initial')}
        self.wheel_h0 = cfg.get('wheel_h0_Nms')


def _due(t_ns: int, period_s: float) -> bool:
    p = int(round(period_s * 1e9))
    return p > 0 and t_ns % p == 0


# ---------------------------------------------------------------------- scenario edits
def with_changes(sc: Dict[str, Any], changes: Dict[str, Any]) -> Dict[str, Any]:
    """Deep copy of a scenario with ``{'a.b.c': value}`` set (keys must exist or be leaves)."""
    out = copy.deepcopy(sc)
    for dotted, value in changes.items():
        node = out
        *path, leaf = dotted.split('.')
        for key in path:
            node = node.setdefault(key, {})
        if value is None:
            node.pop(leaf, None)
        else:
            node[leaf] = value
    return out


def summarize(series: Dict[str, Any]) -> Dict[str, Any]:
    """End-of-run metrics (:func:`adcs_nodes.tools.metrics.run_metrics`) plus estimation error."""
    out = metrics.run_metrics(series['t_s'], series['angle_deg'], series['period_s'])
    t, e = series['t_s'], series['est_err_deg']
    est = metrics.hold_stats(t, e, t[0] + 0.5 * series['period_s'])
    out.update({'est_err_median_deg': est.median, 'est_err_p95_deg': est.p95,
                'wall_s': series['wall_s'], 'duration_s': float(t[-1] - t[0])})
    return out


#: Sensitivity cases: (label, changes); the baseline is the scenario itself.
CORRELATION_S = (0.1, 0.5, 2.0)
MISALIGNMENT_DEG = (0.0, 0.5, 1.0, 2.0)


def misalignment_vector(deg: float) -> List[float]:
    """Rotation vector of magnitude ``deg`` [deg] along the old (0.6, -0.6, 0.5) direction."""
    d = np.array([0.6, -0.6, 0.5])
    return [float(x) for x in d / np.linalg.norm(d) * deg]


#: Hold-only runs: start on the target (body on the orbit axes, zero relative rate), run this
#: many orbits, hold statistics from HOLD_ONLY_FROM orbits on. The filter starts on the truth
#: with a converged covariance (1e-4 on phi: ~1 deg; (1e-4 rad/s)^2 on the rate): with the
#: acquisition P0 (10 on phi) its first updates throw the estimate tens of degrees off and the
#: law tumbles the satellite, which is the acquisition again, not the hold.
HOLD_ONLY_ORBITS = 3.0
HOLD_ONLY_FROM = 1.0
ON_TARGET = {'initial.q_orbit_body_wxyz': [1.0, 0.0, 0.0, 0.0], 'initial.q_orbit_body_xyzw': None,
             'initial.omega_body_eci_body_deg_s': None,
             'initial.omega_body_orbit_body_deg_s': [0.0, 0.0, 0.0],
             'estimator.p0_diag': [1e-4] * 3 + [1e-8] * 3 + [1e-14] * 3}


def hold_only(sc: Dict[str, Any], changes: Dict[str, Any]) -> Dict[str, Any]:
    """Hold accuracy started on the target: no acquisition, so no chaotic capture phase."""
    sc2 = with_changes(sc, {**changes, **ON_TARGET})
    loop = ClosedLoop(sc2, 2.0)
    period = 2.0 * math.pi / float(loop.world.orbit.state(0.0).orbit_rate)
    frames = int(HOLD_ONLY_ORBITS * period / loop.frame_s)
    series = ClosedLoop(sc2, frames * loop.frame_s).run()
    hs = metrics.hold_stats(series['t_s'], series['angle_deg'], HOLD_ONLY_FROM * period)
    est = metrics.hold_stats(series['t_s'], series['est_err_deg'], HOLD_ONLY_FROM * period)
    return {'rms_deg': hs.rms, 'median_deg': hs.median, 'p95_deg': hs.p95, 'max_deg': hs.max,
            'est_err_median_deg': est.median, 'wall_s': series['wall_s']}


def sensitivity(sc: Dict[str, Any], duration_s: Optional[float] = None,
                log=print) -> Dict[str, Any]:
    """Hold accuracy against random-torque correlation time and magnetometer misalignment.

    One parameter changes at a time from the scenario's values (same seed). Each case runs
    twice: from the scenario's initial state (capture, then hold from 4 orbits: the paper's
    numbers, but a single acquisition is chaotic) and started on the target
    (:func:`hold_only`: the hold alone). Returns a JSON-ready dict.
    """
    base_corr = float(sc['spacecraft']['disturbance']['random_period_s'])
    mis = sc['sensors']['magnetometer'].get('misalignment_deg', [0.0, 0.0, 0.0])
    base_mis = float(np.linalg.norm(mis))
    cases = []
    for tc in CORRELATION_S:
        cases.append(('random_period_s', tc, {'spacecraft.disturbance.random_period_s': tc}))
    for m in MISALIGNMENT_DEG:
        cases.append(('misalignment_deg', m,
                      {'sensors.magnetometer.misalignment_deg': misalignment_vector(m)}))
    out = {'scenario': sc.get('name'), 'seed': int(sc['seed']),
           'duration_s': float(duration_s or sc['duration_s']),
           'hold_only_orbits': HOLD_ONLY_ORBITS, 'hold_only_from_orbits': HOLD_ONLY_FROM,
           'baseline': {'random_period_s': base_corr, 'misalignment_deg': base_mis},
           'cases': []}
    done: Dict[tuple, Dict[str, Any]] = {}
    for what, value, changes in cases:
        key = (base_corr if what != 'random_period_s' else value,
               base_mis if what != 'misalignment_deg' else value)
        if key in done:            # the baseline appears in both sweeps: run it once
            res = done[key]
        else:
            res = summarize(ClosedLoop(with_changes(sc, changes), duration_s).run())
            res['hold_only'] = hold_only(sc, changes)
            done[key] = res
        h = res['hold_only']
        log(f'[sensitivity] {what} = {value:g}: from the paper state: capture '
            f'{_fmt(res["capture_orbits"])} orbits, last exit {_fmt(res["last_exit_orbits"])}, '
            f'hold RMS {res["hold_rms_deg"]:.2f} / median {res["hold_median_deg"]:.2f} / p95 '
            f'{res["hold_p95_deg"]:.2f} deg; on target: RMS {h["rms_deg"]:.2f} / median '
            f'{h["median_deg"]:.2f} / p95 {h["p95_deg"]:.2f} deg, estimation median '
            f'{h["est_err_median_deg"]:.2f} deg ({res["wall_s"] + h["wall_s"]:.0f} s wall)')
        out['cases'].append({'parameter': what, 'value': value, **res})
    return out


def _fmt(x: Optional[float]) -> str:
    return 'never' if x is None else f'{x:.2f}'


def _parse_set(items: Sequence[str]) -> Dict[str, Any]:
    import yaml
    out = {}
    for item in items:
        key, _, text = item.partition('=')
        out[key] = yaml.safe_load(text)
    return out


def mc_worker(run_dir: str) -> int:
    """One Monte Carlo run of the plain engine (``adcs montecarlo --engine plain``).

    Reads ``job.json`` and ``scenario.yaml`` of the prepared run directory, runs the closed
    loop, writes ``series.npz`` (per-frame truth and estimate error) and ``result.json`` with
    the metrics of :func:`adcs_nodes.tools.montecarlo.results.series_metrics` (the same
    result as a graph run), or ``failed.json``. Exit code 130 on SIGINT (nothing written).
    """
    from adcs_nodes.tools.montecarlo.files import RESULT_FILE, SERIES_FILE, write_json_atomic
    from adcs_nodes.tools.montecarlo.results import series_metrics
    from adcs_nodes.tools.montecarlo.runner import fail, result_head
    from adcs_nodes.tools.scenario import ScenarioError, load_scenario

    t0 = time.monotonic()
    with open(os.path.join(run_dir, 'job.json'), encoding='utf-8') as fh:
        job = json.load(fh)
    try:
        sc = load_scenario(os.path.join(run_dir, 'scenario.yaml'))
        loop = ClosedLoop(sc, job['duration_s'])
        s = loop.run()
    except KeyboardInterrupt:
        return 130
    except (ScenarioError, ValueError) as exc:
        return fail(run_dir, job, 2, str(exc), time.monotonic() - t0)
    tmp = os.path.join(run_dir, 'series.tmp.npz')
    np.savez_compressed(tmp, **{k: s[k] for k in ('t_s', 'q_orbit_body', 'angle_deg',
                                                  'est_err_deg', 'rate_err_deg_s', 'w_eci',
                                                  'w_orbit')})
    os.replace(tmp, os.path.join(run_dir, SERIES_FILE))
    m = series_metrics(s['t_s'], s['q_orbit_body'], s['w_eci'], s['w_orbit'],
                       job['capture_deg'], job.get('period_s') or s['period_s'])
    est = metrics.hold_stats(s['t_s'], s['est_err_deg'], 0.5 * s['period_s'])
    result = {**result_head(job), **m, 'engine': 'plain', 'bag': None,
              'est_err_median_deg': est.median if est.samples else None,
              'sim_time_s': float(s['t_s'][-1]), 'wall_time_s': time.monotonic() - t0,
              'frames': int(s['t_s'].size), 'missed_frames': 0, 'compose': False,
              'message': 'plain loop (sim_node.tools.closed_loop)'}
    write_json_atomic(os.path.join(run_dir, RESULT_FILE), result)
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Command line (see the module docstring)."""
    from adcs_nodes.tools.scenario import load_scenario

    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ['_mc_worker'] and len(argv) == 2:
        return mc_worker(argv[1])

    p = argparse.ArgumentParser(prog='python -m sim_node.tools.closed_loop',
                                description='Closed loop of a scenario without ROS.')
    p.add_argument('command', choices=('run', 'sensitivity'))
    p.add_argument('scenario')
    p.add_argument('--duration', type=float)
    p.add_argument('--set', action='append', default=[], metavar='KEY=VALUE',
                   help='change a scenario key (dotted path), e.g. seed=3')
    p.add_argument('--ideal', action='store_true', help='controllers get the true state')
    p.add_argument('--out', help='JSON file for the results')
    args = p.parse_args(argv)
    sc = with_changes(load_scenario(args.scenario), _parse_set(args.set))
    if args.command == 'run':
        res = summarize(ClosedLoop(sc, args.duration,
                                   'truth' if args.ideal else 'paper').run(progress=True))
    else:
        res = sensitivity(sc, args.duration, log=lambda s: print(s, flush=True))
    text = json.dumps(res, indent=1, default=float)
    if args.out:
        with open(args.out, 'w', encoding='utf-8') as fh:
            fh.write(text + '\n')
    print(text)
    return 0


def one_blas_thread() -> None:
    """One BLAS/OpenMP thread in this process and its children (numpy is already loaded here,
    so the environment alone would come too late: ``threadpoolctl`` limits the loaded
    libraries). The models make only tiny LAPACK calls; extra threads cost CPU, same bits."""
    for key in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
        os.environ[key] = '1'
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - pinned in ros2_ws/requirements.txt
        return
    threadpool_limits(limits=1)


if __name__ == '__main__':
    # a Monte Carlo run started under ``--dask-local`` inherits an ignored SIGINT (see
    # adcs_nodes.tools.montecarlo.backends.sigint_ignored): the supervisor's SIGINT must stop it
    signal.signal(signal.SIGINT, signal.default_int_handler)
    one_blas_thread()
    raise SystemExit(main())
