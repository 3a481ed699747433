"""Crash safety of a launched graph: a killed launcher, a full disk.

The truth is the operating system's view (which processes exist) and the bag read back with
the analysis tools. Each test runs the real ``adcs`` command with ``HOME`` in a temporary
directory (its run directories and manifests stay there) and waits for conditions with
deadlines, never fixed sleeps.
"""
import os
import signal
import subprocess
import sys
import time

import pytest

from adcs_launch import ROOT, SCENARIOS, wait_manifest

pytestmark = pytest.mark.ros

FREE_TUMBLE = os.path.join(SCENARIOS, 'free_tumble.yaml')
#: Longer than any test: the run never ends by itself (whole 1 s frames, before 2038).
LONG_S = '500000'


def _env(home):
    env = dict(os.environ, HOME=str(home))
    env.pop('ADCS_RUNS_DIR', None)     # the run directories under HOME, as a user's
    env.pop('XDG_RUNTIME_DIR', None)   # domain locks in <tmp>/adcs-domain-locks-<uid>
    return env


def _start(home, *args):
    return subprocess.Popen([sys.executable, '-m', 'adcs_nodes.tools.cli', *args], cwd=ROOT,
                            env=_env(home), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)


def _alive(pid: int) -> bool:
    """Whether ``pid`` is a live process (a zombie waiting for its reaper counts as dead)."""
    try:
        with open(f'/proc/{pid}/stat') as fh:
            state = fh.read().rsplit(')', 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ('Z', 'X')


def _wait(predicate, timeout, what):
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f'timed out after {timeout} s waiting for {what}')
        time.sleep(0.05)


def _states_in(bag) -> int:
    """Number of ``/sim/state`` messages the (unfinished) bag holds now, 0 if none yet."""
    from adcs_nodes.bag import read_messages
    try:
        return sum(1 for _ in read_messages(bag, topics=['/sim/state']))
    except (OSError, ValueError):
        return 0


def _manifest(proc, home):
    import adcs_launch
    saved = adcs_launch.RUNS
    adcs_launch.RUNS = os.path.join(str(home), '.cache', 'adcs', 'runs')
    try:
        return wait_manifest(proc, timeout=120.0)
    finally:
        adcs_launch.RUNS = saved


def _kill_group(proc):
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


@pytest.mark.parametrize('mode', [[], ['--compose']], ids=['process_per_node', 'composed'])
def test_sigkill_of_the_launcher_leaves_no_node_and_a_readable_bag(tmp_path, mode):
    from adcs_nodes.bag import read_messages

    bag = tmp_path / 'bag'
    proc = _start(tmp_path, 'run', FREE_TUMBLE, '--duration', LONG_S, '--record', str(bag),
                  '--quiet', *mode)
    pids = {}
    try:
        manifest = _manifest(proc, tmp_path)
        pids = manifest['pids']
        assert len(pids) == (1 if mode else 3)
        _wait(lambda: _states_in(bag) >= 20, 120.0, 'the recorder writing 20 states')
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        _wait(lambda: not any(_alive(p) for p in pids.values()), 60.0,
              f'every node to die with its launcher ({pids})')
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for pid in pids.values():
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
    # the recorder got SIGTERM (parent-death signal) and finished the bag
    assert (bag / 'metadata.yaml').is_file()
    stamps = [t for topic, t, _ in read_messages(bag, topics=['/sim/state'])]
    assert len(stamps) > 10
    assert stamps == sorted(stamps)


def _mount_tmpfs(path, size='256k'):
    path.mkdir()
    try:
        res = subprocess.run(['mount', '-t', 'tmpfs', '-o', f'size={size},mode=0700', 'tmpfs',
                              str(path)], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired) as exc:
        pytest.skip(f'cannot mount a tmpfs here: {exc}')
    if res.returncode != 0:
        pytest.skip(f'cannot mount a tmpfs here (needs root): {res.stderr.strip()}')


@pytest.mark.parametrize('mode', [[], ['--compose']], ids=['process_per_node', 'composed'])
def test_disk_full_stops_the_run_says_so_and_keeps_the_data(tmp_path, mode):
    """The bag on a 256 KiB tmpfs: the run stops by itself with exit 1 and 'disk full', no
    traceback anywhere, and the bag reads back with the frames written before."""
    from adcs_nodes.bag import read_messages

    disk = tmp_path / 'disk'
    _mount_tmpfs(disk)
    try:
        bag = disk / 'bag'
        proc = _start(tmp_path, 'run', FREE_TUMBLE, '--duration', LONG_S, '--record',
                      str(bag), '--quiet', *mode)
        try:
            out, err = proc.communicate(timeout=120)
        finally:
            if proc.poll() is None:
                _kill_group(proc)
                proc.wait()
        assert proc.returncode == 1, (out, err)
        assert 'disk full' in err, err
        assert 'Traceback' not in out + err, err
        run_dir = max((tmp_path / '.cache' / 'adcs' / 'runs').glob('2*'),
                      key=os.path.getmtime)
        rec_log = (run_dir / 'logs' / ('composed.log' if mode else 'recorder.log')).read_text()
        assert 'Traceback' not in rec_log, rec_log[-2000:]
        assert 'disk full' in rec_log
        states = [msg for _, _, msg in read_messages(bag, topics=['/sim/state'])]
        assert len(states) > 10
        stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in states]
        assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
    finally:
        subprocess.run(['umount', '-l', str(disk)], capture_output=True, timeout=10)


def test_sigkill_of_the_recorder_stops_the_run_and_export_and_report_read_the_bag(
        tmp_path):
    """The recorder killed with SIGKILL mid-run: the launcher stops the run naming it, and
    ``adcs export`` / ``adcs report`` read the unfinished bag (every state up to at most a
    few seconds of sim time before the kill)."""
    import csv

    from adcs_nodes.bag import read_messages

    bag = tmp_path / 'bag'
    proc = _start(tmp_path, 'run', FREE_TUMBLE, '--duration', LONG_S, '--record', str(bag),
                  '--quiet')
    try:
        pids = _manifest(proc, tmp_path)['pids']
        _wait(lambda: _states_in(bag) >= 20, 120.0, 'the recorder writing 20 states')
        os.kill(pids['recorder'], signal.SIGKILL)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            _kill_group(proc)
            proc.wait()
    assert proc.returncode == 1, (out, err)
    assert 'node recorder exited with code -9' in err, err
    assert not (bag / 'metadata.yaml').exists()
    states = [m for _, _, m in read_messages(bag, topics=['/sim/state'])]
    assert len(states) > 10
    env = _env(tmp_path)
    csv_dir = tmp_path / 'csv'
    res = subprocess.run([sys.executable, '-m', 'adcs_nodes.tools.cli', 'export', str(bag),
                          '--csv', str(csv_dir)], env=env, capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    assert 'unfinished bag' in res.stderr
    with open(csv_dir / 'sim__state.csv') as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(states)
    res = subprocess.run([sys.executable, '-m', 'adcs_nodes.tools.cli', 'report', str(bag),
                          '--out', str(tmp_path / 'report')], env=env, capture_output=True,
                         text=True, timeout=180)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / 'report' / 'summary.md').is_file()


def test_a_node_refusing_its_configuration_makes_the_run_exit_2(tmp_path, monkeypatch):
    """A node exiting with code 2 (configuration error) ends the run with exit code 2."""
    from adcs_nodes.tools.run import launcher
    from adcs_nodes.tools.run.launcher import isolation
    from adcs_nodes.scenario import load_scenario

    monkeypatch.setattr(isolation, 'RUNS_DIR', str(tmp_path / 'runs'))
    bag = tmp_path / 'bag'
    run = launcher.Launcher(load_scenario(FREE_TUMBLE), duration_s=10.0, progress=False,
                            log=lambda *a: None, record=str(bag))
    refuse = [sys.executable, '-c', f'import os, sys, time\nwhile not os.path.isdir('
              f'{str(bag)!r}): time.sleep(0.01)\nprint("bad parameter"); sys.exit(2)']
    wait = [sys.executable, '-c', 'import signal; signal.pause()']   # until the launcher stops it
    recorder = [sys.executable, '-c', f'import os, signal; os.mkdir({str(bag)!r}); '
                'signal.pause()']                   # creates its bag at start, as the recorder
    monkeypatch.setattr(run, '_commands', lambda params: {
        'environment': wait, 'dynamics': wait, 'magnetometer': refuse, 'recorder': recorder})
    result = run.run()
    assert result.exit_code == 2, result.message
    assert 'magnetometer refused its configuration' in result.message
    assert result.bag is None and not bag.exists()    # no bag: line for a run that never ran
    assert 'bad parameter' in result.message
