"""Reaction wheels in the launched graph (issue 9): a short MPI maneuver, and live switching
between mpi, magnetic and bdot on one spacecraft with magnetorquers and wheels.

``make test-long`` (marker ``long``, about two minutes of graph runs): the same behaviour,
with the same assertions, is tested on the FrameLoop in ``make test``
(``tests/unit/test_frameloop_wheels.py``), and the graph gives the FrameLoop's series for
paper001_mpi (``tests/graph/test_engine_parity.py``).
"""
import copy
import os

import numpy as np
import pytest
import yaml

from adcs_launch import SCENARIOS, adcs
from adcs_nodes.core import attitude as att
from adcs_nodes.bag import header_stamp_ns, read_messages

pytestmark = pytest.mark.long

EPOCH_NS = 1767225600 * 10**9
Q_LVLH = [1.0, 0.0, 0.0, 0.0]          # body on the LVLH axes (180 deg about x of the orbit frame)


def _paper001(**changes):
    with open(os.path.join(SCENARIOS, 'paper001_mpi.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['initial'] = {'q_orbit_body_xyzw': Q_LVLH, 'omega_body_orbit_body_deg_s': [0.0] * 3}
    sc['estimator']['initial_q_orbit_body_xyzw'] = Q_LVLH
    sc['timing']['timeout_s'] = 2.0
    sc.update(changes)
    return sc


def _write(tmp_path, sc, name):
    path = tmp_path / f'{name}.yaml'
    path.write_text(yaml.safe_dump(sc))
    return str(path)


def _by_t(bag, topic):
    return {round((header_stamp_ns(m) - EPOCH_NS) / 1e9, 6): m
            for _, _, m in read_messages(bag, [topic])}


def _q(m, field):
    q = getattr(m, field)
    return np.array([q.x, q.y, q.z, q.w])


def test_short_mpi_maneuver_with_wheels_reaches_and_holds_the_target(tmp_path):
    sc = _paper001()
    sc['guidance']['euler312_profile'] = [
        {'type': 'maneuver', 'start_s': 0.0, 'end_s': 20.0, 'euler_deg': [2.0, -2.0, 2.0]},
        {'type': 'hold', 'start_s': 20.0, 'end_s': 60.0, 'euler_deg': [2.0, -2.0, 2.0]}]
    bag = str(tmp_path / 'mpi')
    adcs('run', _write(tmp_path, sc, 'mpi'), '--record', bag, '--duration', '60', '--quiet',
         timeout=600)
    cmds = _by_t(bag, '/adcs/actuator_command')
    torques = np.array([list(m.wheel_torque) for m in cmds.values()])
    assert torques.shape[1] == 3 and np.max(np.abs(torques)) <= 1.0 + 1e-12
    assert {m.source for t, m in cmds.items() if t > 0} == {'mpi'}
    truth, target = _by_t(bag, '/sim/state'), _by_t(bag, '/adcs/attitude_target')
    start = np.degrees(att.angle_between(_q(truth[0.0], 'q_orbit_body'),
                                         _q(target[0.0], 'q_ref_body')))
    end = [np.degrees(att.angle_between(_q(truth[t], 'q_orbit_body'),
                                        _q(target[t], 'q_ref_body')))
           for t in sorted(target) if t >= 50.0]
    assert start > 3.0                       # the maneuver is about 3.4 deg
    assert max(end) < 0.1, end               # reached and held (paper: within 0.1 deg)
    wheels = _by_t(bag, '/sensors/wheels')
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
    bag = str(tmp_path / 'switch')
    adcs('run', _write(tmp_path, sc, 'switch'), '--record', bag, '--duration', '40',
         '--quiet', timeout=600)
    src = {t: m.source for t, m in _by_t(bag, '/adcs/actuator_command').items()}
    assert src[10.0] == src[20.0] == src[30.0] == 'zero'     # one zero frame per switch
    assert all(src[float(t)] == 'mpi' for t in range(1, 10))
    assert all(src[float(t)] == 'magnetic' for t in range(11, 20))
    assert all(src[float(t)] == 'bdot' for t in range(21, 30))
    assert all(src[float(t)] == 'mpi' for t in range(31, 41))
    cmds = _by_t(bag, '/adcs/actuator_command')
    for t in range(11, 20):      # magnetic commands a dipole and no wheel torque
        m = cmds[float(t)]
        assert not np.any(m.wheel_torque)
