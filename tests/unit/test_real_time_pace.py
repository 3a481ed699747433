"""``adcs run --real-time`` says when the run did not keep the asked pace (the launcher is
replaced by one that returns a result; the pace is sim time over wall time)."""
import os

import pytest

from adcs_nodes.tools import cli

from adcs_nodes.tools.run import launcher

SCENARIO = os.path.join(os.path.dirname(__file__), '..', '..', 'scenarios',
                        'paper003_slew.yaml')


FRAME_S = 0.1          # paper003_slew's frame


def _fake(sim_s, wall_s, start_s=3.0):
    """A launcher whose run took ``wall_s`` from frame 0, plus ``start_s`` of start-up."""
    class Fake:
        def __init__(self, *args, **kwargs):
            self.kwargs = kwargs

        def run(self):
            return launcher.RunResult(exit_code=0, sim_time_s=sim_s,
                                      wall_time_s=wall_s + start_s,
                                      frames=int(sim_s / FRAME_S), missed_frames=0, bag=None,
                                      run_dir='', message='done',
                                      frames_per_s=sim_s / FRAME_S / wall_s)
    return Fake


@pytest.mark.parametrize('args,sim_s,wall_s,warned', [
    (['--rate', '20'], 80.0, 80.0 / 3.7, True),          # kept 3.7x of 20x
    (['--rate', '20'], 80.0, 80.0 / 19.5, False),        # 97.5 %: kept
    ([], 20.0, 32.8, True),                              # rate 1, kept 0.6x
    ([], 20.0, 20.4, False),
])
def test_a_real_time_run_that_fell_behind_says_so(monkeypatch, capsys, args, sim_s,
                                                  wall_s, warned):
    monkeypatch.setattr(launcher, 'Launcher', _fake(sim_s, wall_s))
    assert cli.main(['run', SCENARIO, '--real-time', *args, '--quiet']) == 0
    err = capsys.readouterr().err
    assert ('WARNING: real time at rate' in err) is warned, err
    if warned:
        assert '--engine composed' in err          # the graph engine: the faster way named


def test_a_lockstep_run_is_not_judged_by_its_pace(monkeypatch, capsys):
    monkeypatch.setattr(launcher, 'Launcher', _fake(20.0, 100.0))
    assert cli.main(['run', SCENARIO, '--quiet']) == 0
    assert 'WARNING' not in capsys.readouterr().err


@pytest.mark.parametrize('args,rate_factor,max_rate', [
    (['--rate', '20'], 1.0, 20.0),                     # lockstep paced to at most 20x
    (['--real-time', '--rate', '20'], 20.0, 0.0),      # real time at 20x, no lockstep pace
    ([], 1.0, 0.0),                                    # lockstep as fast as it goes
])
def test_rate_paces_the_lockstep_without_real_time(monkeypatch, args, rate_factor, max_rate):
    fake = _fake(20.0, 1.0)
    seen = {}

    class Spy(fake):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            seen.update(kw)
    monkeypatch.setattr(launcher, 'Launcher', Spy)
    assert cli.main(['run', SCENARIO, *args, '--quiet']) == 0
    assert (seen['rate_factor'], seen['max_rate']) == (rate_factor, max_rate)


@pytest.mark.parametrize('args', [['--rate', '0'], ['--rate', 'nan'], ['--rate', '-1'],
                                  ['--rate', '5', '--engine', 'plain']])
def test_a_bad_rate_or_a_paced_plain_run_exits_2_saying_why(capsys, args):
    assert cli.main(['run', SCENARIO, *args, '--quiet']) == 2
    err = capsys.readouterr().err
    assert '--rate must be in (0, 1e6]' in err or 'no pace' in err, err
