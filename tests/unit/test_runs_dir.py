"""``ADCS_RUNS_DIR``: where the launcher keeps run directories and active-run manifests.

The variable names the directory; without it the user's ``~/.cache/adcs/runs``. The test
suite sets it to a temporary directory of its own run (``tests/conftest.py``), so no test
writes run directories into the user's home. Truth: the paths, built here by hand.
"""
import importlib.util
import os
import sys
import tempfile

from adcs_nodes.tools.run import launcher, live
from adcs_nodes.tools.run.launcher import isolation
from adcs_nodes.tools.run.launcher import Launcher
from adcs_nodes.scenario import load_scenario

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FREE_TUMBLE = os.path.join(ROOT, 'scenarios', 'free_tumble.yaml')


def _fresh_launcher_module(monkeypatch):
    """A separate copy of the launcher module, executed now (reads the environment now)."""
    spec = importlib.util.spec_from_file_location('launcher_copy', isolation.__file__)
    mod = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, 'launcher_copy', mod)    # (its dataclasses look it up)
    spec.loader.exec_module(mod)
    return mod


def test_the_variable_names_the_runs_directory(tmp_path, monkeypatch):
    monkeypatch.setenv('ADCS_RUNS_DIR', str(tmp_path / 'my-runs'))
    assert _fresh_launcher_module(monkeypatch).RUNS_DIR == str(tmp_path / 'my-runs')


def test_without_the_variable_the_users_cache(tmp_path, monkeypatch):
    monkeypatch.delenv('ADCS_RUNS_DIR', raising=False)
    monkeypatch.setenv('HOME', str(tmp_path))
    home_runs = os.path.join(str(tmp_path), '.cache', 'adcs', 'runs')
    assert _fresh_launcher_module(monkeypatch).RUNS_DIR == home_runs
    monkeypatch.setenv('ADCS_RUNS_DIR', '')          # empty: as if unset
    assert _fresh_launcher_module(monkeypatch).RUNS_DIR == home_runs


def test_the_test_run_keeps_its_runs_out_of_the_home_directory():
    runs = os.environ.get('ADCS_RUNS_DIR')
    assert runs, 'tests/conftest.py sets ADCS_RUNS_DIR'
    home_cache = os.path.join(os.path.expanduser('~'), '.cache')
    assert not os.path.abspath(runs).startswith(home_cache + os.sep), runs
    assert os.path.abspath(runs).startswith(os.path.abspath(tempfile.gettempdir()) + os.sep)
    # what this process's launcher, `adcs status` and `adcs switch` use
    assert launcher.RUNS_DIR == runs and live.RUNS_DIR == runs
    run = Launcher(load_scenario(FREE_TUMBLE), duration_s=10.0, progress=False,
                   log=lambda *a: None)
    assert os.path.dirname(run.run_dir) == runs
