"""``make bench`` machinery at tiny sizes: it runs and prints the table (no speed checks)."""
import os
import subprocess
import sys

from sim_node.tools.bench import Row, Stat, format_table, parse_cases, verdict

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_table_and_verdicts_format():
    rows = [Row('(1)', 'ring', values=[100.0, 300.0, 200.0]),
            Row('(2)', 'graph', 1.0, 10, values=[50.0]),
            Row('ref', 'reference', kind='rk4', values=[5e4], note='not measured')]
    assert Stat([3.0, 1.0, 2.0]).median == 2.0
    text = format_table(rows)
    assert '200 (100-300)' in text and '500' in text and 'not measured' in text
    assert len({len(line) for line in text.splitlines()[:2]}) == 1   # header as wide as rule
    assert 'NOT MET' in verdict('x', 0.4, 0.5, '') and ' MET ' in verdict('x', 0.6, 0.5, '')
    assert parse_cases('1.0:10,0.1:1') == [(1.0, 10), (0.1, 1)]


def test_bench_runs_at_tiny_size(tmp_path):
    out = tmp_path / 'bench.txt'
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [os.path.join(ROOT, 'adcs_nodes'), os.path.join(ROOT, 'sim_node'),
         os.environ.get('PYTHONPATH', '')]))
    proc = subprocess.run([sys.executable, '-m', 'sim_node.tools.bench', '--frames', '20',
                           '--repeats', '1', '--cases', '1.0:10', '--out', str(out)],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr[-3000:]
    text = out.read_text()
    assert text == proc.stdout
    for label in ('(1)', '(2)', '(3)', '(4)', 'ref'):
        assert any(line.startswith(label) for line in text.splitlines()), label
    assert 'reference, not measured here' in text
    assert text.count('MET') >= 3 and 'nproc' in text
