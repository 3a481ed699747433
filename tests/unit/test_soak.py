"""``adcs soak`` without ROS: outcome classification of launcher output, and the bounded loop
with fake launcher commands (small Python scripts that exit 0, die by a signal, hang, ignore
SIGINT, or print the launcher's start-timeout lines)."""
import os
import sys
import textwrap
import time

import pytest

from perf import soak
from perf.soak import Soak, classify


def _run_dir(tmp_path, logs):
    run_dir = tmp_path / 'run'
    (run_dir / 'logs').mkdir(parents=True)
    for name, text in logs.items():
        (run_dir / 'logs' / f'{name}.log').write_text(text)
    return str(run_dir)


def test_finished_and_healed():
    out = '[adcs] run x: 2 nodes, logs in /r/logs\n[adcs] done\n[adcs] 3 s sim in 5.0 s wall\n'
    assert classify(0, out)[0] == 'finished'
    healed = out.replace('[adcs] done', '[adcs] restarting node guidance: unmatched\n'
                         '[adcs] done (restarts: 1: guidance)')
    outcome, _, _, restarts = classify(0, healed)
    assert (outcome, restarts) == ('healed', 1)
    # the launcher's words (soak I): the nodes restarted and the first one's reason
    two = out.replace('[adcs] done', (
        '[adcs] restarting node guidance before frame 0 (restart 1 of at most 1): its '
        'endpoints stayed unmatched for 30 s while every other node was ready: sub:/clock 0/1 '
        '(discovery knows 0)\n[adcs] restarting node dynamics before frame 0 (restart 1 of '
        'at most 1): it accepts guidance\'s messages only from the publisher it locked\n'
        '[adcs] done\n[adcs] restarts: 2 before frame 0 (self-healing: ...)'))
    outcome, detail, _, restarts = classify(0, two)
    assert (outcome, restarts) == ('healed', 2)
    assert detail.startswith('restarted guidance, dynamics; guidance: its endpoints stayed '
                             'unmatched') and detail.endswith('(discovery knows 0)'), detail


def test_start_timeout_names_the_unmatched_endpoints_and_what_discovery_knew(tmp_path):
    run_dir = _run_dir(tmp_path, {
        'guidance': '[WARN] still waiting for endpoints after 10 s: sub:/clock 0/1 '
                    '(discovery knows 0)\n[WARN] still waiting for endpoints after 21 s: '
                    'sub:/clock 0/1 (discovery knows 0)\n',
        'dynamics': '[ERROR] lockstep not started after 120 s: no ready from guidance '
                    '(did a node die during start-up?)\n',
        'environment': 'fine\n'})
    out = (f'[adcs] run x: logs in {run_dir}/logs\n[adcs] node dynamics exited with code 1 '
           'before the end of the run; last lines of its log:\n[ERROR] lockstep not started '
           'after 120 s: no ready from guidance (did a node die during start-up?)\n')
    outcome, detail, sig, _ = classify(1, out, run_dir)
    assert outcome == 'start_timeout' and not sig
    assert detail.startswith('no ready from guidance')
    assert 'guidance: sub:/clock 0/1 (discovery knows 0)' in detail
    assert 'environment' not in detail
    # the master's line only in its log (the launcher's tail cut it): found there too
    outcome, detail, _, _ = classify(1, f'logs in {run_dir}/logs\nnode dynamics exited', run_dir)
    assert outcome == 'start_timeout'


def test_lifecycle_timeout_crash_and_other_failures():
    out = ('[adcs] node estimator was not active 120 s after its start (lifecycle: configure); '
           'last lines of its log')
    assert classify(1, out)[:2] == ('lifecycle_timeout',
                                    'estimator not active (lifecycle: configure)')
    out = ('[adcs] node bdot_controller exited with code -11 during start-up (the lockstep '
           'cannot start without it)')
    assert classify(1, out)[0::2] == ('crash', 'SIGSEGV')
    assert classify(-6, '')[0::2] == ('crash', 'SIGABRT')
    # a flight-software node lost to a signal makes a degraded run (3): still a crash
    assert classify(3, '[adcs] WARNING: node gyro exited with code -9; the graph goes on')[0] \
        == 'crash'
    out = 'Fatal Python error: Segmentation fault\n\nCurrent thread ...\n'
    assert classify(1, out)[0::2] == ('crash', 'SIGSEGV')
    out = ('[adcs] node environment exited with code 1 before the end of the run\n'
           '[adcs] 0 s sim in 3.0 s wall (0.0x real time), missed frames 0\n')
    outcome, detail, _, _ = classify(1, out)
    assert outcome == 'failed' and detail.startswith('[adcs] node environment exited')


def test_hang_and_cut():
    assert classify(None, '', timed_out=True)[:2] == ('hang',
                                                      'killed after its deadline (before the end)')
    assert classify(None, '[adcs] 3 s sim in 4.0 s wall', timed_out=True)[1].endswith(
        '(at teardown)')
    assert classify(None, '', timed_out=True, finished_frames=True)[1].endswith('(at teardown)')
    assert classify(None, '', cut=True)[0] == 'cut'


# ------------------------------------------------------------------ the loop, fake launchers
FAKE = textwrap.dedent('''\
    import os, signal, sys, time
    kind, run_dir = sys.argv[1], sys.argv[2]
    os.makedirs(os.path.join(run_dir, 'logs'), exist_ok=True)
    print(f'[adcs] run fake: 3 nodes, logs in {run_dir}/logs', flush=True)
    if kind == 'ok':
        print('[adcs] done'); print('[adcs] 3 s sim in 1.0 s wall')
    elif kind == 'segv':
        os.kill(os.getpid(), signal.SIGSEGV)
    elif kind == 'hang':
        time.sleep(1000)
    elif kind == 'stubborn':            # ignores SIGINT: killed after the grace
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        time.sleep(1000)
    elif kind == 'start_timeout':
        with open(os.path.join(run_dir, 'logs', 'guidance.log'), 'w') as fh:
            fh.write('still waiting for endpoints after 10 s: sub:/clock 0/1 '
                     '(discovery knows 0)\\n')
        print('[adcs] node dynamics exited with code 1 before the end of the run; last lines')
        print('lockstep not started after 120 s: no ready from guidance')
        sys.exit(1)
    ''')


def _soak(tmp_path, kinds, **kw):
    script = tmp_path / 'fake_adcs.py'
    script.write_text(FAKE)
    counter = iter(range(10 ** 6))

    def command(scenario, mode, duration_s):
        kind = kinds[next(counter) % len(kinds)]
        return [sys.executable, str(script), kind, str(tmp_path / f'run{time.monotonic_ns()}')]
    scen = tmp_path / 'free_tumble.yaml'
    scen.write_text('timing:\n  frame_s: 2.0\n')
    kw.setdefault('burners', 0)
    return Soak([str(scen)], out=str(tmp_path / 'out'), command=command, log=lambda s: None,
                **kw)


def test_the_loop_counts_each_kind_keeps_failure_logs_and_writes_the_table(tmp_path):
    s = _soak(tmp_path, ['ok', 'segv', 'start_timeout', 'hang'], launches=4,
              run_deadline_s=2.0, grace_s=1.0)
    res = s.run()
    assert [r.outcome for r in res] == ['finished', 'crash', 'start_timeout', 'hang']
    assert [r.mode for r in res] == ['processes', 'composed', 'processes', 'composed']
    assert res[1].signal == 'SIGSEGV'
    assert 'discovery knows 0' in res[2].detail
    assert res[0].kept == ''
    for r in res[1:]:
        assert os.path.isfile(os.path.join(r.kept, 'adcs_run.out'))
    assert os.path.isfile(os.path.join(res[2].kept, 'run', 'logs', 'guidance.log'))
    table = (tmp_path / 'out' / 'summary.md').read_text()
    assert '| total | 4 | 1 | 0 | 1 | 0 | 1 | 1 | 0 | 0 | 0 |' in table
    assert len((tmp_path / 'out' / 'soak.csv').read_text().splitlines()) == 5
    assert s.failed == 3


def test_the_loop_stops_at_the_launch_count(tmp_path):
    res = _soak(tmp_path, ['ok'], launches=3, burners=1).run()
    assert len(res) == 3 and all(r.outcome == 'finished' for r in res)


def test_the_loop_stops_within_its_time_budget_even_with_stubborn_hangs(tmp_path):
    s = _soak(tmp_path, ['stubborn'], launches=100, time_budget_s=3.0, run_deadline_s=100.0,
              grace_s=1.0)
    t0 = time.monotonic()
    res = s.run()
    took = time.monotonic() - t0
    assert took < 3.0 + 1.0 + 5.0 + 3.0     # budget + grace + SIGKILL wait + slack
    assert [r.outcome for r in res] == ['cut']
    assert s.failed == 0


def test_burners_are_started_and_stopped():
    with soak.Burners(2) as b:
        pids = [p.pid for p in b.procs]
        assert all(p.poll() is None for p in b.procs)
    for pid in pids:
        with pytest.raises(OSError):
            os.kill(pid, 0)       # reaped: gone


def test_cli_arguments_are_checked(tmp_path, capsys):
    main = soak.main
    assert main(['--launches', '0']) == 2
    assert main(['--env', 'NOEQUALS', '--launches', '1']) == 2
    assert main(['--scenarios', str(tmp_path / 'nope.yaml')]) == 2
    script = tmp_path / 'fake_adcs.py'
    script.write_text(FAKE)
    scen = tmp_path / 's.yaml'
    scen.write_text('timing:\n  frame_s: 1.0\n')
    code = main(['--launches', '2', '--burners', '0', '--scenarios', str(scen),
                 '--out', str(tmp_path / 'o'), '--launcher-cmd',
                 f'{sys.executable} {script} ok {tmp_path}/r-{{mode}}'])
    assert code == 0
    out = capsys.readouterr().out
    assert '| total | 2 | 2 |' in out


def test_discovery_probe_table():
    trials = [[(3, 3, 0.2), (3, 3, 0.4), (3, 3, 3.1)], [(3, 3, 0.3), (2, 2, -1.0), (3, 3, 0.1)]]
    table = soak.discovery_table('P', 3, trials, 2, {'K': 'v'})
    assert '2 trials of 3 participants' in table and 'env K=v' in table
    assert '| 6 | 1 | 1 | 0.30 s | 0.40 s | 3.10 s |' in table


def test_an_env_value_with_launch_is_one_value_per_launch():
    base = {'PATH': '/bin', 'NUMBA_CACHE_DIR': '/home/cache'}
    env = soak.launch_env(base, {'NUMBA_CACHE_DIR': '/tmp/cold/{launch}', 'A': 'b'}, 7)
    assert env == {'PATH': '/bin', 'NUMBA_CACHE_DIR': '/tmp/cold/7', 'A': 'b'}
    assert base['NUMBA_CACHE_DIR'] == '/home/cache'       # the base is not changed
