"""Paper 001's metrics from a bag of the node graph (``adcs run scenarios/paper001_mpi.yaml
--record BAG``), with the plain loop's definitions (:func:`sim_node.tools.paper001_loop.metrics`).

The bag's truth (``/sim/state``), target (``/adcs/attitude_target``), command
(``/adcs/actuator_command``), wheels (``/sim/wheels``), appendages (``/sim/appendages``) and
estimate (``/adcs/attitude_estimate``) are joined on the header stamp (sim time) into the
series :func:`paper001_loop.metrics` reads.

Usage: ``python -m sim_node.tools.paper001_bag BAG [--epoch 2026-01-01T00:00:00Z] [--plots DIR]``
(``--plots``: attitude and rate errors, wheel torque and momentum, modal amplitudes against
time, like the paper's figures).
"""
from __future__ import annotations

import argparse
import json
import math
from datetime import datetime

import numpy as np

from adcs_nodes.core import attitude as att
from adcs_nodes.core.control import mpi
from adcs_nodes.tools.bag import header_stamp_ns, read_messages
from sim_node.tools.paper001_loop import metrics


def _q(msg, name: str) -> np.ndarray:
    q = getattr(msg, name)
    return np.array([q.x, q.y, q.z, q.w])


def _v(msg, name: str) -> np.ndarray:
    v = getattr(msg, name)
    return np.array([v.x, v.y, v.z])


def series(bag: str, epoch: str = '2026-01-01T00:00:00Z') -> dict:
    """The plain loop's record (``t, e, e_d, de, de_d, tau_cmd, tau, h, eta, est_err_deg, sat,
    w_bo``) from a bag, one row per frame with every topic present."""
    epoch_ns = int(round(datetime.fromisoformat(epoch.replace('Z', '+00:00')).timestamp()
                         * 1e9))
    topics = {'/sim/state': {}, '/adcs/attitude_target': {}, '/adcs/actuator_command': {},
              '/sim/wheels': {}, '/sim/appendages': {}, '/adcs/attitude_estimate': {}}
    for topic, _, msg in read_messages(bag, list(topics)):
        topics[topic][header_stamp_ns(msg) - epoch_ns] = msg
    state = topics['/sim/state']
    common = sorted(set(state).intersection(*(set(v) for k, v in topics.items()
                                              if k != '/sim/appendages' and v)))
    rec = {k: [] for k in ('t', 'e', 'e_d', 'de', 'de_d', 'tau_cmd', 'tau', 'h', 'eta',
                           'est_err_deg', 'sat', 'w_bo')}
    # the wheel torque applied over [t, t + dt] is published with the state at t + dt
    wheels = topics['/sim/wheels']
    keys = sorted(wheels)
    nxt = dict(zip(keys[:-1], keys[1:]))
    for t in common:
        s, tg = state[t], topics['/adcs/attitude_target'][t]
        q_ob, w_bo = _q(s, 'q_orbit_body'), _v(s, 'omega_body_orbit_body')
        e = mpi.lvlh_euler312_of(q_ob)
        e_d = mpi.lvlh_euler312_of(_q(tg, 'q_ref_body'))
        rec['t'].append(t / 1e9)
        rec['e'].append(e)
        rec['e_d'].append(e_d)
        rec['de'].append(mpi.euler312_rates_from_body_rate(e, w_bo))
        rec['de_d'].append(mpi.euler312_rates_from_body_rate(e_d, _v(tg, 'omega_body_ref_body')))
        rec['tau_cmd'].append(list(topics['/adcs/actuator_command'][t].wheel_torque))
        rec['tau'].append(list(wheels[nxt.get(t, t)].torque))
        rec['h'].append(list(wheels[t].momentum))
        app = topics['/sim/appendages'].get(t)
        rec['eta'].append(list(app.eta) if app is not None else [])
        rec['est_err_deg'].append(math.degrees(att.angle_between(
            _q(topics['/adcs/attitude_estimate'][t], 'q_orbit_body'), q_ob)))
        rec['sat'].append(False)    # momentum limit: counted in the dynamics' /diagnostics
        rec['w_bo'].append(w_bo)
    return {k: np.array(v) for k, v in rec.items()}


def plots(r: dict, out_dir: str) -> list:
    """PNG figures like the paper's (Figs. 4-9): attitude error, rate error, wheel torque and
    momentum, modal amplitudes, against time. Returns the file paths."""
    import os

    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    os.makedirs(out_dir, exist_ok=True)
    t = r['t']
    err = (np.degrees(r['e'] - r['e_d']) + 180.0) % 360.0 - 180.0
    panels = [
        ('attitude_error.png', err, 'attitude error, 3-1-2 Euler [deg]', ('phi', 'theta', 'psi')),
        ('rate_error.png', np.degrees(r['de'] - r['de_d']), 'Euler-rate error [deg/s]',
         ('phi', 'theta', 'psi')),
        ('wheel_torque.png', r['tau'], 'applied wheel torque [N m]', ('x', 'y', 'z')),
        ('wheel_momentum.png', r['h'], 'wheel momentum [N m s]', ('x', 'y', 'z')),
    ]
    if r['eta'].size:
        panels.append(('modal_amplitudes.png', r['eta'], 'modal coordinates eta', None))
    paths = []
    for name, y, label, legend in panels:
        fig, ax = plt.subplots(figsize=(9, 3.5))
        ax.plot(t, y, lw=0.6)
        ax.set_xlabel('t [s]')
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        if legend:
            ax.legend(legend, loc='upper right', fontsize=8)
        if name == 'attitude_error.png':    # the paper's figures zoom on the small errors
            ax.set_ylim(-0.3, 0.3)
        fig.tight_layout()
        path = os.path.join(out_dir, name)
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('bag')
    ap.add_argument('--epoch', default='2026-01-01T00:00:00Z')
    ap.add_argument('--save', default='', help='also save the series (.npz)')
    ap.add_argument('--plots', default='', metavar='DIR', help='write the paper-like figures')
    a = ap.parse_args(argv)
    r = series(a.bag, a.epoch)
    if a.plots:
        plots(r, a.plots)
    m = metrics(r)
    eta = r['eta']
    if eta.size:
        m['max_abs_eta_per_mode'] = np.abs(eta).max(axis=0).tolist()
        late = r['t'] >= 4200.0
        m['eta_3sigma_4200_5000s'] = (3 * eta[late].std(axis=0)).tolist() if late.any() else []
    m['frames'] = int(len(r['t']))
    m.pop('momentum_limited_frames', None)       # not in the series: the node counts them
    for _, _, msg in read_messages(a.bag, ['/diagnostics']):
        for st in msg.status:
            if st.name == 'dynamics':
                for kv in st.values:
                    if kv.key.endswith('limited_frames'):
                        m[f'dynamics_{kv.key}'] = int(kv.value)
    if a.save:
        np.savez_compressed(a.save, **r)
    print(json.dumps(m, indent=1))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
