"""Lockstep determinism of the closed loop (issue 12): paper000_control runs beside two CPU
burners, one process per node and composed, give the same contents on every data topic
(estimate, commands of every controller, the manager's output, truth, magnetometer, target)
as the plain engine's run, which has no processes, no DDS and no load to be disturbed by.
The plain engine equals an unloaded graph on every data topic (the engine-parity contract,
tests/graph/test_engine_parity.py), so this is the old "loaded = unloaded" check without
the second graph run. ``/tf`` is not compared here (the plain engine publishes no tf): it is
a function of the state and estimate compared here, and tests/graph/test_tf_bag.py checks
that function on a recorded bag."""
import multiprocessing
import os

import pytest
import yaml

from adcs_launch import SCENARIOS, adcs, plain_run
from bag_digest import content_digest

DURATION = '300'
DATA_TOPICS = ('/adcs/attitude_estimate', '/adcs/actuator_command',
               '/adcs/controllers/magnetic/command', '/adcs/controllers/bdot/command',
               '/sim/state', '/sensors/magnetometer', '/adcs/attitude_target')


def _burn(seconds):
    import time
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        pass


@pytest.fixture(scope='module')
def scenario(tmp_path_factory):
    with open(os.path.join(SCENARIOS, 'paper000_control.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['sensors']['magnetometer']['period_s'] = 2.0      # the magnetometer in every frame
    path = tmp_path_factory.mktemp('det') / 'control.yaml'
    path.write_text(yaml.safe_dump(sc))
    return str(path)


@pytest.fixture(scope='module')
def reference(scenario, tmp_path_factory):
    """The plain engine's bag (in this process: what ``adcs run --engine plain`` calls)."""
    bag = str(tmp_path_factory.mktemp('det') / 'reference')
    res = plain_run(scenario, DURATION, bag)
    assert res.exit_code == 0, res.message
    return content_digest(bag)


@pytest.mark.parametrize('compose', [False,
                                     # one composed variant in make test: the in-process one
                                     pytest.param(True, marks=pytest.mark.long), 'inproc'],
                         ids=['process_per_node', 'composed', 'composed_inproc'])
def test_closed_loop_bag_is_identical_beside_cpu_burners(scenario, reference, tmp_path,
                                                         compose, monkeypatch):
    if compose == 'inproc':   # the in-process path, with a composed recorder (raw CDR)
        monkeypatch.setenv('ADCS_COMPOSE_INPROC', '1')
    elif compose:             # composed, all over DDS (the in-process path is the default)
        monkeypatch.setenv('ADCS_COMPOSE_INPROC', '0')
    bag = str(tmp_path / 'loaded')
    burners = [multiprocessing.Process(target=_burn, args=(300.0,)) for _ in range(2)]
    for b in burners:
        b.start()
    try:
        adcs('run', scenario, '--record', bag, '--duration', DURATION, '--quiet',
             *(['--compose'] if compose else []), timeout=600)
    finally:
        for b in burners:
            b.terminate()
            b.join()
    got = content_digest(bag)
    for topic in DATA_TOPICS:
        assert topic in reference, f'{topic} not recorded'
        assert got[topic] == reference[topic], f'{topic} differs under load'
