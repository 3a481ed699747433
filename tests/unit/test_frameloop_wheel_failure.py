"""Flying through a wheel failure on the FrameLoop (no processes; issue 36 item 3, issue 38
item 4): the demo's spacecraft on MPI from the start, ``wheel_stuck`` on wheel_x from 5 s to
45 s, 100 s in all.

* four wheels (the demo's three plus a skew one): the three healthy wheels still span 3-D, so
  MPI keeps control on them (no fallback, no dipole); the stuck wheel gets only its probe torque
  (+/- 2 x 0.2 rad/s x J_w per second); the truth attitude stays within 4 deg of the orbital
  frame; once the wheel is free it follows its probe and is used again after RECOVER_FRAMES.
* three wheels and magnetorquers: MPI keeps control, the magnetorquers take the x axis the
  wheels left no longer cover (a non-zero dipole during the failure only).

The allocation itself is checked against numpy's least squares and the (A5) identity in
tests/unit/test_wheel_allocation.py.
"""
import math

import numpy as np
import pytest

from adcs_nodes.core.wheel_health import RECOVER_FRAMES
from frameloop_run import q, raw, run, t_s, v, validated

STUCK_S, FREE_S = 5.0, 45.0
PROBE_NM = 2 * 0.2 * 3.0e-4            # PROBE_FACTOR x min_change_rad_s x J_w / period


def _scenario(tmp_path, four):
    sc = raw('demo_mission')
    sc['duration_s'] = 100.0
    sc['initial'] = {'q_orbit_body_xyzw': [0.0, 0.0, 0.0, 1.0],
                     'omega_body_orbit_body_deg_s': [0.3, -0.2, 0.25]}
    sc['manager'] = {'safe': 'bdot', 'initial': 'mpi', 'fallback': ['magnetic']}
    sc['guidance']['profile'] = [{'t_s': 0.0, 'type': 'hold'}]
    sc['faults'] = [{'at_s': STUCK_S, 'kind': 'wheel_stuck', 'target': 'wheel_x',
                     'params': {'duration_s': FREE_S - STUCK_S}}]
    if four:
        skew = dict(sc['spacecraft']['wheels'][0], name='wheel_s', axis=[3 ** -0.5] * 3)
        sc['spacecraft']['wheels'].append(skew)
    out, _ = run(validated(tmp_path, sc, 'wheels'))
    t0 = t_s(out['sim/state'][0])
    return out, t0


def _series(out, t0):
    mpi = {round(t_s(m) - t0): m for m in out['adcs/controllers/mpi/command']}
    applied = {round(t_s(m) - t0): m.source for m in out['adcs/actuator_command']}
    err_deg = {round(t_s(m) - t0): math.degrees(2 * math.acos(min(1.0, abs(q(m.q_orbit_body)[3]))))
               for m in out['sim/state']}
    return mpi, applied, err_deg


@pytest.fixture(scope='module')
def four(tmp_path_factory):
    return _series(*_scenario(tmp_path_factory.mktemp('four'), True))


@pytest.fixture(scope='module')
def three(tmp_path_factory):
    return _series(*_scenario(tmp_path_factory.mktemp('three'), False))


def _failed_frames(mpi):
    return sorted(t for t, m in mpi.items() if m.source.startswith('mpi; wheel wheel_x stuck'))


def test_four_wheels_mpi_keeps_control_on_the_three_left(four):
    mpi, applied, err = four
    assert set(applied.values()) == {'mpi'}                 # no fallback, no zero frame
    failed = _failed_frames(mpi)
    assert failed[0] == STUCK_S + 5                         # CONFIRM_FRAMES bad intervals
    assert failed == list(range(failed[0], failed[-1] + 1))
    for t in failed:
        m = mpi[t]
        assert abs(m.wheel_torque[0]) == pytest.approx(PROBE_NM, rel=1e-12)   # its probe only
        assert np.all(v(m.dipole_body) == 0.0)              # the wheels left span 3-D
        assert np.any(np.abs(np.asarray(m.wheel_torque[1:])) > 1e-5)         # they work
    signs = [np.sign(mpi[t].wheel_torque[0]) for t in failed]
    assert all(a == -b for a, b in zip(signs, signs[1:]))   # alternating: net momentum zero
    assert max(err.values()) < 4.0 and err[100] < 0.5


def test_four_wheels_the_freed_wheel_is_used_again_after_recover_frames(four):
    mpi, _, _ = four
    failed = _failed_frames(mpi)
    # the probe of frame FREE_S is the first the free wheel follows (judged at FREE_S + 1)
    assert failed[-1] == FREE_S + RECOVER_FRAMES - 1
    after = [t for t in mpi if t > failed[-1]]
    assert all(mpi[t].source == 'mpi' for t in after)
    used = [abs(mpi[t].wheel_torque[0]) for t in after]
    assert all(abs(u - PROBE_NM) > 1e-9 for u in used)     # allocated, not probed
    assert max(used) > 1e-5


def test_three_wheels_and_magnetorquers_keep_mpi_in_control(three):
    mpi, applied, err = three
    assert set(applied.values()) == {'mpi'}
    failed = _failed_frames(mpi)
    assert failed[0] == STUCK_S + 5 and failed[-1] == FREE_S + RECOVER_FRAMES - 1
    for t, m in mpi.items():
        dipole = v(m.dipole_body)
        if t in failed:
            assert np.linalg.norm(dipole) > 0.1 and np.max(np.abs(dipole)) <= 5.0
        else:
            assert np.all(dipole == 0.0)
    assert max(err.values()) < 12.0 and err[100] < 2.0
