"""Reaction wheels and paper 001's flexible spacecraft on the FrameLoop (the plain engine: no
ROS, no process): a short MPI maneuver reaches and holds its target, live switching between
mpi, magnetic and bdot on one spacecraft, and the wings' modes excited by the maneuver.

These were launched-graph tests (``tests/integration/test_wheels_graph.py`` and
``test_flexible_graph.py``); the assertions are theirs, with the same numbers and tolerances.
That the graph gives the FrameLoop's series is ``tests/graph/test_engine_parity.py``
(paper001_mpi as a graph); the graph versions run in ``make test-long``.

Truth for the modes: the modal frequencies are the paper's (Sec. 6); the modes start at rest
(digest section 6) and the first seconds of the maneuver (torque at the 1 N m limit) must
excite them, and they stay small.
"""
import copy

import numpy as np

from adcs_nodes.core import attitude as att
from frameloop_run import by_t, q, raw, run, validated

Q_LVLH = [1.0, 0.0, 0.0, 0.0]          # body on the LVLH axes (180 deg about x of the orbit frame)
PAPER_HZ = [0.16, 0.85, 0.96, 2.10, 2.55]


def _paper001(**changes):
    sc = raw('paper001_mpi')
    sc['initial'] = {'q_orbit_body_xyzw': Q_LVLH, 'omega_body_orbit_body_deg_s': [0.0] * 3}
    sc['estimator']['initial_q_orbit_body_xyzw'] = Q_LVLH
    sc['timing']['timeout_s'] = 2.0
    sc.update(changes)
    return sc


def test_short_mpi_maneuver_with_wheels_reaches_and_holds_the_target(tmp_path):
    sc = _paper001()
    sc['guidance']['euler312_profile'] = [
        {'type': 'maneuver', 'start_s': 0.0, 'end_s': 20.0, 'euler_deg': [2.0, -2.0, 2.0]},
        {'type': 'hold', 'start_s': 20.0, 'end_s': 60.0, 'euler_deg': [2.0, -2.0, 2.0]}]
    out, _ = run(validated(tmp_path, sc, 'mpi'), 60.0)
    cmds = by_t(out['adcs/actuator_command'])
    torques = np.array([list(m.wheel_torque) for m in cmds.values()])
    assert torques.shape[1] == 3 and np.max(np.abs(torques)) <= 1.0 + 1e-12
    assert {m.source for t, m in cmds.items() if t > 0} == {'mpi'}
    truth, target = by_t(out['sim/state']), by_t(out['adcs/attitude_target'])
    start = np.degrees(att.angle_between(q(truth[0.0].q_orbit_body),
                                         q(target[0.0].q_ref_body)))
    end = [np.degrees(att.angle_between(q(truth[t].q_orbit_body), q(target[t].q_ref_body)))
           for t in sorted(target) if t >= 50.0]
    assert start > 3.0                       # the maneuver is about 3.4 deg
    assert max(end) < 0.1, end               # reached and held (paper: within 0.1 deg)
    wheels = by_t(out['sensors/wheels'])
    assert len(wheels) == 301 and list(wheels[0.0].name) == ['wheel_x', 'wheel_y', 'wheel_z']


def test_switch_between_mpi_magnetic_and_bdot_on_one_spacecraft(tmp_path):
    sc = _paper001(duration_s=40.0)
    sc['timing'] = {'frame_s': 1.0, 'substeps': 10, 'timeout_s': 2.0}
    for key in ('star_tracker', 'gyro', 'wheel_tachometer'):
        sc['sensors'][key]['period_s'] = 1.0
    sc['estimator']['period_s'] = 1.0
    sc['guidance'] = {'period_s': 1.0}              # hold the orbital frame
    sc['spacecraft']['magnetorquer'] = {'max_dipole_Am2': [40.0, 40.0, 40.0]}
    sc['sensors']['magnetometer'] = {'period_s': 1.0}
    sc['controllers'] = {'period_s': 1.0, 'mpi': copy.deepcopy(sc['controllers']['mpi']),
                         'magnetic': {}, 'bdot': {}}
    sc['manager'] = {'safe': 'bdot', 'initial': 'mpi',
                     'schedule': [{'t_s': 10.0, 'controller': 'magnetic'},
                                  {'t_s': 20.0, 'controller': 'bdot'},
                                  {'t_s': 30.0, 'controller': 'mpi'}]}
    out, _ = run(validated(tmp_path, sc, 'switch'), 40.0)
    cmds = by_t(out['adcs/actuator_command'])
    src = {t: m.source for t, m in cmds.items()}
    assert src[10.0] == src[20.0] == src[30.0] == 'zero'     # one zero frame per switch
    assert all(src[float(t)] == 'mpi' for t in range(1, 10))
    assert all(src[float(t)] == 'magnetic' for t in range(11, 20))
    assert all(src[float(t)] == 'bdot' for t in range(21, 30))
    assert all(src[float(t)] == 'mpi' for t in range(31, 41))
    for t in range(11, 20):      # magnetic commands a dipole and no wheel torque
        assert not np.any(cmds[float(t)].wheel_torque)


def test_paper001_records_nonzero_modal_motion(tmp_path):
    """The dynamics integrate the wings' modes with the body and the wheels (the two-wing
    robustness case: 10 modes)."""
    out, _ = run(validated(tmp_path, raw('paper001_mpi_two_wings')), 20.0)
    app = by_t(out['sim/appendages'])
    assert len(app) == 101 and sorted(app)[-1] == 20.0            # every 0.2 s frame
    first = app[0.0]
    np.testing.assert_allclose(list(first.frequency_hz), PAPER_HZ * 2)   # two wings
    assert not any(first.eta) and not any(first.eta_dot)         # at rest at t = 0
    eta = np.array([list(m.eta) for _, m in sorted(app.items())])
    eta_dot = np.array([list(m.eta_dot) for _, m in sorted(app.items())])
    assert eta.shape == (101, 10) and np.all(np.isfinite(eta))
    assert np.max(np.abs(eta)) > 1e-4                               # the maneuver excites them
    assert np.max(np.abs(eta_dot)) > 1e-5
    assert np.max(np.abs(eta)) < 1.0                                # and they stay small
    cmds = [list(m.wheel_torque) for m in out['adcs/actuator_command']]
    assert np.max(np.abs(cmds)) <= 1.0 + 1e-12
