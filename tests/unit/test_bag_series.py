"""The one reader of both reports (adcs_nodes/tools/analyse/bag_series.py), on series built by
hand: one t0 (the first /sim/state stamp, whatever came before it), every series in stamp
order with its seconds, the controller spans, the time axis by run length, ragged wheels."""
import math

import numpy as np
import pytest

from adcs_nodes.tools.analyse.bag_series import (RunData, TopicStats, _finish, ragged, spans,
                                                 time_axis)

S = 10**9


def test_t0_is_the_first_state_stamp_and_every_series_is_in_stamp_order():
    d = RunData()
    d.stats['/clock'] = TopicStats('rosgraph_msgs/msg/Clock', True, [5 * S])
    for t in (9 * S, 7 * S, 8 * S):                     # recorded out of stamp order
        d.state['t'].append(t)
        d.state['q_orbit_body'].append([0.0, 0.0, 0.0, 1.0])
        d.state['q_eci_body'].append([0.0, 0.0, 0.0, 1.0])
        d.state['w_eci'].append([t / S, 0.0, 0.0])
        d.state['w_orbit'].append([0.0, 0.0, 0.0])
    d.status['t'] += [6 * S, 8 * S]                     # a status before the first state
    d.status['active'] += ['bdot', 'mpi']
    d.status['mode'] += ['', '']
    d.status['switch_count'] += [0, 1]
    d.status['last_fault'] += ['', '']
    _finish(d)
    assert d.t0 == 7 * S
    assert d.state['t'] == [7 * S, 8 * S, 9 * S] and d.state['s'] == [0.0, 1.0, 2.0]
    assert [w[0] for w in d.state['w_eci']] == [7.0, 8.0, 9.0]      # rows moved together
    assert d.status['s'] == [-1.0, 1.0]


def test_without_state_t0_is_the_earliest_header_stamp():
    d = RunData()
    d.stats['/a'] = TopicStats('x/msg/A', True, [4 * S, 3 * S])
    d.stats['/b'] = TopicStats('x/msg/B', False, [1 * S])           # a log time: not a stamp
    _finish(d)
    assert d.t0 == 3 * S
    assert d.stats['/a'].rate_hz() == pytest.approx(1.0)
    assert d.stats['/b'].rate_hz() is None


def test_spans_merge_repeated_labels_and_end_at_t_end():
    assert spans([0, 5, 10, 12], ['bdot', 'bdot', 'mpi', 'fuzzy'], 20) == [
        (0, 10, 'bdot'), (10, 12, 'mpi'), (12, 20, 'fuzzy')]
    assert spans([], [], 20) == []


@pytest.mark.parametrize('t_end, period, unit, scale', [
    (600.0, None, 's', 1.0), (1200.0, 5400.0, 's', 1.0), (2000.0, None, 'min', 60.0),
    (2000.0, 5400.0, 'min', 60.0), (2700.0, 5400.0, 'orbits', 5400.0),
    (86400.0, None, 'min', 60.0)])
def test_the_time_axis_unit_follows_the_run_length(t_end, period, unit, scale):
    axis = time_axis(t_end, period)
    assert (axis.unit, axis.scale) == (unit, scale)
    assert axis.label == f'sim time [{unit}]'
    assert axis([0.0, t_end])[1] == pytest.approx(t_end / scale)


def test_ragged_rows_are_padded_with_nan():
    h = ragged([[1.0, 2.0, 3.0], [4.0], []])
    assert h.shape == (3, 3) and h[0].tolist() == [1.0, 2.0, 3.0]
    assert h[1, 0] == 4.0 and np.isnan(h[1, 1:]).all() and np.isnan(h[2]).all()
    assert ragged([]).shape == (0, 0)
    assert math.isnan(ragged([[], [1.0]])[0, 0])
