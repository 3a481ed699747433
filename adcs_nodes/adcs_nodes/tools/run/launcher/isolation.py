"""Run isolation: a private ``ROS_DOMAIN_ID`` per run, localhost discovery, the project's Fast
DDS profile, owner-only run directories and manifests (not a security boundary:
``docs/security.md``)."""
from __future__ import annotations

import errno
import fcntl
import json
import os
import random
import re
import shutil
import stat
import tempfile
from typing import Dict, Iterable, List

#: Run directories and active-run manifests: ``$ADCS_RUNS_DIR``, else ``~/.cache/adcs/runs``.
RUNS_DIR = os.environ.get('ADCS_RUNS_DIR') or os.path.join(os.path.expanduser('~'), '.cache',
                                                           'adcs', 'runs')
#: ``ROS_DOMAIN_ID`` values a run draws from, at random among the free ones (docs/security.md,
#: "Domain ids": 0 is everybody's, 100..214 the tests' or in the ephemeral port range).
RUN_DOMAINS = tuple(range(1, 100)) + tuple(range(215, 233))
#: Run directories kept in ``RUNS_DIR`` (older ones are removed when a run starts).
KEEP_RUNS = 50
#: Run directory names made by the launcher (only these are pruned).
RUN_DIR_PATTERN = re.compile(r'\d{8}T\d{6}-[A-Za-z0-9_.-]+-\d+')
#: Fast DDS defaults of every process of a run (UDP only with 4 MiB socket buffers, a 50 ms
#: writer heartbeat): docs/reliability.md, "Reliable samples under load".
FASTDDS_PROFILES = os.path.join(
    os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(
        __file__))))), 'config', 'fastdds_profiles.xml')
#: The middleware settings of a run (:func:`child_env`, :func:`use_dds_env`).
DDS_ENV_KEYS = ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE', 'FASTDDS_BUILTIN_TRANSPORTS',
                'FASTDDS_DEFAULT_PROFILES_FILE')


class LaunchError(RuntimeError):
    """The graph could not be started or a node failed; the message says which and why."""


def private_dir(path: str) -> str:
    """Create ``path`` (0700) or check it is this user's own real directory; LaunchError."""
    try:
        os.makedirs(path, mode=0o700, exist_ok=True)
        st = os.lstat(path)
    except OSError as exc:
        raise LaunchError(f'cannot create {path}: {exc.strerror or exc}') from None
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid():
        raise LaunchError(f'{path} is not a directory owned by you (a symlink planted by '
                          'someone else?); remove it')
    if st.st_mode & 0o077:
        os.chmod(path, 0o700)
    return path


def domain_lock_dir() -> str:
    """Per-user directory (0700, ownership checked) of the domain lock files."""
    runtime = os.environ.get('XDG_RUNTIME_DIR', '')
    if runtime and os.path.isabs(runtime) and os.path.isdir(runtime):
        return os.path.join(runtime, 'adcs-domain-locks')
    return os.path.join(tempfile.gettempdir(), f'adcs-domain-locks-{os.getuid()}')


def acquire_domain(domains: Iterable[int] = RUN_DOMAINS):
    """Claim a free ROS_DOMAIN_ID of ``domains`` at random with an exclusive lock file (no
    symlink followed); ``(id, handle)``, claimed until the handle is closed."""
    lock_dir = private_dir(domain_lock_dir())
    ids = list(domains)
    random.shuffle(ids)
    for dom in ids:
        try:
            fd = os.open(os.path.join(lock_dir, f'{dom}.lock'),
                         os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
        except OSError:
            continue  # ELOOP: a symlink in place of the lock file; not ours to use
        fh = os.fdopen(fd, 'r+')
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.close()
            continue
        return dom, fh
    raise LaunchError(f'no free ROS_DOMAIN_ID among {len(ids)} ({len(ids)} runs at once?)')


def prune_runs(runs_dir: str = RUNS_DIR, keep: int = KEEP_RUNS,
               protect: Iterable[str] = ()) -> List[str]:
    """Remove the run directories beyond the newest ``keep`` (not ``protect``, not live)."""
    try:
        names = [n for n in os.listdir(runs_dir) if RUN_DIR_PATTERN.fullmatch(n)]
    except OSError:
        return []
    busy = {os.path.abspath(p) for p in protect}
    for name in os.listdir(runs_dir):
        if name.startswith('active-') and name.endswith('.json'):
            try:
                with open(os.path.join(runs_dir, name)) as fh:
                    data = json.load(fh)
                os.kill(int(data['pid']), 0)   # a manifest left by a killed launcher: stale
                busy.add(os.path.abspath(data['run_dir']))
            except (OSError, ValueError, KeyError, TypeError):
                continue
    dirs = []
    for name in names:
        path = os.path.join(runs_dir, name)
        try:
            st = os.lstat(path)
        except OSError:
            continue
        if stat.S_ISDIR(st.st_mode):
            dirs.append((st.st_mtime, name, path))
    dirs.sort(reverse=True)
    removed = []
    for _, _, path in dirs[keep:]:
        if os.path.abspath(path) in busy:
            continue
        shutil.rmtree(path, ignore_errors=True)
        removed.append(path)
    return removed


def write_private(path: str, text: str) -> None:
    """Write ``text`` to ``path`` readable by the owner only (0600), replacing it atomically."""
    tmp = f'{path}.tmp{os.getpid()}'
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW | os.O_CLOEXEC,
                 0o600)
    try:
        with os.fdopen(fd, 'w') as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def disk_full(exc: OSError) -> bool:
    return exc.errno in (errno.ENOSPC, errno.EDQUOT)


def child_env(domain: int) -> Dict[str, str]:
    """Environment of every child: the run's domain, localhost, the Fast DDS profile."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(domain)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    env.setdefault('RCUTILS_COLORIZED_OUTPUT', '0')
    env.update(profile_env(env))      # UDP on loopback only (docs/decisions.md)
    if env.get('FASTDDS_DEFAULT_PROFILES_FILE') == FASTDDS_PROFILES:
        # the profile binds to loopback; LOCALHOST would add shared memory, shared by every
        # run on the host (docs/reliability.md, "Shared memory between runs")
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'SYSTEM_DEFAULT'
    if env.get('FASTDDS_DEFAULT_PROFILES_FILE') == '':   # "no file": Fast DDS would log an
        del env['FASTDDS_DEFAULT_PROFILES_FILE']         # error for the empty path
    return env


def profile_env(environ) -> Dict[str, str]:
    """The project's Fast DDS profile, or ``{}`` when ``environ`` names one (even empty)."""
    if 'FASTDDS_DEFAULT_PROFILES_FILE' in environ or 'FASTRTPS_DEFAULT_PROFILES_FILE' in environ:
        return {}
    return {'FASTDDS_DEFAULT_PROFILES_FILE': FASTDDS_PROFILES}


def use_dds_env(env: Dict[str, str]) -> None:
    """Give this process the run's middleware settings, before its first rclpy node."""
    for key in DDS_ENV_KEYS:
        if key in env:
            os.environ[key] = env[key]
        else:
            os.environ.pop(key, None)
