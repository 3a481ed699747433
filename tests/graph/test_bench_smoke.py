"""``make bench`` machinery at tiny sizes: it runs and prints the table (no speed checks).

It starts processes (the bench and its graphs, on domains it claims): graph tier, marked
``parallel`` (not serialized with the launched-graph tests; was ``tests/unit``)."""
import os
import subprocess
import sys

import pytest

from perf.bench import (Row, Sample, delivery_pattern, format_table, hop_pattern,
                        start_costs, verdict)

pytestmark = pytest.mark.parallel

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_table_and_verdicts_format():
    samples = [Sample(10, r, 1.0, 2.0, 1e-3) for r in (100.0, 300.0, 200.0)]
    rows = [Row('(1)', 'ring', samples=samples, loads=[0.5, 0.7, 0.6]),
            Row('(6)', 'reference', unit='RK4 steps', step_s=0.1, skipped='not measured: x')]
    text = format_table(rows)
    assert '200 (100-300)' in text and 'not measured: x' in text and '0.60' in text
    assert '1.000' in text   # CPU ms per frame
    assert len({len(line) for line in text.splitlines()[:2]}) == 1   # header as wide as rule
    assert 'NOT MET' in verdict('x', 0.4, 0.5, '') and ' MET ' in verdict('x', 0.6, 0.5, '')
    assert 'NOT MEASURED' in verdict('x', None, 0.5, '')
    assert ' MET ' in verdict('x', 1.02, 1.05, '', at_most=True)
    assert 'NOT MET' in verdict('x', 1.2, 1.05, '', at_most=True)


def test_hop_pattern_of_paper000_at_1s_frames():
    # clock -> env -> dyn (2); command due every 2 s: clock -> est -> ctrl -> mgr -> dyn (4);
    # magnetometer every 10 s on a command frame: 7 hops
    sc = {'sensors': {'magnetometer': {'period_s': 10.0}}, 'controllers': {'period_s': 2.0}}
    assert hop_pattern(sc, 1.0) == [7, 2, 4, 2, 4, 2, 4, 2, 4, 2]
    assert hop_pattern(sc, 2.0) == [7, 4, 4, 4, 4]
    assert hop_pattern({}, 1.0) == [2]


def test_delivery_pattern_of_paper000_at_1s_frames():
    # the ring of target (a) makes the graph's own deliveries: /clock to the 7 nodes, the
    # environment to dynamics and the magnetometer, sim/state to the magnetometer (10 a frame);
    # command frames add the estimate (3 readers), the target, two commands, the applied
    # command (3 readers): 19; the magnetometer's sample adds 3: 22
    from adcs_nodes.scenario import load_scenario
    from perf.bench import bench_scenario
    sc = bench_scenario(load_scenario(os.path.join(ROOT, 'scenarios', 'paper000_control.yaml')))
    assert delivery_pattern(sc, 1.0) == [22, 10, 19, 10, 19, 10, 19, 10, 19, 10]


def test_start_costs_are_read_per_process_from_the_node_logs(tmp_path):
    """Rows (7g)/(7c): each log file is one process; a composed process logs one line per
    node (its CPU grows between them: the largest counts)."""
    logs = tmp_path / 'logs'
    logs.mkdir()
    line = '[INFO] [1796679621.7] [{}]: start cost {{"t_s": 0.0, "cpu_s": {}{}}}\n'
    (logs / 'estimator.log').write_text('[INFO] [1.0] [estimator]: lockstep: fires ...\n'
                                        + line.format('estimator', 0.8, ', "import_cpu_s": 0.2'))
    (logs / 'composed.log').write_text(line.format('dynamics', 1.0, '')
                                       + line.format('ns.estimator', 1.1, ''))
    (logs / 'recorder.log').write_text('[INFO] [1.0] [recorder]: recording every topic\n')
    assert start_costs(str(tmp_path)) == {
        'estimator': {'cpu_s': 0.8, 'import_cpu_s': 0.2, 'nodes': ['estimator']},
        'composed': {'cpu_s': 1.1, 'import_cpu_s': 0.0, 'nodes': ['dynamics', 'estimator']}}


@pytest.mark.long   # make bench runs the whole table
def test_bench_runs_at_tiny_size(tmp_path):
    out = tmp_path / 'bench.txt'
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [os.path.join(ROOT, 'tests'), os.path.join(ROOT, 'adcs_nodes'),
         os.path.join(ROOT, 'sim_node'), os.environ.get('PYTHONPATH', '')]))
    # row (3) is row (3i)'s code with the in-process path off: left out (two launches less);
    # row (8): a 4-run campaign of 0.05 orbits (the whole command: no speed check at this size)
    proc = subprocess.run([sys.executable, '-m', 'perf.bench', '--frames', '25',
                           '--repeats', '1', '--basilisk', 'skip', '--rows',
                           '1,2,3i,4,5,6,7g,7c,8', '--campaign-runs', '4',
                           '--campaign-orbits', '0.05', '--out', str(out)],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    text = out.read_text()
    assert text == proc.stdout
    for label in ('(1)', '(2)', '(3)', '(3i)', '(4)', '(5)', '(6)', '(7g)', '(7c)', '(8)'):
        assert any(line.startswith(label) for line in text.splitlines()), label
    assert 'skipped (--basilisk skip)' in text and 'NOT MEASURED' in text
    assert 'not selected (--rows)' in [line for line in text.splitlines()
                                       if line.startswith('(3) ')][0]
    # (a), (b) and (c) of row (3i) get a verdict; (3)'s and (d) (no Basilisk) are not measured
    assert text.count('MET') >= 3 and text.count('NOT MEASURED') >= 3   # MET or NOT MET
    assert 'nproc' in text and 'load average' in text
    assert '(f) start-up CPU to frame 0' in text and 'dynamics' in text    # (7g)'s per node
    campaign = [line for line in text.splitlines() if '(g) campaign CPU' in line][0]
    assert 'target <= 1.05 x' in campaign and 'CPU for 4 runs' in campaign, campaign
    ratio = float(campaign.split('FrameLoop CPU')[1].split()[0])
    assert ratio > 1.0, campaign    # the command's processes include every run's FrameLoop
