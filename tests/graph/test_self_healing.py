"""Self-healing before frame 0 (issue 20): a node whose expected endpoints stay unmatched
while every other node is ready is restarted once; stuck again, the run fails saying why.

The never-matching node is made with the launcher's test-only ``ADCS_TEST_NODE_ROS_ARGS``: the
``environment``'s ``/clock`` subscription remapped to a topic nobody publishes (its
handshake waits for it for ever, ``discovery knows 0``, as in the CI28 failure)."""
import os

import pytest

pytest.importorskip('rclpy')

from adcs_launch import SCENARIOS  # noqa: E402

FREE_TUMBLE = os.path.join(SCENARIOS, 'free_tumble.yaml')
NOWHERE = '-r /clock:=/adcs_test/nowhere'


def _run(monkeypatch, node_args, **kw):
    from adcs_nodes.tools.run import launcher
    from adcs_nodes.tools.run.launcher import healing, processes
    from adcs_nodes.scenario import load_scenario
    monkeypatch.setattr(healing, 'HEAL_WAIT_S', 10.0)    # the first 'still waiting' line
    monkeypatch.setenv(processes.TEST_NODE_ARGS_ENV, node_args)
    lines = []
    run = launcher.Launcher(load_scenario(FREE_TUMBLE), duration_s=4.0, progress=False,
                            log=lines.append, **kw)
    return run.run(), lines


@pytest.mark.long   # the restart path: test_a_node_healed_by_its_restart... in make test;
#                    the give-up rule: tests/unit/test_launcher_self_healing.py
def test_a_node_that_never_matches_is_restarted_once_then_the_run_fails(monkeypatch):
    result, lines = _run(monkeypatch, f'environment:{NOWHERE}')
    assert result.exit_code == 1, result.message
    assert result.restarts == {'environment': 1}
    assert ('node environment still has unmatched endpoints after 1 restart(s) before '
            'frame 0: sub:/adcs_test/nowhere 0/1 (discovery knows 0)') in result.message
    assert sum('restarting node environment before frame 0' in ln for ln in lines) == 1
    assert not any('restarting node dynamics' in ln for ln in lines)
    with open(os.path.join(result.run_dir, 'logs', 'environment.log')) as fh:
        assert fh.read().count('----- restarted by the launcher before frame 0') == 1


def test_a_node_healed_by_its_restart_runs_to_the_end_as_without_it(monkeypatch, tmp_path):
    result, lines = _run(monkeypatch, f'environment@1:{NOWHERE}',
                         record=str(tmp_path / 'bag'))
    assert result.exit_code == 0, result.message
    assert result.restarts == {'environment': 1}
    assert result.frames == 4 and result.missed_frames == 0
    assert '[adcs] restarts: 1 before frame 0 (self-healing: environment: its endpoints' \
        in result.message
    # nothing had happened before frame 0: the bag is the one of a run without a restart,
    # whose data series are the plain engine's (the engine-parity contract)
    from adcs_launch import data_digest, plain_run
    clean = plain_run(FREE_TUMBLE, 4.0, tmp_path / 'clean')
    assert clean.exit_code == 0, clean.message
    assert data_digest(tmp_path / 'bag') == data_digest(tmp_path / 'clean')
