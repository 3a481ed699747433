"""Issue 38 item 1 in a launched graph: the filter restart + star-tracker outage combination
(two overlapping bias steps: the MEKF refuses 10 samples and restarts; the star tracker is then
silent and stuck) gives the plain engine's series on every data topic, one process per node.

With the estimate gone, the controllers and the manager stop waiting for it and the world
runs ahead of the estimator, so the star tracker's returning sample may reach it before it
has counted its own third miss; the frame-synchronisation rule reads misses and returns from
the stamps (``core.lockstep.FrameSync``), so the estimator holds the return whatever the
order (it used it, and the graph differed, when the order decided). The random combinations
run plain against composed in ``tests/node/test_fault_parity.py``. And the plain engine's bag
holds, message for message, the bytes the nodes publish (its sink converts core samples).
"""
import yaml

from adcs_launch import SCENARIOS, adcs, data_digest, plain_run
from adcs_nodes.bag import read_messages


def test_restart_and_outage_give_the_plain_series_in_a_graph(tmp_path):
    with open(f'{SCENARIOS}/paper001_mpi.yaml') as fh:
        sc = yaml.safe_load(fh)
    sc['timing']['timeout_s'] = 1.0          # the silent producers cost timeouts of wall time
    at = {'target': 'star_tracker'}
    sc['faults'] = [        # 0.2 s frames: refused from 0.4 s, the 10th (2.2 s) restarts
        {**at, 'at_s': 0.4, 'kind': 'bias_step',
         'params': {'bias': [0.01, 0, 0], 'duration_s': 3.0}},
        {**at, 'at_s': 0.6, 'kind': 'bias_step',
         'params': {'bias': [0, 0.01, 0], 'duration_s': 3.0}},
        {**at, 'at_s': 2.4, 'kind': 'dropout', 'params': {'duration_s': 1.0}},
        {**at, 'at_s': 2.6, 'kind': 'stuck', 'params': {'duration_s': 2.0}}]
    path = tmp_path / 'restart_outage.yaml'
    path.write_text(yaml.safe_dump(sc))
    graph, plain = str(tmp_path / 'graph'), str(tmp_path / 'plain')
    run = adcs('run', str(path), '--record', graph, '--duration', '6', '--quiet', timeout=600,
               check=False)
    assert run.returncode == 3, run.stderr        # degraded: no estimate after the restart
    assert plain_run(path, 6, plain).exit_code == 3
    stamps = [m.header.stamp for _, _, m in read_messages(graph, ['/adcs/attitude_estimate'])]
    assert len(stamps) == 11                 # 0 .. 2.0 s; none after the restart (held)
    assert data_digest(graph) == data_digest(plain)


def raw_series(bag):
    """Per data topic: the raw CDR bytes of every message in log order."""
    from rosbags.rosbag2 import Reader

    from adcs_launch import NOT_DATA
    out = {}
    with Reader(bag) as reader:
        for conn, _, raw in reader.messages():
            if conn.topic not in NOT_DATA + ('/clock', '/lockstep/status'):
                out.setdefault(conn.topic, []).append(bytes(raw))
    return out


def test_the_plain_bag_holds_the_bytes_the_nodes_publish(tmp_path):
    """The plain engine's bag sink converts core samples to messages and encodes them: the
    same bytes, message for message, as the composed run's recorder received from the nodes
    (not only the same values: ``data_digest`` compares deserialised values)."""
    path = f'{SCENARIOS}/paper000_control.yaml'
    composed, plain = str(tmp_path / 'composed'), str(tmp_path / 'plain')
    adcs('run', path, '--engine', 'composed', '--record', composed, '--duration', '40',
         '--quiet', timeout=600)
    assert plain_run(path, 40, plain).exit_code == 0
    a, b = raw_series(plain), raw_series(composed)
    assert sorted(a) == sorted(b) and len(a) > 8
    assert {t: len(v) for t, v in a.items()} == {t: len(v) for t, v in b.items()}
    assert [t for t in a if a[t] != b[t]] == []
