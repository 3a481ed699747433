"""Composed runner's in-process path (issue 13): the same final state to the last bit.

``paper000_control`` (estimator, controllers, manager in the loop) at 1 s frames for 60
frames, composed, once over DDS (``--dds``) and once with the in-process path (the default,
``--inproc``); the clock master's final state
(written with ``--state-out`` as exact hex floats) must be identical, and the in-process run
must really have delivered messages in process.
"""
import json
import os
import re
import subprocess

import pytest

pytest.importorskip('rclpy')

from domains import worker_domain  # noqa: E402
from adcs_nodes.tools.run.launcher import child_env  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _compose_cmd(tmp_path):
    import copy

    from adcs_nodes.graph import params_file_text
    from adcs_nodes.tools.run.launcher import Launcher
    from adcs_nodes.scenario import load_scenario

    sc = copy.deepcopy(load_scenario(os.path.join(ROOT, 'scenarios', 'paper000_control.yaml')))
    sc['timing']['frame_s'], sc['timing']['substeps'] = 1.0, 10
    # no input may time out (5 s of wall time in the scenario): a missed frame under load would
    # change one run's final state; every input comes at once when the nodes are right
    sc['timing']['timeout_s'] = 60.0
    launcher = Launcher(sc, duration_s=60.0, compose=True, progress=False,
                        run_dir=str(tmp_path), log=lambda *a, **k: None)
    params = tmp_path / 'params.yaml'
    params.write_text(params_file_text(launcher.nodes))
    return launcher._commands(str(params))['composed']


def test_inproc_path_gives_the_same_final_state(tmp_path):
    cmd = _compose_cmd(tmp_path)
    states, logs = {}, {}
    for n, mode in enumerate(('dds', 'inproc')):
        out = tmp_path / f'state-{mode}.json'
        env = {k: v for k, v in child_env(worker_domain(130, 10, n)).items()
               if k != 'ADCS_COMPOSE_INPROC'}
        extra = ['--inproc'] if mode == 'inproc' else ['--dds']
        proc = subprocess.run(cmd + ['--state-out', str(out)] + extra, cwd=ROOT, env=env,
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, f'{mode}: {proc.stderr[-3000:]}'
        states[mode] = json.loads(out.read_text())
        logs[mode] = proc.stderr
    assert any(len(v) == 4 for v in states['dds'].values()), states['dds']   # a quaternion
    assert states['inproc'] == states['dds']
    m = re.search(r'in-process deliveries (\d+)', logs['inproc'])
    assert m and int(m.group(1)) >= 60 * 5, logs['inproc'][-2000:]
    assert 'in-process deliveries' not in logs['dds']


def test_inproc_is_the_default_and_dds_turns_it_off(monkeypatch):
    from adcs_nodes.tools.run.compose import inproc_enabled

    monkeypatch.delenv('ADCS_COMPOSE_INPROC', raising=False)
    assert inproc_enabled(False) and inproc_enabled(True)
    assert not inproc_enabled(False, dds=True)
    for off in ('0', 'false', 'No', 'off'):
        monkeypatch.setenv('ADCS_COMPOSE_INPROC', off)
        assert not inproc_enabled(False)
        assert inproc_enabled(True)       # --inproc wins over the environment
    monkeypatch.setenv('ADCS_COMPOSE_INPROC', '1')
    assert inproc_enabled(False)
