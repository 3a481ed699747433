"""Forged actuator commands in a launched run (issue 12, ``publisher_guard``).

A closed loop (paper 000 satellite, B-dot on a 2 s magnetometer, no estimator) runs 2000
frames recorded. After the run's start handshake (dynamics logged ``lockstep start``) a
stranger joins the run's domain (``forger.py``) and, for 20 ``/clock`` ticks, publishes valid
commands (30 A m^2 dipoles) stamped with the current and the next frame on
``adcs/actuator_command`` (read by ``dynamics``) and ``adcs/controllers/bdot/command`` (read
by ``controller_manager``). Before the guard these commands were applied (the forged one of
a frame arrives before the true one) and nothing reported it. Now:

* the true trajectory (``/sim/state``) and the manager's output are bit for bit those of a
  run without the forger (the plain engine's run, whose data topics are a launched run's by
  engine parity), in a forged run composed (one process, DDS between the nodes) and, in
  test-long, one process per node (the in-process path ``--inproc`` cannot record yet, see
  docs/security.md);
* a forger that takes the name of the node it impersonates (``controller_manager``) after
  the handshake is refused all the same (its GID was not there at the lock);
* ``dynamics`` and ``controller_manager`` count the dropped messages in ``/diagnostics``
  (``security_foreign_publisher``), and the bag holds their ``adcs/security_events``
  (reason, topic, the forger's GID) and the forged messages themselves.
"""
import json
import os
import subprocess
import sys
import time

import pytest
import yaml

from adcs_launch import ROOT, SCENARIOS, start_adcs, wait_manifest
from adcs_nodes.bag import flatten_message, read_messages

pytestmark = pytest.mark.ros

DURATION = '4000'
FRAMES = 2001                       # t = 0, 2, ..., 4000 s
FORGED = ['adcs/actuator_command', 'adcs/controllers/bdot/command']
HERE = os.path.dirname(os.path.abspath(__file__))


@pytest.fixture(scope='module')
def scenario(tmp_path_factory):
    with open(os.path.join(SCENARIOS, 'paper000_control.yaml')) as fh:
        sc = yaml.safe_load(fh)
    del sc['estimator']
    sc['controllers'] = {'period_s': 2.0, 'bdot': sc['controllers']['bdot']}
    sc['manager'] = {'safe': 'bdot', 'initial': 'bdot', 'stale_after_s': 0.0}
    sc['sensors']['magnetometer']['period_s'] = 2.0
    path = tmp_path_factory.mktemp('guard') / 'bdot.yaml'
    path.write_text(yaml.safe_dump(sc))
    return str(path)


@pytest.fixture(scope='module')
def clean(scenario, tmp_path_factory):
    """The run without the forger, on the plain engine (in this process, 1-2 s instead of a
    20-25 s launched run): its data topics are bit for bit a launched run's
    (``test_engine_parity``)."""
    from adcs_nodes.scenario import load_scenario
    from adcs_nodes.tools.run.plain import run_plain
    bag = str(tmp_path_factory.mktemp('guard') / 'clean')
    res = run_plain(load_scenario(scenario), float(DURATION), bag, progress=False)
    assert res.exit_code == 0, res.message
    return bag


def _wait_for(predicate, timeout, what, proc):
    deadline = time.monotonic() + timeout
    while not predicate():
        if proc.poll() is not None:
            raise AssertionError(f'run ended before {what}: {proc.communicate()}')
        if time.monotonic() > deadline:
            raise AssertionError(f'timed out after {timeout} s waiting for {what}')
        time.sleep(0.05)


def _log_has(path, text):
    try:
        with open(path) as fh:
            return text in fh.read()
    except OSError:
        return False


def _by_stamp(bag, topic):
    """(true, forged) messages of a topic: ``{stamp: exact contents}`` and a list."""
    true, forged = {}, []
    for _, _, m in read_messages(bag, topics=[topic]):
        stamp = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
        if getattr(m, 'source', '') == 'forger':
            forged.append(m)
        else:
            true[stamp] = repr(flatten_message(m))
    return true, forged


def _assert_same(got, ref, what):
    """Bit-for-bit equal messages at every stamp both bags hold. A message the recorder
    lost under load (seen once: DDS, not the simulation) leaves a gap; the last frame and
    nearly all others must be there, and each later state carries every earlier command."""
    common = sorted(set(got) & set(ref))
    assert len(common) >= 0.95 * FRAMES and common[-1] == max(ref), \
        f'{what}: {len(got)} and {len(ref)} messages recorded, {len(common)} in common'
    bad = [t for t in common if got[t] != ref[t]]
    assert not bad, f'{what} differs from the run without the forger from t = ' \
                    f'{(bad[0] - common[0]) / 1e9:g} s ({len(bad)} of {len(common)} stamps)'


def _last_diagnostics(bag, node):
    """Key-values of the last ``/diagnostics`` status of ``node`` in the bag."""
    last = None
    for _, _, msg in read_messages(bag, topics=['/diagnostics']):
        for st in msg.status:
            if st.name == node:
                last = {kv.key: kv.value for kv in st.values}
    return last


@pytest.mark.parametrize('compose,name', [
    # the per-node variant in test-long: the composed one, with the harder same-name forger, in
    # make test (the guard is the same code in each node)
    pytest.param(False, 'forger', marks=pytest.mark.long), (True, 'controller_manager')],
                         ids=['process_per_node', 'composed_same_name'])
def test_forged_commands_are_dropped_counted_and_recorded(scenario, clean, tmp_path, compose,
                                                          name):
    from adcs_nodes.tools.run.launcher import child_env
    bag = str(tmp_path / 'forged')
    # paced (the same series): unpaced, the composed run ended within 5 s of wall time,
    # sometimes before the forger had matched its readers (ticks 0)
    proc = start_adcs('run', scenario, '--record', bag, '--duration', DURATION, '--quiet',
                      '--rate', '300', *(['--compose'] if compose else []))
    forger = None
    try:
        manifest = wait_manifest(proc, timeout=60.0)
        log = os.path.join(manifest['run_dir'], 'logs',
                           ('composed' if compose else 'dynamics') + '.log')
        # The forger must forge before the run ends: the composed run takes 4-5 s of wall
        # time from its lockstep start at load 8, the forger needed 1.6-1.8 s of it when
        # started there (mostly its Python and rclpy imports). It starts now, while the graph
        # starts, and joins the domain when told (after the handshake).
        forger = subprocess.Popen(
            [sys.executable, os.path.join(HERE, 'forger.py'), '--topics', *FORGED,
             '--name', name, '--go-on-stdin'],
            cwd=ROOT, env=child_env(manifest['domain']), stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        _wait_for(lambda: _log_has(log, 'lockstep start'), 120.0, 'the lockstep start', proc)
        f_out, f_err = forger.communicate('go\n', timeout=180)
        out, err = proc.communicate(timeout=600)
    finally:
        for p in (forger, proc):
            if p is not None and p.poll() is None:
                p.kill()
                p.communicate()
    assert proc.returncode == 0, out + err
    assert 'security: dynamics refused' in out + err, out + err     # the summary says so
    report = json.loads(f_out.strip().splitlines()[-1])
    assert report['ticks'] >= 1, (report, f_err)       # it forged while the run was going on
    assert all(n >= 2 for n in report['sent'].values()), report

    # the truth, the measurements, the controller's and the manager's commands are bit for
    # bit those of the run without the forger; the bag also holds the forged commands (the
    # recorder records every publisher)
    for topic in ('/sim/state', '/sensors/magnetometer', *('/' + t for t in FORGED)):
        true, forged = _by_stamp(bag, topic)
        _assert_same(true, _by_stamp(clean, topic)[0], topic)
        if topic.lstrip('/') in FORGED:
            assert forged, f'the forged {topic} messages are not in the bag'

    events = [(msg.status[0].name, {kv.key: kv.value for kv in msg.status[0].values})
              for _, _, msg in read_messages(bag, topics=['/adcs/security_events'])]
    for node, topic in (('dynamics', '/adcs/actuator_command'),
                        ('controller_manager', '/adcs/controllers/bdot/command')):
        diag = _last_diagnostics(bag, node)
        assert diag is not None, f'no /diagnostics of {node}'
        dropped = int(diag['security_foreign_publisher'])
        assert 1 <= dropped <= report['sent'][topic.lstrip('/')], (node, diag)
        mine = [v for n, v in events if n == node and v['reason'] == 'foreign_publisher']
        assert mine, f'no security event of {node} in the bag'
        assert all(v['topic'] == topic and v['publisher_gid'] != '-' for v in mine), mine
        assert len({v['publisher_gid'] for v in mine}) == 1, mine     # the one forger
        assert len(mine) <= dropped
        # nothing else refused: no false alarm on the true producers' messages
        # (a refused true producer would be a second publisher GID among the events above)
        assert diag['security_duplicate_stamp'] == diag['security_old_stamp'] == \
            diag['security_before_handshake'] == '0', diag
