"""``adcs report``'s pointing by controller phase, on series built by hand: the angles are
known rotations about z, the phases the manager's status changes."""
import math

import pytest

from adcs_nodes.tools.analyse.report import _Data, controller_phases

S = 10**9


def _about_z(deg):
    h = math.radians(deg) / 2.0
    return [0.0, 0.0, math.sin(h), math.cos(h)]


def _data(angle_of_t, status, target_frame='orbit', n=2000):
    d = _Data()
    for k in range(n):
        d.state['t'].append(k * S)
        d.state['q_orbit_body'].append(_about_z(angle_of_t(k)))
        d.state['q_eci_body'].append(_about_z(angle_of_t(k) + 90.0))
    for k in range(0, n, 10):                       # the target at 0.1 Hz, held between
        d.target['t'].append(k * S)
        d.target['q'].append(_about_z(0.0))
        d.target['frame'].append(target_frame)
    for t, name in status:
        d.status['t'].append(t * S)
        d.status['active'].append(name)
    return d


def test_each_phase_is_judged_over_its_last_ten_minutes_or_its_second_half():
    # 40 deg until 1000 s, then 30 deg falling 0.1 deg/s to 0 at 1300 s; a repeated status
    # (the same controller) is no new phase
    angle = lambda k: 40.0 if k < 1000 else max(0.0, 30.0 - 0.1 * (k - 1000))   # noqa: E731
    phases = controller_phases(_data(angle, [(0, 'bdot'), (500, 'bdot'), (1000, 'mpi')]), 0)
    assert [p['controller'] for p in phases] == ['bdot', 'mpi']
    bdot, mpi = phases
    assert (bdot['from_s'], bdot['to_s']) == (0.0, 1000.0)
    assert bdot['end_angle_deg'] == pytest.approx(40.0) and not bdot['settled']
    # mpi: 1000..1999 s, window 600 s -> from 1399 s: already at 0
    assert mpi['end_angle_deg'] == pytest.approx(0.0, abs=1e-6)
    assert mpi['last_window_max_deg'] == pytest.approx(0.0, abs=1e-6) and mpi['settled']
    # a short phase: its second half (1000..1200 s -> 1100..1199 s: 20 deg down to 10.1)
    short = controller_phases(_data(angle, [(0, 'bdot'), (1000, 'mpi'), (1200, 'fuzzy')]), 0)
    assert short[1]['last_window_max_deg'] == pytest.approx(20.0, abs=1e-6)
    assert not short[1]['settled']


def test_an_eci_target_is_compared_with_the_eci_attitude_and_no_status_gives_no_table():
    d = _data(lambda k: 5.0, [(0, 'mpi')], target_frame='eci')
    (only,) = controller_phases(d, 0)
    assert only['end_angle_deg'] == pytest.approx(95.0)      # the eci attitude is 90 deg on
    assert controller_phases(_data(lambda k: 5.0, []), 0) == []
