"""``adcs sweep`` without processes: the grid (values split at top-level commas, validated as
``adcs run --set`` validates them, exit 2 before any run), the metrics of a grid point from
hand-made results and series, and a tiny sweep on the FrameLoop run in this process (the
runs' process replaced by :func:`adcs_nodes.tools.campaigns.worker.mc_worker` called here),
interrupted by
Ctrl-C and resumed: the same table as a sweep that was never interrupted, and only the
missing runs run again."""
import csv
import math
import os

import numpy as np
import pytest
import yaml

from adcs_nodes.tools import cli
from adcs_nodes.tools.campaigns import campaign as campaign_mod
from adcs_nodes.tools.campaigns import sweep
from adcs_nodes.tools.campaigns.files import SERIES_FILE, load_result, run_dir_of
from adcs_nodes.scenario import ScenarioError
from frameloop_run import SCENARIOS

SCENARIO = os.path.join(SCENARIOS, 'paper000_control.yaml')
ALPHA = 'controllers.magnetic.alpha_per_s'
K = 'controllers.magnetic.k_Nms'


# ---------------------------------------------------------------------- the grid
def test_values_split_at_top_level_commas_only():
    assert sweep.split_values('1e-3, 2e-3,3e-3') == ['1e-3', '2e-3', '3e-3']
    assert sweep.split_values('[40, 40, 40],[60,60,60]') == ['[40, 40, 40]', '[60,60,60]']
    assert sweep.split_values('"a,b",c') == ['"a,b"', 'c']
    assert sweep.split_values('{x: 1, y: 2}') == ['{x: 1, y: 2}']
    for bad in ('1,,2', '1,', '[1,2', '1]', '"a,b'):
        with pytest.raises(sweep.SweepError):
            sweep.split_values(bad)


def test_grid_values_are_yaml_and_the_product_runs_the_last_key_fastest():
    grid = sweep.parse_grid([f'{ALPHA}=1.5e-3,2e-3', f'{K}=0.1,0.2,0.4',
                             'spacecraft.magnetorquer.max_dipole_Am2=[40,40,40]'])
    assert grid == [(ALPHA, [1.5e-3, 2e-3]), (K, [0.1, 0.2, 0.4]),
                    ('spacecraft.magnetorquer.max_dipole_Am2', [[40, 40, 40]])]
    pts = sweep.grid_points(grid)
    assert len(pts) == 6
    assert [(p[ALPHA], p[K]) for p in pts[:4]] == [(1.5e-3, 0.1), (1.5e-3, 0.2),
                                                   (1.5e-3, 0.4), (2e-3, 0.1)]
    assert sweep.swept_keys(grid) == [ALPHA, K]
    names = {sweep.point_name(p) for p in pts}
    assert len(names) == 6
    assert all(os.sep not in n and ' ' not in n for n in names)
    # the name is the value, exactly: 0.1 and '0.1' (a string) are two points
    assert sweep.point_name({K: 0.1}) != sweep.point_name({K: '0.1'})


@pytest.mark.parametrize('items, message', [
    ([], 'at least one --set'),
    ([f'{ALPHA}=1e-3', f'{ALPHA}=2e-3'], 'given twice'),
    ([f'{ALPHA}=1e-3,1e-3'], 'given twice'),
    ([f'{ALPHA}=1e-3,,2e-3'], 'empty value'),
    ([f'{ALPHA}1e-3'], 'KEY=VALUE'),
    ([f'{ALPHA}=[1,'], 'unbalanced'),
])
def test_bad_grids_are_refused(items, message):
    with pytest.raises((sweep.SweepError, ScenarioError), match=message):
        sweep.parse_grid(items)


@pytest.mark.parametrize('sets, message', [
    ([f'{ALPHA}=2e-3,3e-3', 'controllers.magnetic.gain=1'], 'unknown key'),
    ([f'{ALPHA}=2e-3,-3e-3'], 'must be > 0'),
    ([f'{ALPHA}=2e-3,fast'], 'alpha_per_s'),
    ([f'{K}=0.2', f'{K}=0.3'], 'given twice'),
    (['controllers.magnetic.alpha_per_s=2e-3', 'timing.frame_s=3'], 'frame'),
])
def test_the_command_exits_2_before_any_run(sets, message, tmp_path, capsys):
    out = tmp_path / 'sw'
    argv = ['sweep', SCENARIO, '--runs', '1', '--duration', '4', '--out', str(out)]
    for s in sets:
        argv += ['--set', s]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith('adcs sweep: ') and message in err, err
    assert not (out / 'points').exists()


def test_bad_campaign_arguments_exit_2(tmp_path, capsys):
    base = ['sweep', SCENARIO, '--set', f'{ALPHA}=2e-3', '--out', str(tmp_path / 'sw')]
    assert cli.main(base + ['--runs', '0']) == 2
    assert '--runs must be in [1, 100000], got 0' in capsys.readouterr().err
    assert cli.main(base + ['--runs', '1', '--duration', '3']) == 2
    assert 'whole number' in capsys.readouterr().err


# ---------------------------------------------------------------------- metrics of a point
def _res(status, cap=None, in_time=False, hold=None, conv=None, est=True, err=None, conv5=0.0):
    return {'status': status, 'capture_time_s': cap, 'captured_in_time': in_time,
            'hold_median_deg': hold, 'converged_s': conv, 'converged_5deg_s': conv5,
            'has_estimate': est, 'est_err_median_deg': err, 'wall_time_s': 10.0}


def test_point_metrics_count_what_the_table_says():
    period = 1000.0
    results = [_res('captured', 2000.0, True, 1.0, 100.0, err=0.5),
               _res('captured', 3000.0, True, 2.0, 500.0, err=1.5),   # T/2 exactly: in
               _res('captured', 5000.0, False, 3.0, 501.0, err=2.5),  # captured late
               _res('not_captured', None, False, 40.0, None, err=30.0, conv5=None),
               {'status': 'error', 'message': 'boom'}]                 # not counted
    m = sweep.point_metrics(results, runs=6, period_s=period)
    assert (m['runs'], m['done'], m['captured'], m['in_4_orbits']) == (6, 4, 3, 2)
    assert m['in_4_orbits_pct'] == 50.0
    assert m['capture_median_orbits'] == 3.0
    assert m['hold_median_of_medians_deg'] == 2.5                  # median of 1, 2, 3, 40
    assert (m['converged_half_orbit'], m['converged_half_orbit_pct']) == (2, 50.0)
    assert math.isinf(m['converge_p90_orbits'])                    # one run never converged
    assert (m['converged_5deg_half_orbit'], m['converged_5deg_half_orbit_pct']) == (3, 75.0)
    assert m['est_err_median_deg'] == 2.0
    empty = sweep.point_metrics([], runs=3, period_s=period)
    assert empty['done'] == 0 and empty['in_4_orbits_pct'] is None
    assert empty['converged_half_orbit'] is None
    # without an estimate (ideal knowledge) the convergence column says nothing
    ideal = sweep.point_metrics([_res('captured', 10.0, True, 1.0, None, est=False)], 1,
                                period)
    assert ideal['converged_half_orbit'] is None


def test_convergence_is_read_from_the_run_series(tmp_path):
    period = 80.0
    t = np.arange(0.0, 200.0, 2.0)
    err = np.where(t < 30.0, 30.0, 1.0)
    err[(t == 26.0) | (t == 28.0)] = 4.0           # within 5 deg from 26 s, 2 deg from 30 s
    err[t == 50.0] = 2.5                           # out of 2 deg again: in for good at 52 s
    err[t == 150.0] = 3.0                          # after the first orbit: not counted by 2 deg
    np.savez(tmp_path / SERIES_FILE, t_s=t + 7.0, est_err_deg=err)
    assert sweep.run_convergence(str(tmp_path), period) == {
        'converged_s': 52.0, 'converged_5deg_s': 26.0, 'has_estimate': True}
    err[t == 190.0] = 6.0                          # out of 5 deg late in the run
    np.savez(tmp_path / SERIES_FILE, t_s=t, est_err_deg=err)
    c = sweep.run_convergence(str(tmp_path), period)
    assert c['converged_s'] == 52.0 and c['converged_5deg_s'] == 192.0
    err[t == 80.0] = 2.5                           # the last sample of the first orbit: out
    np.savez(tmp_path / SERIES_FILE, t_s=t, est_err_deg=err)
    assert sweep.run_convergence(str(tmp_path), period)['converged_s'] is None
    np.savez(tmp_path / SERIES_FILE, t_s=t, est_err_deg=np.full(t.size, np.nan))
    assert sweep.run_convergence(str(tmp_path), period) == {
        'converged_s': None, 'converged_5deg_s': None, 'has_estimate': False}


def test_the_tables_put_each_point_on_its_own_line():
    rows = [{'point': {ALPHA: a, K: k}, **sweep.point_metrics(
        [_res('captured', 10.0, a == 2e-3, 1.0, 1.0)], 1, 1000.0), 'out': 'x'}
        for a in (2e-3, 3e-3) for k in (0.1, 0.2)]
    text = sweep.table_markdown(rows, [ALPHA, K])
    lines = text.splitlines()
    assert len(lines) == 6 and lines[2].startswith('| 0.002 | 0.1 | 1/1 | 1/1 (100 %)')
    assert lines[4].startswith('| 0.003 | 0.1 | 1/1 | 0/1 (0 %)')
    gain_map = sweep.map_markdown(rows, [ALPHA, K]).splitlines()
    assert gain_map[0] == f'| {ALPHA} \\ {K} | 0.1 | 0.2 |'
    assert gain_map[2:] == ['| 0.002 | 1/1 | 1/1 |', '| 0.003 | 0/1 | 0/1 |']
    assert sweep.map_markdown(rows, [ALPHA]) == ''


# ---------------------------------------------------------------------- a sweep, in process
class _InProcessBackend:
    """The local backend's interface, each run done here by the plain worker's body
    (:func:`adcs_nodes.tools.campaigns.worker.mc_worker`) instead of its process;
    ``interrupt_after`` results
    delivered, Ctrl-C arrives (the runs not done stay pending)."""

    def __init__(self, interrupt_after=None):
        self.jobs = []
        self.interrupt_after = interrupt_after
        self.ran = []

    def submit(self, job):
        self.jobs.append(job)

    def results(self):
        from adcs_nodes.tools.campaigns.worker import mc_worker
        for n, job in enumerate(self.jobs):
            if self.interrupt_after is not None and n >= self.interrupt_after:
                raise KeyboardInterrupt
            assert mc_worker(job['run_dir']) == 0
            self.ran.append(job['run_dir'])
            yield load_result(job['run_dir'])

    def drain(self, timeout_s):
        return []

    def close(self):
        pass


def _run_sweep(out, backends, monkeypatch, capsys, extra=()):
    made = iter(backends)
    monkeypatch.setattr(campaign_mod, 'LocalBackend', lambda jobs: next(made))
    code = cli.main(['sweep', SCENARIO, '--set', f'{ALPHA}=2e-3,3e-3', '--set', f'{K}=0.2',
                     '--runs', '2', '--duration', '20', '--out', str(out), *extra])
    return code, capsys.readouterr().out


def _csv(path):
    with open(path, encoding='utf-8', newline='') as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        del r['out'], r['run_wall_median_s']     # where and how fast, not what
    return rows


def test_an_interrupted_sweep_resumes_to_the_table_of_an_uninterrupted_one(
        tmp_path, monkeypatch, capsys):
    # uninterrupted
    full = [_InProcessBackend(), _InProcessBackend()]
    code, text = _run_sweep(tmp_path / 'a', full, monkeypatch, capsys)
    assert code == 0, text
    assert [len(b.ran) for b in full] == [2, 2]
    # Ctrl-C after the first run of the first point: exit 130, the second point never starts
    cut = _InProcessBackend(interrupt_after=1)
    code, text = _run_sweep(tmp_path / 'b', [cut], monkeypatch, capsys)
    assert code == 130, text
    assert len(cut.ran) == 1 and 'interrupted' in text
    assert '| 0.002 | 1/2 |' in text and '| 0.003 | 0/2 |' in text
    # the same command again: only the three missing runs run
    rest = [_InProcessBackend(), _InProcessBackend()]
    code, text = _run_sweep(tmp_path / 'b', rest, monkeypatch, capsys)
    assert code == 0, text
    assert [len(b.ran) for b in rest] == [1, 2]
    assert 'resuming: 1 of 2 runs already done, 1 to run' in text
    assert _csv(tmp_path / 'b' / 'sweep.csv') == _csv(tmp_path / 'a' / 'sweep.csv')
    # and once more: nothing to run (no backend is even made), the same table
    code, again = _run_sweep(tmp_path / 'b', [], monkeypatch, capsys)
    assert code == 0 and again.split('[sweep] paper000_control')[1] == \
        text.split('[sweep] paper000_control')[1]
    for name in ('sweep.md', 'sweep.json', 'sweep.png'):
        assert (tmp_path / 'b' / name).is_file()
    # --table: nothing runs, even for a run that is missing, and the table says what is there
    os.remove(os.path.join(run_dir_of(str(next((tmp_path / 'b' / 'points').iterdir())), 1),
                           'result.json'))
    code, table = _run_sweep(tmp_path / 'b', [], monkeypatch, capsys, ['--table'])
    assert code == 0 and 'nothing runs' in table and '| 1/2 |' in table, table


def test_every_point_runs_its_values_on_the_same_draws(tmp_path, monkeypatch, capsys):
    code, _ = _run_sweep(tmp_path / 's', [_InProcessBackend(), _InProcessBackend()],
                         monkeypatch, capsys)
    assert code == 0
    points = sorted((tmp_path / 's' / 'points').iterdir())
    assert len(points) == 2
    seen = {}
    for p in points:
        for i in range(2):
            with open(os.path.join(run_dir_of(str(p), i), 'scenario.yaml')) as fh:
                sc = yaml.safe_load(fh)
            seen.setdefault(i, []).append(sc)
    for i, (a, b) in seen.items():
        assert {a['controllers']['magnetic']['alpha_per_s'],
                b['controllers']['magnetic']['alpha_per_s']} == {2e-3, 3e-3}
        assert a['controllers']['magnetic']['k_Nms'] == b['controllers']['magnetic']['k_Nms'] \
            == 0.2
        assert a['initial'] == b['initial'] and a['seed'] == b['seed']
    assert seen[0][0]['initial'] != seen[1][0]['initial']
