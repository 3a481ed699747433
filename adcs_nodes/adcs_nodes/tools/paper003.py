"""Paper 003 reproduction in a plain numpy loop (no ROS): fuzzy vs reference eigenaxis slew.

Scenario (digest ``papers/fuzzy-eigenaxis-slew.md`` section 9): principal inertias (250, 200,
180) kg m^2, from psi 34, theta -7.5, gamma 16.5 deg (3-2-1, eq. (1) with row 3 corrected) to
the reference axes, at rest at both ends, ``|M_i| <= 1 N m``. Plant: rigid body (13) with a
quaternion, RK4 at ``dt_int``, controller at ``dt_ctrl`` with the torque held (zero-order hold).

Metrics (the paper defines neither; ASSUMPTIONS of the digest, section 10):

* settling time: first time after which ``phi`` stays within ``band`` x ``phi0`` (5 %) until
  the end of the run;
* energy: ``E = int_0^T_s sum_i |M_i| dt`` [N m s], up to the settling time (also reported up
  to the end of the run).

``python -m adcs_nodes.tools.paper003 [OUT_DIR]`` prints the table (and writes the PNG
equivalents of the paper's Figs. 6-9 to ``OUT_DIR``).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Optional

import numpy as np

from adcs_nodes.core import attitude
from adcs_nodes.core.control import ControlInputs, Estimate, Target
from adcs_nodes.core.control.eigenaxis import dcm_euler_321

INERTIA = (250.0, 200.0, 180.0)
EULER0_DEG = (34.0, -7.5, 16.5)          # psi, theta, gamma
PAPER = dict(settling_s=25.73, energy_Nms=42.91, speed_ratio=1.5, energy_ratio=1.37)
#: Tolerances of the PASS/FAIL table, fixed before any tuning (relative).
TOLERANCE = dict(settling_s=0.15, energy_Nms=0.20, speed_ratio=0.20, energy_ratio=0.20)


@dataclass
class Run:
    """One simulated slew."""

    t: np.ndarray          # (N,) [s]
    phi: np.ndarray        # (N,) eigenangle to the target [rad]
    omega: np.ndarray      # (N, 3) body rate [rad/s]
    torque: np.ndarray     # (N, 3) torque held over [t, t + dt_ctrl) [N m]
    settling_s: float      # nan if not settled
    energy_Nms: float      # up to settling (nan if not settled)
    energy_total_Nms: float
    max_abs_torque_Nm: float
    overshoot_deg: float   # largest phi after the first minimum below the band [deg]
    seconds_per_call: float  # CPU time of controller.update per call [s]
    e_phi: np.ndarray      # (N, 3) eigenaxis the controller used (nan if it reports none)
    q: np.ndarray          # (N, 4) q_eci_body, scalar last


def initial_quaternion(euler_deg=EULER0_DEG) -> np.ndarray:
    """``q_eci_body`` of the paper's Euler-Krylov angles (psi, theta, gamma) [deg]."""
    psi, theta, gamma = (math.radians(a) for a in euler_deg)
    return attitude.from_matrix(dcm_euler_321(psi, theta, gamma).T)


def _deriv(q: np.ndarray, w: np.ndarray, J: np.ndarray, Jinv: np.ndarray,
           m: np.ndarray) -> tuple:
    x, y, z, s = q
    a, b, c = w
    dq = 0.5 * np.array([s * a + y * c - z * b, s * b + z * a - x * c,
                         s * c + x * b - y * a, -x * a - y * b - z * c])
    dw = Jinv @ (m - np.cross(w, J @ w))                                              # (13)
    return dq, dw


def simulate(controller, inertia=INERTIA, euler0_deg=EULER0_DEG, t_end: float = 80.0,
             dt_ctrl: float = 0.1, dt_int: float = 0.01, band: float = 0.05,
             q_target_eci: Optional[np.ndarray] = None) -> Run:
    """Slew from ``euler0_deg`` to ``q_target_eci`` (default identity) with ``controller``.

    ``controller`` has the core interface (``reset``, ``update(ControlInputs, t, dt)``); it
    is fed the true state (inertial attitude and rate, target in frame ``'eci'``).
    """
    J = np.diag(np.asarray(inertia, dtype=float)) if np.ndim(inertia) == 1 else \
        np.asarray(inertia, dtype=float)
    Jinv = np.linalg.inv(J)
    q = initial_quaternion(euler0_deg)
    w = np.zeros(3)
    q_t = attitude.identity() if q_target_eci is None else attitude.normalize(q_target_eci)
    target = Target(q_ref_body=q_t, frame='eci')
    n_sub = max(1, int(round(dt_ctrl / dt_int)))
    h = dt_ctrl / n_sub
    n = int(round(t_end / dt_ctrl))
    ts, phis, ws, ms, axes, qs = [], [], [], [], [], []
    controller.reset()
    t_ctrl = 0.0
    for k in range(n + 1):
        t = k * dt_ctrl
        est = Estimate(q_orbit_body=q, omega_body_eci_body=w, omega0=0.0, q_eci_body=q)
        t0 = time.process_time()       # CPU time: not inflated by other processes
        cmd = controller.update(ControlInputs(estimate=est, target=target), t, dt_ctrl)
        t_ctrl += time.process_time() - t0
        m = np.asarray(cmd.torque_body, dtype=float)
        ts.append(t)
        phis.append(attitude.angle_between(q, q_t))
        ws.append(w.copy())
        qs.append(q.copy())
        ms.append(m.copy())
        axes.append(np.asarray(cmd.info.get('e_phi', np.full(3, np.nan)), dtype=float))
        if k == n:
            break
        for _ in range(n_sub):                                      # RK4, torque held
            k1 = _deriv(q, w, J, Jinv, m)
            k2 = _deriv(q + 0.5 * h * k1[0], w + 0.5 * h * k1[1], J, Jinv, m)
            k3 = _deriv(q + 0.5 * h * k2[0], w + 0.5 * h * k2[1], J, Jinv, m)
            k4 = _deriv(q + h * k3[0], w + h * k3[1], J, Jinv, m)
            q = q + h / 6.0 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            w = w + h / 6.0 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
            q = q / np.linalg.norm(q)
    t_arr, phi = np.array(ts), np.array(phis)
    torque = np.array(ms)
    settle = settling_time(t_arr, phi, band * phi[0])
    sum_abs = np.abs(torque).sum(axis=1)
    energy_total = float(np.sum(sum_abs[:-1]) * dt_ctrl)
    energy = float('nan') if math.isnan(settle) else \
        float(np.sum(sum_abs[:-1][t_arr[:-1] < settle - 1e-9]) * dt_ctrl)
    inside = np.nonzero(phi <= band * phi[0])[0]
    overshoot = float(np.degrees(phi[inside[0]:].max())) if inside.size else float('nan')
    return Run(t_arr, phi, np.array(ws), torque, settle, energy, energy_total,
               float(np.abs(torque).max()), overshoot, t_ctrl / (n + 1), np.array(axes),
               np.array(qs))


def settling_time(t: np.ndarray, phi: np.ndarray, threshold: float) -> float:
    """First sample time after which ``phi <= threshold`` for the rest of the run (nan if the
    last sample is outside)."""
    outside = np.nonzero(phi > threshold)[0]
    if outside.size == 0:
        return float(t[0])
    if outside[-1] == len(t) - 1:
        return float('nan')
    return float(t[outside[-1] + 1])


def make_fuzzy(**kw):
    """The fuzzy controller with the paper's inertia and limit (keywords override)."""
    from adcs_nodes.core.control.fuzzy import FuzzyEigenaxisController
    return FuzzyEigenaxisController(np.diag(INERTIA), 1.0, **kw)


def make_reference(**kw):
    """The reference eigenaxis slew with the paper's inertia and limit."""
    from adcs_nodes.core.control.reference_slew import ReferenceSlewController
    return ReferenceSlewController(np.diag(INERTIA), 1.0, **kw)


def reproduce(t_end: float = 80.0) -> dict:
    """Run the fuzzy controller (default set with both Table 1 readings, the smooth set, no
    compensation) and the reference; return the results table (rows: the default set).

    Returns
    -------
    dict
        ``runs``: name -> :class:`Run`; ``rows``: list of (quantity, ours, paper, tolerance,
        PASS/FAIL) for the default (reversed) reading.
    """
    from adcs_nodes.core.control.fuzzy import SMOOTH
    runs = {
        'fuzzy (Table 1 reversed)': simulate(make_fuzzy(table1_rows='reversed'), t_end=t_end),
        'fuzzy (Table 1 as printed)': simulate(make_fuzzy(table1_rows='as_printed'),
                                               t_end=t_end),
        'fuzzy (smooth set)': simulate(make_fuzzy(**SMOOTH), t_end=t_end),
        'fuzzy (no compensation)': simulate(make_fuzzy(compensation=False), t_end=t_end),
        'reference slew': simulate(make_reference(), t_end=t_end),
    }
    f, r = runs['fuzzy (Table 1 reversed)'], runs['reference slew']
    ours = dict(settling_s=f.settling_s, energy_Nms=f.energy_Nms,
                speed_ratio=r.settling_s / f.settling_s,
                energy_ratio=r.energy_Nms / f.energy_Nms)
    rows = []
    for key, paper in PAPER.items():
        v = ours[key]
        ok = math.isfinite(v) and abs(v - paper) <= TOLERANCE[key] * paper
        rows.append((key, v, paper, TOLERANCE[key], 'PASS' if ok else 'FAIL'))
    return dict(runs=runs, rows=rows)


def format_table(result: dict) -> str:
    """Plain-text tables of :func:`reproduce`."""
    lines = ['paper 003 fuzzy eigenaxis slew (plain numpy loop; metrics: 5 % band of phi0, '
             'E = int sum|M_i| dt to settling)',
             '(E_run: to the end of the run; phi_max_in: largest phi after first entering the '
             'band [deg])',
             f'{"run":28s} {"T_s [s]":>8s} {"E [N m s]":>10s} {"E_run":>8s} {"max|M_i|":>9s} '
             f'{"phi_max_in":>10s} {"CPU us/call":>11s}']
    for name, run in result['runs'].items():
        lines.append(f'{name:28s} {run.settling_s:8.2f} {run.energy_Nms:10.2f} '
                     f'{run.energy_total_Nms:8.2f} {run.max_abs_torque_Nm:9.3f} '
                     f'{run.overshoot_deg:10.2f} {1e6 * run.seconds_per_call:11.1f}')
    lines.append(f'{"quantity":14s} {"ours":>8s} {"paper":>8s} {"tol":>6s} verdict')
    for key, v, paper, tol, verdict in result['rows']:
        lines.append(f'{key:14s} {v:8.2f} {paper:8.2f} {100 * tol:5.0f}% {verdict}')
    return '\n'.join(lines)


def write_figures(result: dict, out_dir: str) -> list:
    """PNG equivalents of the paper's Figs. 6-9 for every run of :func:`reproduce`.

    Fig. 6: eigenangle phi(t); Fig. 7: Euler-Krylov angles psi, theta, gamma (t); Fig. 8: body
    rates omega_i(t); Fig. 9: torques M_i(t). Returns the written paths.
    """
    import os
    from matplotlib.figure import Figure
    os.makedirs(out_dir, exist_ok=True)
    runs = result['runs']
    panels = [
        ('fig6_phi.png', 'eigenangle phi [deg] (Fig. 6)',
         lambda r: [('phi', np.degrees(r.phi))]),
        ('fig7_euler.png', 'Euler-Krylov angles [deg] (Fig. 7)',
         lambda r: list(zip(('gamma (x)', 'theta (y)', 'psi (z)'), np.degrees(
             np.array([attitude.to_euler_321(q) for q in r.q])).T))),
        ('fig8_rates.png', 'body rates omega_i [deg/s] (Fig. 8)',
         lambda r: list(zip(('omega_1', 'omega_2', 'omega_3'), np.degrees(r.omega).T))),
        ('fig9_torque.png', 'torques M_i [N m] (Fig. 9)',
         lambda r: list(zip(('M_1', 'M_2', 'M_3'), r.torque.T))),
    ]
    paths = []
    for name, title, series in panels:
        fig = Figure(figsize=(9, 2.6 * len(runs)))
        for k, (label, run) in enumerate(runs.items()):
            ax = fig.add_subplot(len(runs), 1, k + 1)
            for lab, y in series(run):
                ax.plot(run.t, y, label=lab)
            if name.startswith('fig6'):
                ax.axhline(np.degrees(0.05 * run.phi[0]), color='k', lw=0.5, ls='--',
                           label='5 % band')
            if math.isfinite(run.settling_s):
                ax.axvline(run.settling_s, color='r', lw=0.5, ls=':', label='settling')
            ax.set_title(f'{label}: {title}', fontsize=9)
            ax.grid(True, lw=0.3)
            ax.legend(fontsize=7, loc='upper right')
        fig.axes[-1].set_xlabel('t [s]')
        fig.tight_layout()
        path = os.path.join(out_dir, name)
        fig.savefig(path, dpi=90)
        paths.append(path)
    return paths


if __name__ == '__main__':
    import sys
    res = reproduce()
    print(format_table(res))
    if len(sys.argv) > 1:
        for path in write_figures(res, sys.argv[1]):
            print(path)
