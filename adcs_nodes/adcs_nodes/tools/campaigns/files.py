"""Campaign files: atomic writes, run directories, results, the campaign lock."""
from __future__ import annotations

import fcntl
import json
import os
import socket
import time
import uuid
from typing import Any, Dict, Optional

from adcs_nodes.tools.campaigns.config import CampaignError

RESULT_FILE = 'result.json'
FAILED_FILE = 'failed.json'
#: Per-frame series of a plain-engine run (numpy ``.npz``), its data instead of a bag.
SERIES_FILE = 'series.npz'


def write_json_atomic(path: str, data: Any) -> None:
    """Write ``data`` as JSON to ``path`` atomically (fsynced; :func:`write_text_atomic`)."""
    write_text_atomic(path, json.dumps(data, indent=1), fsync=True)


def write_text_atomic(path: str, text: str, fsync: bool = False) -> None:
    """Write ``text`` to ``path`` atomically (a unique temporary file, ``os.replace``)."""
    tmp = f'{path}.tmp-{uuid.uuid4().hex}'
    with open(tmp, 'w', encoding='utf-8', newline='') as fh:
        fh.write(text)
        if fsync:
            fh.flush()
            os.fsync(fh.fileno())
    os.replace(tmp, path)


def result_head(job: Dict[str, Any]) -> Dict[str, Any]:
    """The fields every ``result.json`` and ``failed.json`` of a run starts with."""
    return {'index': job['index'], 'dispersion': job['dispersion'], 'bag': 'bag',
            'host': socket.gethostname(), 'supervisor_pid': os.getppid(),
            'worker_pid': os.getpid(),
            'finished_utc': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}


def fail(run_dir: str, job: Dict[str, Any], code: int, message: str, wall: float) -> int:
    """Write the run's ``failed.json``; the exit code (``code``, at least 1)."""
    write_json_atomic(os.path.join(run_dir, FAILED_FILE),
                      {**result_head(job), 'status': 'error', 'exit_code': code,
                       'message': message, 'wall_time_s': wall})
    print(f'[montecarlo] run failed: {message}', flush=True)
    return code or 1


def run_dir_of(out: str, index: int) -> str:
    """``OUT/runs/run_<index>`` (zero-padded to 4 digits so listings sort)."""
    return os.path.join(out, 'runs', f'run_{index:04d}')


def load_result(run_dir: str) -> Optional[Dict[str, Any]]:
    """The run's ``result.json`` when it is done, else None (an unlabelled old one: failed)."""
    from adcs_nodes.tools.campaigns.capture import label_old_result

    path = os.path.join(run_dir, RESULT_FILE)
    metadata = os.path.join(run_dir, 'bag', 'metadata.yaml')
    series = os.path.join(run_dir, SERIES_FILE)
    if not (os.path.isfile(path) and (os.path.isfile(metadata) or os.path.isfile(series))):
        return None
    try:
        with open(path, encoding='utf-8') as fh:
            result = json.load(fh)
        if not isinstance(result, dict):
            raise ValueError(f'{RESULT_FILE} is a JSON {type(result).__name__}, not a result: '
                             'the run is run again')
        return label_old_result(run_dir, result)
    except (OSError, ValueError, KeyError) as exc:      # ScenarioError is a ValueError
        write_json_atomic(os.path.join(run_dir, FAILED_FILE), {
            'status': 'error', 'exit_code': 1, 'message': f'cannot resume this run: {exc}'})
        return None


#: What a campaign directory holds (``True``: a directory); anything else there is refused.
LAYOUT = {'campaign.json': False, 'campaign.csv': False, 'summary.md': False,
          'capture_vs_rate.png': False, '.lock': False, 'runs': True}


def check_layout(out: str) -> None:
    """CampaignError naming the first entry of ``out`` that is not what a campaign wrote."""
    if os.path.exists(out) and not os.path.isdir(out):
        raise CampaignError(f'--out {out} is a file, not a campaign directory')
    for name, is_dir in LAYOUT.items():
        path = os.path.join(out, name)
        if os.path.lexists(path) and os.path.isdir(path) != is_dir:
            raise CampaignError(f'{path} is {"not " if is_dir else ""}a directory: it is not '
                                f'the campaign\'s {name}; remove it, or choose another --out')


def read_campaign_json(path: str) -> Dict[str, Any]:
    """A campaign's ``campaign.json``; CampaignError in one line for a damaged one."""
    why = ''
    try:
        with open(path, encoding='utf-8') as fh:
            data = json.load(fh)
        if not isinstance(data, dict):
            why = f'a JSON {type(data).__name__}, not a campaign'
    except OSError as exc:
        why = f'cannot be read ({exc.strerror or exc})'
    except ValueError as exc:
        why = f'not JSON ({exc})'[:200]
    if why:
        raise CampaignError(f'{path}: {why}: remove the file to start the campaign again, or '
                            'choose another --out')
    return data


class campaign_lock:
    """Exclusive lock on ``OUT/.lock``: two campaigns never share one directory at once."""

    def __init__(self, out: str) -> None:
        self.path = os.path.join(out, '.lock')
        self.fh = None

    def __enter__(self) -> 'campaign_lock':
        try:
            self.fh = open(self.path, 'w')
        except OSError as exc:
            raise CampaignError(f'{self.path}: cannot open the campaign lock: '
                                f'{exc.strerror or exc}') from None
        try:
            fcntl.flock(self.fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self.fh.close()
            raise CampaignError(f'another campaign is running in {os.path.dirname(self.path)}')
        return self

    def __exit__(self, *exc: Any) -> None:
        self.fh.close()


def touch(path: str) -> None:
    with open(path, 'w'):
        pass


def clean_old_stop_files(out: str, age_s: float = 3600.0) -> None:
    """Remove stop files of sessions interrupted more than ``age_s`` ago."""
    now = time.time()
    for name in os.listdir(out):
        path = os.path.join(out, name)
        if name.startswith('.stop-') and now - os.path.getmtime(path) > age_s:
            os.unlink(path)
