"""``adcs --help`` and every subcommand's help are complete after the parsers were
consolidated (issue 34 item 3): the options a user has are all there, the ones shared by
several commands (``--run PID``, the bag, the campaign options of ``montecarlo`` and
``sweep``) are defined once, and the standalone copies of ``adcs report``/``export``/
``replay``/``sweep`` are gone (their one extra, ``export --topic``, moved into ``adcs``)."""
import importlib

import pytest

from adcs_nodes.tools import cli
from replay_bag import write_small_bag

CAMPAIGN = {'--runs', '--jobs', '--scheduler', '--dask-local', '--out', '--duration', '--seed',
            '--max-rate-deg-s', '--capture-deg', '--mag-bias-nT', '--misalignment-deg'}
OPTIONS = {
    'run': {'--record', '--duration', '--real-time', '--rate', '--engine', '--compose',
            '--domain', '--report', '--quiet', '--set'},
    'switch': {'--run'}, 'status': {'--run', '--watch'},
    'slew': {'--to', '--frame', '--controller', '--tolerance-deg', '--timeout-s', '--run'},
    'fault': {'--at', '--param', '--run'},
    'export': {'--csv', '--topic'}, 'report': {'--out'},
    'replay': {'--topics', '--rate', '--time-offset', '--now', '--no-clock', '--wait',
               '--start', '--duration', '--lockstep', '--nodes', '--write-params',
               '--stall-timeout', '--plugin'},
    'montecarlo': CAMPAIGN | {'--auto-detumble', '--bdot-gain', '--engine', '--compose'},
    'sweep': CAMPAIGN | {'--set', '--table'},
    'compare': CAMPAIGN | {'--controllers'},
    'list': {'--dir'}, 'validate': set(), 'schema': set(),
}


def _help(capsys, *argv):
    with pytest.raises(SystemExit) as info:
        cli.main([*argv, '--help'])
    assert info.value.code == 0
    return capsys.readouterr().out


def test_every_command_is_in_the_top_help(capsys):
    text = _help(capsys)
    for command in OPTIONS:
        assert f'    {command}' in text, command


@pytest.mark.parametrize('command', sorted(OPTIONS))
def test_each_command_help_lists_every_option(capsys, command):
    text = _help(capsys, command)
    missing = [o for o in OPTIONS[command] if f'{o} ' not in text and f'{o}\n' not in text
               and f'{o}=' not in text]
    assert not missing, f'adcs {command} --help misses {missing}'


def test_the_standalone_copies_are_gone():
    for module in ('analyse.report', 'analyse.export', 'analyse.report_html',
                   'campaigns.sweep', 'replay'):
        assert not hasattr(importlib.import_module(f'adcs_nodes.tools.{module}'), 'main')


def test_export_selects_topics(tmp_path, capsys):
    bag = write_small_bag(tmp_path / 'bag')
    assert cli.main(['export', bag, '--csv', str(tmp_path / 'csv'), '--topic', '/clock']) == 0
    assert sorted(p.name for p in (tmp_path / 'csv').iterdir()) == ['clock.csv']
