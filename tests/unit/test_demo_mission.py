"""The demo mission (scenarios/demo_mission.yaml, `make demo`) on the FrameLoop (the plain
engine: no ROS, no process): every phase is reached in order, both faults are announced and
what the flight software does about them is seen, and no NaN reaches an actuator.

One run of the whole mission (9600 frames, about 25-35 s of CPU) shared by the tests. The
composed graph gives the same series (the engine parity contract, tests/graph/
test_engine_parity.py).

Truth: the scenario's timeline (its header): auto sequence detumble (B-dot) -> acquire
(magnetic), scheduled fuzzy capture at CAPTURE_S and MPI at POINT_S, fuzzy slew at SLEW_S and
MPI hold at HOLD_S, star tracker NaN from BLIND_S for 300 s, wheel_x stuck from STUCK_S, after
which MPI flies on with the two wheels left and the magnetorquers (no fallback).
"""
import collections
import math

import numpy as np
import pytest

from adcs_nodes.core import attitude as att
from adcs_nodes.msgs.fields import stamp_ns
from frameloop_run import messages, q, raw, v, validated
from sim_node.engine import FrameLoop

#: The topics the tests read (keeping every topic of 9600 frames costs more than the run).
KEPT = ('sim/state', 'sim/wheels', 'sim/faults', 'adcs/attitude_estimate',
        'adcs/estimator/diagnostics', 'adcs/attitude_target', 'adcs/actuator_command',
        'adcs/controller_status')
EPOCH_NS = 1773964800 * 10**9          # the scenario's epoch, 2026-03-20T00:00:00Z
#: The scenario's scripted times [s] (its header).
CAPTURE_S, POINT_S = 4400.0, 5040.0
BLIND_S, SLEW_S, HOLD_S, STUCK_S, END_S = 5400.0, 6600.0, 7200.0, 8400.0, 9600.0


def t_s(msg):
    """Sim time [s] of a message's header stamp."""
    return (stamp_ns(msg.header.stamp) - EPOCH_NS) / 1e9


def by_t(msgs):
    """``{sim time [s] rounded to 1 us: message}``."""
    return {round(t_s(m), 6): m for m in msgs}


@pytest.fixture(scope='module')
def mission(tmp_path_factory):
    sc = validated(tmp_path_factory.mktemp('demo'), raw('demo_mission'), 'demo_mission')
    loop = FrameLoop.from_scenario(sc)
    out = collections.defaultdict(list)
    for frame in loop.run():
        for topic, msg in messages(frame, loop):
            if topic in KEPT:
                out[topic].append(msg)
    assert t_s(out['sim/state'][0]) == 0.0
    return out, loop


def _status(out):
    return [(t_s(m), m) for m in out['adcs/controller_status']]


def _sources(out):
    """[(t, source)] at every change of the forwarded command's source."""
    runs, last = [], None
    for m in out['adcs/actuator_command']:
        if m.source != last:
            runs.append((t_s(m), m.source))
            last = m.source
    return runs


def test_every_phase_is_reached_in_order(mission):
    out, _ = mission
    modes = [(t, m.mode, m.active) for t, m in _status(out)]
    seq = [(mode, active) for _, mode, active in modes]
    # the automatic sequence, then the schedule (which suspends it: mode '')
    firsts = [seq.index(p) for p in (('detumble', 'bdot'), ('acquire', 'magnetic'),
                                     ('', 'fuzzy'), ('', 'mpi'))]
    assert firsts == sorted(firsts)
    starts = [(t, (mode, active)) for i, (t, mode, active) in enumerate(modes)
              if i == 0 or modes[i - 1][1:] != (mode, active)]
    when = {p: [t for t, x in starts if x == p]
            for p in (('acquire', 'magnetic'), ('', 'fuzzy'), ('', 'mpi'))}
    assert 1000.0 < when[('acquire', 'magnetic')][0] < CAPTURE_S
    assert when[('', 'fuzzy')] == [CAPTURE_S, SLEW_S] and when[('', 'mpi')] == [POINT_S, HOLD_S]
    sources = [s for _, s in _sources(out)]
    for name in ('bdot', 'magnetic', 'mpi', 'fuzzy'):
        assert name in sources                  # each controller drove the actuators
    truth, target = by_t(out['sim/state']), by_t(out['adcs/attitude_target'])

    def err(t):
        return math.degrees(att.angle_between(q(truth[t].q_orbit_body),
                                              q(target[t].q_ref_body)))
    rate0 = math.degrees(np.linalg.norm(v(truth[0.0].omega_body_eci_body)))
    rate_acq = math.degrees(np.linalg.norm(v(truth[when[('acquire', 'magnetic')][0]]
                                             .omega_body_eci_body)))
    assert rate0 > 3.0 and rate_acq < 0.6            # detumbled
    assert max(err(float(t)) for t in range(int(POINT_S) - 600, int(POINT_S))) < 10.0  # captured
    assert err(BLIND_S - 100.0) < 0.1                # MPI fine pointing on the orbital frame
    assert err(SLEW_S) > 40.0                        # the new attitude is 45 deg away ...
    assert max(err(t) for t in range(int(SLEW_S) + 300, int(HOLD_S))) < 0.5   # ... reached
    assert max(err(t) for t in range(int(HOLD_S) + 400, int(STUCK_S))) < 0.1  # MPI holds it
    wheels = by_t(out['sim/wheels'])
    assert max(abs(h) for t in range(int(SLEW_S), int(STUCK_S))
               for h in wheels[float(t)].momentum) < 0.2


def test_the_star_tracker_blind_the_mekf_coasts_on_the_gyro_and_comes_back(mission):
    out, loop = mission
    announced = [(t_s(m), s.message) for m in out['sim/faults'] for s in m.status]
    assert (BLIND_S, 'active: nan star_tracker') in announced
    assert (BLIND_S + 300.0, 'cleared: nan star_tracker') in announced
    diag = by_t(out['adcs/estimator/diagnostics'])
    assert diag[BLIND_S - 1.0].rejected_count == 0
    assert diag[BLIND_S + 299.0].rejected_count == 300     # every blind sample refused
    assert 'star tracker' in diag[BLIND_S + 299.0].last_rejection
    assert loop.estimator.rejected_count == 300
    est, truth = by_t(out['adcs/attitude_estimate']), by_t(out['sim/state'])

    def err(t):
        return math.degrees(att.angle_between(q(est[t].q_eci_body), q(truth[t].q_eci_body)))
    b = int(BLIND_S)
    before = max(err(float(t)) for t in range(b - 100, b))
    coasting = [err(float(t)) for t in range(b, b + 300)]
    after = max(err(float(t)) for t in range(b + 400, b + 500))
    assert len(est) == END_S + 1                     # an estimate every frame, blind or not
    assert max(coasting) > 2 * before                # the error grows on the gyro alone ...
    assert max(coasting) < 0.1                       # ... slowly (bias estimated before)
    assert after < 0.5 * max(coasting)               # the star tracker back: it comes down
    sigma = [math.degrees(3 * math.sqrt(max(est[float(t)].covariance[k * 7] for k in range(3))))
             for t in (BLIND_S - 1.0, BLIND_S + 299.0)]
    assert sigma[1] > 2 * sigma[0]                   # the filter knows it is coasting


def test_the_stuck_wheel_is_seen_and_mpi_flies_on_with_two_wheels_and_the_magnetorquers(mission):
    """wheel_x stuck: MPI's wheel check says so (a state, not a NaN); MPI keeps control on
    wheel_y, wheel_z and the magnetorquers for the x axis (no fallback, no missed frame);
    wheel_x is given only its probe torque; the attitude holds within 2 deg to the end."""
    out, loop = mission
    announced = [(t_s(m), s.message) for m in out['sim/faults'] for s in m.status]
    assert (STUCK_S, 'active: wheel_stuck wheel_x') in announced
    assert all(s == 'mpi' for t, s in _sources(out) if t > HOLD_S)     # no fallback
    noted = [(t, m) for t, m in _status(out) if m.last_fault]
    assert noted and STUCK_S < noted[0][0] < STUCK_S + 300.0          # seen within minutes
    t_seen, status = noted[0]
    assert status.active == 'mpi' and status.missed_frames == 0
    assert status.last_fault.startswith(f'mpi: wheel wheel_x stuck since t = {t_seen:g} s')
    assert 'non-finite' not in status.last_fault
    assert loop.manager.core.status()['missed_frames'] == 0
    act, wheels = by_t(out['adcs/actuator_command']), by_t(out['sim/wheels'])
    probe = 2 * 0.2 * 3.0e-4                  # PROBE_FACTOR x min_change x J_w / 1 s
    for t in range(int(t_seen), int(END_S)):
        assert abs(act[float(t)].wheel_torque[0]) == pytest.approx(probe, rel=1e-12)
        assert wheels[float(t + 1)].torque[0] == 0.0                   # stuck: no torque

    def dipole(t):
        return np.linalg.norm(v(act[float(t)].dipole_body))
    assert max(dipole(t) for t in range(int(t_seen), int(END_S))) > 0.5   # x on the rods
    assert all(dipole(t) == 0.0 for t in range(int(HOLD_S) + 1, int(t_seen)))
    truth, target = by_t(out['sim/state']), by_t(out['adcs/attitude_target'])
    err = [math.degrees(att.angle_between(q(truth[float(t)].q_orbit_body),
                                          q(target[float(t)].q_ref_body)))
           for t in range(int(STUCK_S), int(END_S) + 1)]
    rates = [math.degrees(np.linalg.norm(v(truth[float(t)].omega_body_orbit_body)))
             for t in range(int(STUCK_S), int(END_S) + 1)]
    assert max(err) < 2.0 and err[-1] < 0.1 and max(rates) < 0.03


def test_no_nan_reaches_an_actuator(mission):
    out, _ = mission
    for m in out['adcs/actuator_command']:
        assert np.all(np.isfinite(v(m.dipole_body))) and np.all(np.isfinite(m.wheel_torque))
        assert np.all(np.isfinite(v(m.torque_body)))
    assert len(out['adcs/actuator_command']) == END_S + 1
