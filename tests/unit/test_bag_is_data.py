"""A bag is data, never code (issue 38 item 2, docs/security.md).

A bag whose ``scenario.yaml`` is hostile (an alias bomb, a plugin path, a syntax error, a
list) gives one line and no traceback within 5 s from ``adcs report``, ``adcs export`` and
``adcs replay``, and no plugin is imported: the test plugin writes a marker file when it is
imported. A plugin is imported only when the user gives it (``adcs replay --plugin``).
``adcs report`` exits non-zero on a bag with nothing to report. In process (``cli.main``),
before any rclpy node is made.
"""
import os
import time

import pytest
import yaml
from replay_bag import write_small_bag
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from adcs_nodes.scenario import load_scenario
from adcs_nodes.tools import cli

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BOMB = 'a: &a ["x","x","x","x","x","x","x","x","x"]\n' + ''.join(
    f'{c}: &{c} [*{p},*{p},*{p},*{p},*{p},*{p},*{p},*{p},*{p}]\n'
    for p, c in zip('abcdefgh', 'bcdefghi')) + 'name: *i\n'
PLUGIN = ('import os\n'
          'open(os.environ["ADCS_TEST_PLUGIN_MARKER"], "w").write("imported")\n')


@pytest.fixture
def marker(tmp_path, monkeypatch):
    path = tmp_path / 'plugin_was_imported'
    monkeypatch.setenv('ADCS_TEST_PLUGIN_MARKER', str(path))
    return path


def _effective(plugins):
    """The effective scenario ``adcs run`` stores beside a bag, naming ``plugins``."""
    sc = load_scenario(os.path.join(ROOT, 'scenarios', 'paper000_estimation.yaml'))
    return yaml.safe_dump({**{k: v for k, v in sc.items() if not k.startswith('_')},
                           'plugins': plugins}, sort_keys=False)


def _bag(tmp_path, text):
    bag = write_small_bag(tmp_path / 'bag')
    with open(os.path.join(bag, 'scenario.yaml'), 'w', encoding='utf-8') as fh:
        fh.write(text)
    return bag


def _adcs(capsys, *argv):
    t0 = time.monotonic()
    code = cli.main(list(argv))
    out = capsys.readouterr()
    return code, out.err, time.monotonic() - t0


HOSTILE = {'alias bomb': (BOMB, 'YAML nodes'),
           'syntax error': ('name: [unclosed\nseed: 1\n', 'YAML syntax error'),
           'a list': ('- name: x\n- seed: 1\n', 'not a scenario (a YAML mapping) but list'),
           'plugins not a list': ('name: x\nplugins: evil.py\n', 'plugins: expected a list')}


@pytest.mark.parametrize('case', sorted(HOSTILE))
def test_a_hostile_scenario_yaml_is_one_line_exit_2_everywhere(tmp_path, capsys, marker, case):
    text, reason = HOSTILE[case]
    bag = _bag(tmp_path, text)
    for argv in (('report', bag, '--out', str(tmp_path / 'rep')),
                 ('export', bag, '--csv', str(tmp_path / 'csv')),
                 ('replay', bag), ('replay', bag, '--lockstep'),
                 ('replay', bag, '--lockstep', '--write-params', str(tmp_path / 'p.yaml'))):
        code, err, wall = _adcs(capsys, *argv)
        assert code == 2, (argv, err)
        assert err.count('\n') == 1 and reason in err and 'a bag is data' in err, (argv, err)
        assert err.startswith(f'adcs {argv[0]}: ') and wall < 5.0, (argv, err, wall)
    assert not (tmp_path / 'rep').exists() and not (tmp_path / 'csv').exists()


def test_the_plugins_of_a_bag_are_named_never_imported(tmp_path, capsys, marker):
    plugin = tmp_path / 'evil_plugin.py'
    plugin.write_text(PLUGIN)
    bag = _bag(tmp_path, _effective([str(plugin)]))
    for argv in (('replay', bag, '--lockstep'),
                 ('replay', bag, '--write-params', str(tmp_path / 'p.yaml'))):
        code, err, wall = _adcs(capsys, *argv)
        assert code == 2 and err.count('\n') == 1 and wall < 5.0, (argv, err)
        # (a long path is shortened in the one-line message: its file name stays)
        assert 'the run used the plugins ' in err and plugin.name in err, err
        assert '--plugin' in err, err
    for argv in (('report', bag, '--out', str(tmp_path / 'rep')),
                 ('export', bag, '--csv', str(tmp_path / 'csv'))):
        code, err, wall = _adcs(capsys, *argv)     # they need no plugin: they say so, go on
        assert code == 0, (argv, err)
        assert 'the run used the plugins ' in err and plugin.name in err, err
        assert 'not imported (a bag is data' in err, err
    assert (tmp_path / 'rep' / 'summary.md').is_file() and (tmp_path / 'csv').is_dir()
    from adcs_nodes.tools.analyse.papers.series import scenario_dict
    from adcs_nodes.tools.bagfile import bag_scenario
    assert scenario_dict(bag_scenario(bag))['plugins'] == []   # validated again, without
    assert not marker.exists()
    # given by the user, it is theirs to trust: imported, the parameters written
    code, err, _ = _adcs(capsys, 'replay', bag, '--plugin', str(plugin), '--write-params',
                         str(tmp_path / 'p.yaml'))
    assert code == 0, err
    assert marker.read_text() == 'imported'
    assert str(plugin) in (tmp_path / 'p.yaml').read_text()


def test_report_of_a_bag_with_nothing_to_report_exits_non_zero(tmp_path, capsys):
    store = get_typestore(Stores.ROS2_KILTED)
    w = Writer(tmp_path / 'empty', version=8, storage_plugin=StoragePlugin.MCAP)
    w.open()
    w.add_connection('/sensors/magnetometer', 'sensor_msgs/msg/MagneticField',
                     typestore=store)
    w.close()
    code, err, _ = _adcs(capsys, 'report', str(tmp_path / 'empty'), '--out',
                         str(tmp_path / 'rep'))
    assert code == 2 and 'nothing to report' in err and 'Traceback' not in err, err


def test_an_oversized_scenario_is_refused_before_it_is_parsed(tmp_path, capsys):
    bag = _bag(tmp_path, 'name: x\n' + '#' * 1_000_001)
    code, err, _ = _adcs(capsys, 'report', bag)
    assert code == 2 and 'larger than 1000000 bytes' in err, err
