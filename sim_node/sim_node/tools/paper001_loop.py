"""Plain-numpy closed loop of paper 001 (no ROS): flexible spacecraft, wheels, disturbances,
star tracker + gyro, MEKF, MPI controller, the paper's 5000 s profile.

A first look at the numbers before the node graph runs the same scenario; the metrics follow
the digest's definitions (true minus desired 3-1-2 Euler angles and Euler rates w.r.t. LVLH;
stabilisation windows 500-1000 s and 4200-5000 s, tracking 1100-3500 s).

Usage: ``python -m sim_node.tools.paper001_loop [--duration S] [--wings one|two] ...``
"""
from __future__ import annotations

import argparse
import json
import math
import time
from datetime import datetime, timezone

import numpy as np

from adcs_nodes.core import attitude as att
from adcs_nodes.core.control import ControlInputs, Estimate, Target
from adcs_nodes.core.control import mpi
from adcs_nodes.core.estimation.algorithms import EstimatorInputs
from adcs_nodes.core.estimation.mekf import MEKF
from adcs_nodes.core.estimation.onboard import OnboardState
from adcs_nodes.core.guidance_profiles import paper001_initial_state, paper001_profile
from adcs_nodes.core.orbit import CircularOrbit
from sim_node.models.actuators import WheelCluster, WheelMomentumError
from sim_node.models.disturbances import paper001_disturbances
from sim_node.models.flexible import FlexibleSpacecraft, PAPER001_INERTIA, paper001_modes
from sim_node.models.sensors import GYRO_DRIFT_WALK_RAD_S_SQRT_S, Gyro, StarTracker

#: Paper 001 eq. (31): the controller's inertia (5 % off) [kg m^2].
INERTIA_31 = np.array([[1260.0, -840.0, -9.5], [-840.0, 2375.0, -26.2], [-9.5, -26.2, 2660.0]])


def run(duration: float = 5000.0, wings: str = 'two', literal: bool = False,
        substeps: int = 5, seed: int = 1, estimator: str = 'mekf', unloading: bool = True,
        reference_time: str = 't0', gyro_noise: float = 1e-6, damping: float = 0.005,
        hold_horizon_s: float = 0.0) -> dict:
    """Run the loop; returns time series (numpy arrays) keyed by name."""
    orbit = CircularOrbit(600e3, math.radians(97.79), math.radians(90.0),
                          epoch=datetime(2026, 3, 21, tzinfo=timezone.utc))
    w0 = orbit.mean_motion
    f, freq = paper001_modes(wings)
    wheels = WheelCluster(np.eye(3), 1.0, 55.0, 0.1)
    sc = FlexibleSpacecraft(PAPER001_INERTIA, f, freq, damping, wheels,
                            paper001_disturbances(w0, seed, unloading=unloading),
                            wheel_error=WheelMomentumError(0.01 / 3.0, 0.2, 3, seed))
    q_ob0, w_bo0 = paper001_initial_state()
    s0 = orbit.state(0.0)
    x = sc.pack(att.multiply(s0.q_eci_orbit, q_ob0),
                w_bo0 + att.to_matrix(q_ob0).T @ [0.0, w0, 0.0])
    ctrl = mpi.MPIController(INERTIA_31, np.eye(3), [1.0] * 3, [55.0] * 3, 0.2,
                             literal_model=literal, reference_time=reference_time,
                             hold_horizon_s=hold_horizon_s)
    st = StarTracker(seed=seed + 10)
    gyro = Gyro(gyro_noise, 0.0, GYRO_DRIFT_WALK_RAD_S_SQRT_S, seed=seed + 20)
    filt = MEKF(gyro_noise_std_rad_s=max(gyro_noise, 1e-9))
    profile = paper001_profile()
    n = int(round(duration / 0.2))
    rec = {k: [] for k in ('t', 'e', 'e_d', 'de', 'de_d', 'tau_cmd', 'tau', 'h', 'eta',
                           'est_err_deg', 'sat', 'w_bo')}
    for k in range(n):
        t = k * 0.2
        orb = orbit.state(t)
        q_eb, w_bi = x[0:4], x[4:7]
        q_ob = att.multiply(att.conjugate(orb.q_eci_orbit), q_eb)
        w_bo = w_bi - att.to_matrix(q_ob).T @ [0.0, w0, 0.0]
        if estimator == 'mekf':
            ref = OnboardState(orb.q_eci_orbit, np.zeros(3), w0, orb.argument_of_latitude,
                               orb.r_eci)
            dt = 0.2 if k else 0.0
            inputs = EstimatorInputs(ref, gyro_rate_body=gyro.measure(w_bi, dt),
                                     q_eci_body_meas=st.measure(q_eb))
            out = filt.step(inputs, t, dt)
            e6 = out.estimate
            est = Estimate(e6.q_orbit_body, e6.omega_body_eci_body, w0,
                           q_eci_body=filt.q.copy())
        else:
            est = Estimate(q_ob, w_bi, w0, q_eci_body=q_eb)
        pt = profile.profile_at(t)
        tgt = Target(pt.q_ref_body, pt.omega_body_ref_body, pt.omega_dot_body_ref_body,
                     pt.frame, pt.time_to_go_s)
        h_w = sc.unpack(x)['h_wheels']
        cmd = ctrl.update(ControlInputs(est, tgt, wheel_momentum_Nms=h_w), t, 0.2)
        e = mpi.lvlh_euler312_of(q_ob)
        e_d = mpi.lvlh_euler312_of(pt.q_ref_body)
        rec['t'].append(t)
        rec['e'].append(e)
        rec['e_d'].append(e_d)
        rec['de'].append(mpi.euler312_rates_from_body_rate(e, w_bo))
        rec['de_d'].append(mpi.euler312_rates_from_body_rate(e_d, pt.omega_body_ref_body))
        rec['tau_cmd'].append(cmd.wheel_torque)
        rec['h'].append(h_w)
        rec['eta'].append(x[7:7 + sc.m].copy())
        rec['est_err_deg'].append(math.degrees(att.angle_between(est.q_orbit_body, q_ob)))
        rec['w_bo'].append(w_bo)
        sat = False
        for i in range(4):
            x, applied = sc.step(x, t + 0.05 * i, 0.05, cmd.wheel_torque, substeps=substeps)
            sat = sat or bool(np.any(applied['momentum_limited']))
        rec['tau'].append(applied['wheel_torque'])
        rec['sat'].append(sat)
    return {k: np.array(v) for k, v in rec.items()}


def _wrap_deg(a: np.ndarray) -> np.ndarray:
    return (a + 180.0) % 360.0 - 180.0


def metrics(r: dict) -> dict:
    """The paper's numbers from a run (digest sections 5 and 8)."""
    t = r['t']
    err = _wrap_deg(np.degrees(r['e'] - r['e_d']))
    derr = np.degrees(r['de'] - r['de_d'])

    def window(a, b):
        return (t >= a) & (t < b)

    out = {}
    stab = window(500, 1000) | window(4200, 5000)
    trk = window(1100, 3500)
    if stab.any():
        out['stab_angle_3sigma_deg'] = (3 * err[stab].std(axis=0)).tolist()
        out['stab_angle_max_deg'] = np.abs(err[stab]).max(axis=0).tolist()
        out['stab_rate_3sigma_deg_s'] = (3 * derr[stab].std(axis=0)).tolist()
    if trk.any():
        out['track_angle_3sigma_deg'] = (3 * err[trk].std(axis=0)).tolist()
        out['track_angle_max_deg'] = np.abs(err[trk]).max(axis=0).tolist()
        out['track_rate_3sigma_deg_s'] = (3 * derr[trk].std(axis=0)).tolist()
    for t_end, until in ((200.0, 1000.0), (3700.0, 5000.0)):
        i = int(np.searchsorted(t, t_end))
        if i >= len(t):
            continue
        out[f'error_at_{int(t_end)}s_deg'] = err[i].tolist()
        w = window(t_end, until)
        bad = np.flatnonzero(np.any(np.abs(err[w]) >= 0.1, axis=1))
        tw = t[w]
        out[f'back_within_0.1deg_after_{int(t_end)}s_s'] = (
            float(tw[bad[-1]] - t_end + 0.2) if len(bad) and bad[-1] + 1 < len(tw)
            else (0.0 if not len(bad) else None))
        out[f'overshoot_after_{int(t_end)}s_deg'] = np.abs(err[w]).max(axis=0).tolist()
    out['max_abs_h_Nms'] = np.abs(r['h']).max(axis=0).tolist()
    out['max_abs_wheel_torque_Nm'] = np.abs(r['tau']).max(axis=0).tolist()
    out['torque_at_limit_fraction'] = float(np.mean(np.any(np.abs(r['tau_cmd']) > 0.999,
                                                           axis=1)))
    out['momentum_limited_frames'] = int(np.sum(r['sat']))
    out['max_abs_eta'] = float(np.abs(r['eta']).max())
    out['estimate_error_median_deg'] = float(np.median(r['est_err_deg']))
    sat_t = t[np.any(np.abs(r['tau_cmd']) > 0.999, axis=1)]
    out['torque_limit_episodes_start_s'] = [float(sat_t[0])] + [
        float(b) for a, b in zip(sat_t, sat_t[1:]) if b - a > 1.0] if len(sat_t) else []
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--duration', type=float, default=5000.0)
    ap.add_argument('--wings', choices=('one', 'two'), default='two')
    ap.add_argument('--literal', action='store_true')
    ap.add_argument('--substeps', type=int, default=5)
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--estimator', choices=('mekf', 'truth'), default='mekf')
    ap.add_argument('--no-unloading', action='store_true')
    ap.add_argument('--reference-time', choices=('t0', 't0_plus_tau'), default='t0')
    ap.add_argument('--damping', type=float, default=0.005)
    ap.add_argument('--hold-horizon', type=float, default=0.0)
    ap.add_argument('--save', default='')
    a = ap.parse_args(argv)
    t0, c0 = time.time(), time.process_time()
    r = run(a.duration, a.wings, a.literal, a.substeps, a.seed, a.estimator,
            not a.no_unloading, a.reference_time, damping=a.damping,
            hold_horizon_s=a.hold_horizon)
    m = metrics(r)
    m['wall_s'] = time.time() - t0
    m['cpu_s'] = time.process_time() - c0
    m['args'] = vars(a)
    if a.save:
        np.savez_compressed(a.save, **r)
    print(json.dumps(m, indent=1))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
