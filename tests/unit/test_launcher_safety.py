"""Launcher safety without starting a graph: domain locks, run directories, bad run inputs.

The truth is the file system (modes, link targets, contents) and the documented limits.
"""
import json
import os
import stat

import pytest

from adcs_nodes.tools.run.launcher import isolation as launcher
from adcs_nodes.tools.run.launcher import result
from adcs_nodes.tools.run.launcher import LaunchError, Launcher, acquire_domain
from adcs_nodes.tools.run.launcher.isolation import prune_runs
from adcs_nodes.scenario import load_scenario

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FREE_TUMBLE = os.path.join(ROOT, 'scenarios', 'free_tumble.yaml')


@pytest.fixture
def lock_dir(tmp_path, monkeypatch):
    path = tmp_path / 'locks'
    monkeypatch.setattr(launcher, 'domain_lock_dir', lambda: str(path))
    return path


def test_planted_symlink_is_not_followed(lock_dir):
    lock_dir.mkdir(mode=0o700)
    victim = lock_dir.parent / 'victim.txt'
    victim.write_text('precious')
    os.symlink(victim, lock_dir / '7.lock')
    with pytest.raises(LaunchError, match='no free ROS_DOMAIN_ID'):
        acquire_domain([7])
    dom, fh = acquire_domain([7, 8])
    try:
        assert dom == 8
    finally:
        fh.close()
    assert victim.read_text() == 'precious'
    assert os.readlink(lock_dir / '7.lock') == str(victim)


def test_lock_dir_is_private_and_a_planted_dir_symlink_is_refused(lock_dir):
    dom, fh = acquire_domain([5])
    fh.close()
    assert stat.S_IMODE(os.stat(lock_dir).st_mode) == 0o700
    assert stat.S_IMODE(os.stat(lock_dir / '5.lock').st_mode) == 0o600
    os.rename(lock_dir, lock_dir.parent / 'elsewhere')
    os.symlink(lock_dir.parent / 'elsewhere', lock_dir)
    with pytest.raises(LaunchError, match='not a directory owned by you'):
        acquire_domain([5])


def test_default_lock_dir_is_per_user(monkeypatch):
    monkeypatch.delenv('XDG_RUNTIME_DIR', raising=False)
    assert launcher.domain_lock_dir().endswith(f'adcs-domain-locks-{os.getuid()}')


def test_domains_are_many_valid_and_drawn_at_random(lock_dir):
    ids = launcher.RUN_DOMAINS
    assert len(set(ids)) > 100
    assert all(1 <= d <= 232 for d in ids)                 # Fast DDS on UDP: 0..232
    assert not any(100 <= d <= 199 for d in ids)           # the unlocked test domains
    assert not any(102 <= d <= 214 for d in ids)           # ports in the ephemeral range
    held = [acquire_domain() for _ in range(8)]
    try:
        got = [d for d, _ in held]
        assert len(set(got)) == 8                          # claimed: never shared
        assert got != sorted(got)                          # not handed out in order
    finally:
        for _, fh in held:
            fh.close()


def test_prune_keeps_the_newest_and_the_active_runs(tmp_path):
    runs = tmp_path / 'runs'
    runs.mkdir()
    made = []
    for i in range(60):
        d = runs / f'20260101T{i:06d}-scenario_{i}-{1000 + i}'
        d.mkdir()
        (d / 'params.yaml').write_text('x')
        os.utime(d, (1e9 + i, 1e9 + i))
        made.append(d)
    (runs / 'keep-me').mkdir()                             # not a run directory: untouched
    (runs / 'active-1.json').write_text(json.dumps({'pid': os.getpid(),
                                                    'run_dir': str(made[0])}))
    (runs / 'active-2.json').write_text(json.dumps({'pid': 2**22 + 1,   # above pid_max: dead
                                                    'run_dir': str(made[1])}))
    removed = prune_runs(str(runs), keep=50)
    assert sorted(removed) == sorted(str(d) for d in made[1:10])
    left = {p.name for p in runs.iterdir()}
    assert {d.name for d in made[10:]} | {made[0].name, 'keep-me', 'active-1.json',
                                          'active-2.json'} == left


def test_private_files_and_dirs(tmp_path):
    d = tmp_path / 'run'
    d.mkdir(mode=0o755)
    os.chmod(d, 0o755)
    launcher.private_dir(str(d))
    assert stat.S_IMODE(os.stat(d).st_mode) == 0o700
    f = d / 'active-1.json'
    launcher.write_private(str(f), '{"domain": 5}')
    assert stat.S_IMODE(os.stat(f).st_mode) == 0o600
    assert json.loads(f.read_text()) == {'domain': 5}


@pytest.mark.parametrize('change, message', [
    ({'name': '../../escape'}, 'names the run directory'),
    ({'name': 'a/b'}, 'names the run directory'),
    ({'epoch': 'not-a-date'}, 'ISO-8601'),
    ({'epoch': '2037-12-31T00:00:00Z'}, '2038'),
])
def test_launcher_refuses_bad_runs(change, message):
    sc = dict(load_scenario(FREE_TUMBLE), **change)
    with pytest.raises(LaunchError, match=message):
        Launcher(sc, duration_s=86400 * 30, progress=False)


@pytest.mark.parametrize('duration', [float('inf'), float('nan'), -1.0, 0.0])
def test_launcher_refuses_non_finite_durations(duration):
    with pytest.raises(LaunchError, match=r'--duration .*duration_s: (expected a finite|must '
                       'be > 0)'):
        Launcher(load_scenario(FREE_TUMBLE), duration_s=duration, progress=False)


def test_a_fault_after_a_duration_override_is_refused_up_front():
    """Issue 38 item 7: a scripted fault after the end of a shortened run never strikes;
    the launcher says so before it starts anything (the validator's check, named for
    ``--duration``)."""
    sc = load_scenario(os.path.join(ROOT, 'scenarios', 'paper000_estimation.yaml'))
    sc = dict(sc, faults=[{'index': 0, 'kind': 'dropout', 'target': 'magnetometer',
                           'at_s': 50.0, 'params': {'duration_s': 5.0}}])
    with pytest.raises(LaunchError, match=r'^--duration 20: faults\[0\]\.at_s: 50 s is '
                       r'outside the run \[0, 20\] s'):
        Launcher(sc, duration_s=20.0, progress=False)
    assert Launcher(sc, duration_s=60.0, progress=False).duration_s == 60.0


@pytest.mark.parametrize('engine', ['plain', 'composed', 'graph'])
def test_adcs_run_refuses_a_fault_after_a_duration_override(tmp_path, capsys, engine):
    import yaml

    from adcs_nodes.tools import cli
    with open(os.path.join(ROOT, 'scenarios', 'paper000_estimation.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['faults'] = [{'kind': 'dropout', 'target': 'magnetometer', 'at_s': 50.0}]
    path = tmp_path / 'late_fault.yaml'
    path.write_text(yaml.safe_dump(sc))
    assert cli.main(['run', str(path), '--engine', engine, '--duration', '20', '--record',
                     str(tmp_path / 'bag')]) == 2
    err = capsys.readouterr().err
    assert 'adcs run: --duration 20: faults[0].at_s: 50 s is outside the run' in err, err
    assert not (tmp_path / 'bag').exists()
    from adcs_nodes.scenario import ScenarioError
    from adcs_nodes.tools.run.launch_graph import launch_graph
    with pytest.raises(ScenarioError, match='--duration 20: faults'):   # ros2 launch duration:=
        launch_graph(str(path), duration_s=20.0)


def test_a_100_kB_controller_name_is_refused_unsent_and_not_echoed():
    from adcs_nodes.tools.run.live import LiveError, switch
    with pytest.raises(LiveError) as info:
        switch('x' * 100_000, pid=1)
    assert len(str(info.value)) < 300
    assert '100000 characters' in str(info.value)


def test_save_scenario_on_a_full_disk_reports_and_keeps_the_bag(tmp_path, monkeypatch):
    import errno
    bag = tmp_path / 'bag'
    run = Launcher(load_scenario(FREE_TUMBLE), duration_s=10.0, record=str(bag),
                   progress=False, run_dir=str(tmp_path / 'run'))
    bag.mkdir()
    (bag / 'bag.mcap').write_bytes(b'data')

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(result.yaml, 'safe_dump', full)
    message = result.save_scenario(run.sc, run.record, run.duration_s)
    assert 'disk full' in message and 'the bag is kept' in message
    assert sorted(p.name for p in bag.iterdir()) == ['bag.mcap']   # no cut scenario.yaml


@pytest.mark.parametrize('rate', [float('inf'), float('nan'), 0.0, -2.0, 1e9])
def test_launcher_refuses_absurd_real_time_rates(rate):
    with pytest.raises(LaunchError, match='--rate'):
        Launcher(load_scenario(FREE_TUMBLE), duration_s=10.0, real_time=True,
                 rate_factor=rate, progress=False)
