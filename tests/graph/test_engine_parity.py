"""Engine parity, the contract of the frame engine (issue 19): every shipped scenario gives the
same series on every data topic with the plain engine (the FrameLoop, no ROS), composed (all
nodes in one process) and as a graph (one process per node), to the last bit on one machine.

Each run is short: two periods of the slowest component of the scenario (every sensor,
estimator, controller and the manager fire at least twice; the estimator's
previous-frame command is used). The plain bags are written in this process
(:func:`adcs_nodes.tools.run.plain.run_plain`, what ``adcs run --engine plain`` calls), one of them
(:data:`PLAIN_CLI`) through the command itself; the bags are compared with
``tests/bag_digest.content_digest`` (per topic: count and a hash of every message's
values in stamp order).

Not compared: ``/tf``, ``/tf_static`` and ``/diagnostics`` (the plain engine does not publish
them: no data topics), ``adcs/security_events`` (the graph's publisher guard), and
``adcs/controller_status`` (published on change and once per wall second in a graph: wall
timed; on change in the plain engine). A law changed in one engine only changes a data topic
here.
"""
import math
import os

import pytest
import yaml

from adcs_launch import SCENARIOS, adcs, data_digest, plain_run
SHIPPED = sorted(f for f in os.listdir(SCENARIOS) if f.endswith('.yaml'))
#: The graph engine (one process per node) for scenarios of every shape: magnetic control
#: with the filter, wheels on a flexible craft with the MEKF (make test); a slew with ideal
#: torque, the horizon sensor (test-long: the same node classes run them composed here, and
#: the DDS between processes is the same for every scenario). Each costs about 10 s of
#: processes; composed covers all of them.
GRAPH = ('paper000_control.yaml', 'paper001_mpi.yaml',
         pytest.param('paper003_slew.yaml', marks=pytest.mark.long),
         pytest.param('paper004_yaw.yaml', marks=pytest.mark.long))
#: The scenario whose plain bag comes from ``adcs run --engine plain`` (a process, the command
#: line); the others' from :func:`adcs_nodes.tools.run.plain.run_plain` in this process (the same
#: code under the command, without an interpreter start each).
PLAIN_CLI = 'paper000_control.yaml'
#: Composed runs paced with ``--rate`` (at most F x real time): the pace changes the wall time
#: of the frames, never a number (paper001_mpi: 0.2 s frames, 50 ms of wall time each).
PACED = {'paper001_mpi.yaml': '4'}


def short_duration(path):
    """Two periods of the slowest component, in whole frames (at least 5 frames)."""
    with open(path) as fh:
        sc = yaml.safe_load(fh)
    frame = float(sc['timing']['frame_s'])
    periods = [float(s.get('period_s', frame)) for s in (sc.get('sensors') or {}).values()]
    periods.append(float((sc.get('estimator') or {}).get('period_s', frame)))
    periods.append(float((sc.get('controllers') or {}).get('period_s', frame)))
    frames = max(5, math.ceil(2.0 * max(periods) / frame))
    return f'{frames * frame:g}'


def short_scenario(path, directory):
    """``path`` itself, or a copy without the faults that start after the short run (a fault
    after the end of a ``--duration`` override is refused; it could not strike anyway)."""
    with open(path) as fh:
        sc = yaml.safe_load(fh)
    end = float(short_duration(path))
    faults = [f for f in sc.get('faults') or [] if float(f['at_s']) <= end]
    if len(faults) == len(sc.get('faults') or []):
        return path
    sc['faults'] = faults
    copy = os.path.join(str(directory), os.path.basename(path))
    if not os.path.exists(copy):
        with open(copy, 'w') as fh:
            yaml.safe_dump(sc, fh, sort_keys=False)
    return copy


@pytest.fixture(scope='module')
def short_dir(tmp_path_factory):
    """Where the short copies of the scenarios go (:func:`short_scenario`)."""
    return tmp_path_factory.mktemp('short')


@pytest.fixture(scope='module')
def plain_bags(tmp_path_factory, short_dir):
    """Each shipped scenario's plain-engine bag: :data:`PLAIN_CLI`'s by the real command (a
    subprocess), the others' by :func:`adcs_nodes.tools.run.plain.run_plain` in this process."""
    out = {}
    root = tmp_path_factory.mktemp('plain')
    for name in SHIPPED:
        path = short_scenario(os.path.join(SCENARIOS, name), short_dir)
        bag = str(root / name[:-5])
        if name == PLAIN_CLI:
            adcs('run', path, '--engine', 'plain', '--record', bag, '--duration',
                 short_duration(path), '--quiet', timeout=600)
        else:
            res = plain_run(path, short_duration(path), bag)
            assert res.exit_code == 0, f'{name}: {res.message}'
        out[name] = data_digest(bag)
    return out


def _compare(plain, other, engine, name):
    assert set(plain) == set(other), f'{name}: topics differ, plain {sorted(plain)} vs ' \
                                     f'{engine} {sorted(other)}'
    differ = [t for t in plain if plain[t] != other[t]]
    assert not differ, f'{name}: plain and {engine} differ on {differ}: ' + ', '.join(
        f'{t} {plain[t][0]} vs {other[t][0]} messages' for t in differ)
    assert sum(n for n, _ in plain.values()) > 0


@pytest.mark.parametrize('name', SHIPPED)
def test_plain_and_composed_give_the_same_bag(plain_bags, short_dir, name, tmp_path):
    path = short_scenario(os.path.join(SCENARIOS, name), short_dir)
    bag = str(tmp_path / 'composed')
    pace = ('--rate', PACED[name]) if name in PACED else ()
    adcs('run', path, '--engine', 'composed', '--record', bag, '--duration',
         short_duration(path), '--quiet', *pace, timeout=600)
    _compare(plain_bags[name], data_digest(bag), 'composed', name)


@pytest.mark.parametrize('name', GRAPH)
def test_plain_and_graph_give_the_same_bag(plain_bags, short_dir, name, tmp_path):
    path = short_scenario(os.path.join(SCENARIOS, name), short_dir)
    bag = str(tmp_path / 'graph')
    adcs('run', path, '--record', bag, '--duration', short_duration(path), '--quiet',
         timeout=600)
    _compare(plain_bags[name], data_digest(bag), 'graph', name)
