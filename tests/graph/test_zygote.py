"""The launcher's fork server (``adcs_nodes.tools.run.zygote``) and its handle, as processes
seen by the operating system: a forked child runs a module as ``python -m`` would (argv,
environment, own session, log, exit code), is killed by its pid, dies with the zygote, and a
SIGKILLed launcher leaves nothing behind. A zygote that cannot start falls back to executing
the node. Every wait has a deadline; no fixed sleeps."""
import json
import os
import signal
import subprocess
import sys
import time

import pytest

pytest.importorskip('rclpy')

from adcs_nodes.tools.run.launcher.processes import Forked, Processes, Zygote  # noqa: E402

pytestmark = [pytest.mark.ros, pytest.mark.parallel]
HERE = os.path.dirname(os.path.abspath(__file__))
CHILD = [sys.executable, '-m', 'zygote_child']
DEADLINE_S = 120.0


def _env(**extra):
    path = os.pathsep.join(p for p in (HERE, os.environ.get('PYTHONPATH', '')) if p)
    return dict(os.environ, PYTHONPATH=path, **extra)


def _alive(pid: int) -> bool:
    """Whether ``pid`` is a live process (a zombie counts as dead)."""
    try:
        with open(f'/proc/{pid}/stat') as fh:
            return fh.read().rsplit(')', 1)[1].split()[0] not in ('Z', 'X')
    except (OSError, IndexError):
        return False


def _until(predicate, what, timeout=DEADLINE_S):
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f'timed out after {timeout} s waiting for {what}'
        time.sleep(0.05)


def _log(path):
    with open(path, encoding='utf-8', errors='replace') as fh:
        return fh.read()


@pytest.fixture(scope='module')
def zygote(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('zygote')
    said = []
    zyg = Zygote([], _env(), str(tmp / 'zygote.log'), said.append)
    yield zyg, tmp, said
    zyg.close()


def _spawn(zyg, tmp, name, args, **env):
    path = str(tmp / f'{name}.log')
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_CLOEXEC, 0o600)
    try:
        return zyg.spawn(CHILD + args, _env(**env), fd), path
    finally:
        os.close(fd)


def test_a_forked_child_runs_its_module_with_its_argv_env_session_and_exit_code(zygote):
    zyg, tmp, _ = zygote
    proc, log = _spawn(zyg, tmp, 'report', ['report', '3', '--ros-args', '-r', 'x:=y'],
                       ZYGOTE_TEST='from the request')
    assert isinstance(proc, Forked) and proc.wait(DEADLINE_S) == 3 and proc.returncode == 3
    seen = json.loads(_log(log).strip().splitlines()[-1])
    assert seen['argv'] == ['report', '3', '--ros-args', '-r', 'x:=y']
    assert seen['var'] == 'from the request'
    assert seen['sid'] == seen['pgid'] == seen['pid'] == proc.pid   # its own session
    assert seen['stdin'] == ''                                       # /dev/null
    assert proc.pid != zyg.proc.pid
    costs = [json.loads(ln.split('start cost ', 1)[1]) for ln in
             _log(str(tmp / 'zygote.log')).splitlines() if '[zygote]: start cost ' in ln]
    assert costs and costs[0]['import_cpu_s'] > 0 and costs[-1]['cpu_s'] >= costs[0]['cpu_s']


@pytest.mark.parametrize('mode, message', [('raise', 'RuntimeError: boom in the child'),
                                           ('refuse', 'refused: bad configuration')])
def test_an_exception_or_a_refusal_exits_1_with_its_message_in_the_log(zygote, mode, message):
    zyg, tmp, _ = zygote
    proc, log = _spawn(zyg, tmp, mode, [mode])
    assert proc.wait(DEADLINE_S) == 1
    assert message in _log(log)


def test_a_child_is_killed_by_its_pid_and_wait_times_out_while_it_lives(zygote):
    zyg, tmp, _ = zygote
    proc, log = _spawn(zyg, tmp, 'wait', ['wait'])
    _until(lambda: 'ready' in _log(log), 'the child to start')
    assert proc.poll() is None
    with pytest.raises(subprocess.TimeoutExpired):
        proc.wait(timeout=0.2)
    os.killpg(proc.pid, signal.SIGKILL)
    assert proc.wait(DEADLINE_S) == -signal.SIGKILL
    assert not _alive(proc.pid)


def test_the_zygote_s_death_ends_its_children_and_is_said(tmp_path):
    said = []
    zyg = Zygote([], _env(), str(tmp_path / 'zygote.log'), said.append)
    try:
        proc, log = _spawn(zyg, tmp_path, 'wait', ['wait'])
        _until(lambda: 'ready' in _log(log), 'the child to start')
        zyg.proc.kill()
        assert proc.wait(DEADLINE_S) == -signal.SIGTERM     # its parent-death signal
        _until(lambda: not _alive(proc.pid), 'the child to die with the zygote')
        assert not zyg.alive and any('zygote (fork server) ended' in s for s in said)
    finally:
        zyg.close()


LAUNCHER = r'''
import os, sys
from adcs_nodes.tools.run.launcher.processes import Zygote
zyg = Zygote([], dict(os.environ), sys.argv[1] + '/zygote.log')
fd = os.open(sys.argv[1] + '/wait.log', os.O_WRONLY | os.O_CREAT | os.O_CLOEXEC, 0o600)
child = zyg.spawn([sys.executable, '-m', 'zygote_child', 'wait'], dict(os.environ), fd)
print(zyg.proc.pid, child.pid, flush=True)
sys.stdin.read()
'''


def test_a_sigkilled_launcher_leaves_no_zygote_and_no_child(tmp_path):
    launcher = subprocess.Popen([sys.executable, '-c', LAUNCHER, str(tmp_path)], env=_env(),
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                start_new_session=True)
    try:
        pids = [int(p) for p in launcher.stdout.readline().split()]
        assert len(pids) == 2 and all(_alive(p) for p in pids)
        _until(lambda: 'ready' in _log(str(tmp_path / 'wait.log')), 'the child to start')
        launcher.kill()
        launcher.wait(DEADLINE_S)
        _until(lambda: not any(_alive(p) for p in pids), f'zygote and child to die ({pids})')
    finally:
        launcher.kill()
        launcher.wait()


def test_a_zygote_that_cannot_start_is_said_once_and_the_nodes_are_executed(tmp_path):
    said = []
    procs = Processes(str(tmp_path), said.append)
    cmds = {'a': CHILD + ['report', '0'], 'b': CHILD + ['report', '5'],
            'c': [sys.executable, '-m', 'no_such_module_for_the_zygote']}
    procs.spawn_all(cmds, _env())
    try:
        assert [type(procs.procs[n]) for n in 'ab'] == [subprocess.Popen] * 2
        assert procs.procs['a'].wait(DEADLINE_S) == 0 and procs.procs['b'].wait(DEADLINE_S) == 5
        assert sum('zygote (fork server)' in s for s in said) == 1, said
        assert 'no_such_module_for_the_zygote' in _log(procs.log_path('zygote'))
    finally:
        procs.stop_all(grace_s=5.0)
