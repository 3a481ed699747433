"""A campaign in its output directory: check, prepare, execute, tabulate, resume."""
from __future__ import annotations

import os
import shutil
import signal
import threading
import time
import uuid
from dataclasses import asdict
from typing import Any, Callable, Dict, List, Optional, Sequence

import yaml

from adcs_nodes.tools.campaigns.backends import DaskBackend, LocalBackend
from adcs_nodes.tools.campaigns.capture import ORBIT_FRAME
from adcs_nodes.tools.campaigns.config import (IDENTITY_KEYS, CampaignConfig, CampaignError,
                                               apply_dispersion, draw_dispersion)
from adcs_nodes.tools.campaigns.files import (campaign_lock, check_layout, clean_old_stop_files,
                                              load_result, read_campaign_json, run_dir_of,
                                              touch, write_json_atomic, write_text_atomic)
from adcs_nodes.tools.campaigns.runner import STOP_GRACE_S, RunOwner
from adcs_nodes.tools.campaigns.summary import (orbit_period_s, plot_capture_vs_rate,
                                                summary_markdown)
from adcs_nodes.tools.campaigns.table import write_table

#: Statuses of a run that ended (the others: ``interrupted``, ``pending``).
_FINISHED = ('captured', 'not_captured', 'error')


class Campaign:
    """One invocation of a campaign in ``out``: check, prepare, execute, tabulate."""

    def __init__(self, cfg: CampaignConfig, base: Dict[str, Any], out: str,
                 log: Callable[[str], None] = print) -> None:
        self.cfg = cfg
        self.base = base
        self.out = os.path.abspath(out)
        self.log = log
        self.session = uuid.uuid4().hex[:12]
        self.stop_file = os.path.join(self.out, f'.stop-{self.session}')
        self.rows: Dict[int, Dict[str, Any]] = {}
        self.executed = 0

    # -------------------------------------------------------------- set-up
    def check_or_create(self) -> None:
        """Create ``campaign.json``, or refuse a restart whose identity differs."""
        path = os.path.join(self.out, 'campaign.json')
        if os.path.isfile(path):
            old = read_campaign_json(path)
            new = self.cfg.identity()
            old.setdefault('engine', 'graph')   # written before the engines: the graph
            # written before the guidance target: every capture was measured to the orbit frame
            old.setdefault('capture_reference', ORBIT_FRAME)
            diff = [f'{k}: {old.get(k)!r} in campaign.json, {new[k]!r} now'
                    for k in IDENTITY_KEYS if old.get(k) != new[k]]
            if diff:
                why = (' Its runs measured capture to the orbit frame; this scenario\'s is '
                       'measured to its guidance target (adcs_nodes/tools/campaigns/'
                       'capture.py): run it again in another --out.'
                       if old['capture_reference'] == ORBIT_FRAME != new['capture_reference']
                       else '')
                raise CampaignError(f'{self.out} holds a campaign with other arguments ('
                                    + '; '.join(diff) + '). Repeat its arguments to resume, '
                                    'or choose another --out.' + why)
        data = {**asdict(self.cfg), 'version': 1,
                'updated_utc': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}
        write_json_atomic(path, data)

    def prepare(self, index: int) -> Dict[str, Any]:
        """Fresh run directory with ``scenario.yaml`` and ``job.json``; returns the job."""
        run_dir = run_dir_of(self.out, index)
        RunOwner(run_dir).end_previous()        # a lost worker's run process, still writing
        if os.path.isdir(run_dir) and not os.path.islink(run_dir):
            shutil.rmtree(run_dir)   # an incomplete run: half-written bag, logs
        elif os.path.lexists(run_dir):
            os.unlink(run_dir)
        os.makedirs(run_dir)
        disp = draw_dispersion(self.cfg, index)
        sc = apply_dispersion(self.base, disp, self.cfg.duration_s, self.cfg)
        with open(os.path.join(run_dir, 'scenario.yaml'), 'w', encoding='utf-8') as fh:
            fh.write(f'# run {index} of the Monte Carlo campaign in {self.out} '
                     f'(seed {self.cfg.seed}), dispersed from {self.cfg.scenario_path}\n')
            yaml.safe_dump(sc, fh, sort_keys=False)
        job = {'index': index, 'run_dir': run_dir, 'stop_file': self.stop_file,
               'duration_s': self.cfg.duration_s, 'capture_deg': self.cfg.capture_deg,
               'compose': self.cfg.compose, 'engine': self.cfg.engine,
               'period_s': orbit_period_s(self.base), 'dispersion': asdict(disp)}
        write_json_atomic(os.path.join(run_dir, 'job.json'), job)
        return job

    # -------------------------------------------------------------- execution
    def run(self, jobs: int = 1, scheduler: Optional[str] = None,
            dask_local: bool = False) -> int:
        """Execute every run not done yet; write the table, summary and plot; the exit code."""
        check_layout(self.out)
        os.makedirs(self.out, exist_ok=True)
        with campaign_lock(self.out):
            self.check_or_create()
            clean_old_stop_files(self.out)
            todo = self._collect_done()
            interrupted = False
            if todo:
                if dask_local:
                    backend = DaskBackend(None, self.session, local_workers=jobs)
                elif scheduler:
                    backend = DaskBackend(scheduler, self.session)
                else:
                    backend = LocalBackend(jobs)
                interrupted = self._execute(backend, todo)
            self._collect_written(todo)
            for i in range(self.cfg.runs):
                self.rows.setdefault(i, {'index': i, 'status': 'pending', 'dispersion':
                                         asdict(draw_dispersion(self.cfg, i))})
            self.write_outputs()
        return self._exit_code(interrupted)

    def _collect_done(self) -> List[int]:
        todo = []
        for i in range(self.cfg.runs):
            result = load_result(run_dir_of(self.out, i))
            if result is None:
                todo.append(i)
            else:
                self.rows[i] = result
        if len(todo) < self.cfg.runs:
            self.log(f'[montecarlo] resuming: {self.cfg.runs - len(todo)} of {self.cfg.runs} '
                     f'runs already done, {len(todo)} to run')
        return todo

    def _collect_written(self, todo: Sequence[int]) -> None:
        # a run whose result.json is on disk has finished, delivered or not
        for i in todo:
            if self.rows.get(i, {}).get('status') in _FINISHED:
                continue
            result = load_result(run_dir_of(self.out, i))
            if result is not None:
                result.setdefault('dispersion', asdict(draw_dispersion(self.cfg, i)))
                self.rows[i] = result
                self.executed += 1

    def _execute(self, backend: Any, todo: Sequence[int]) -> bool:
        t0 = time.monotonic()
        old_term = sigterm_as_interrupt()
        try:
            for i in todo:
                backend.submit(self.prepare(i))
            for result in backend.results():
                self._record(result, t0)
            return False
        except KeyboardInterrupt:
            self.log('[montecarlo] interrupted: stopping the runs in progress '
                     '(finished runs are kept; run the same command again to resume)')
            touch(self.stop_file)
            for result in backend.drain(STOP_GRACE_S + 15.0):
                self._record(result, t0)
            return True
        finally:
            backend.close()
            if old_term is not None:
                signal.signal(signal.SIGTERM, old_term)

    def _record(self, result: Dict[str, Any], t0: float) -> None:
        index = int(result['index'])
        result.setdefault('dispersion', asdict(draw_dispersion(self.cfg, index)))
        self.rows[index] = result
        if result.get('status') in _FINISHED:
            self.executed += 1
        done = sum(1 for r in self.rows.values() if r.get('status') in _FINISHED)
        self.log(_progress_line(result, done, self.cfg.runs, time.monotonic() - t0))
        write_table(os.path.join(self.out, 'campaign.csv'), self._sorted_rows())

    def _sorted_rows(self) -> List[Dict[str, Any]]:
        return [self.rows[i] for i in sorted(self.rows) if i < self.cfg.runs]

    def _exit_code(self, interrupted: bool) -> int:
        rows = self._sorted_rows()
        failed = sum(1 for r in rows if r.get('status') == 'error')
        self.log(f'[montecarlo] executed {self.executed} run(s) in this call; '
                 f'{sum(1 for r in rows if r.get("status") == "captured")} captured, '
                 f'{failed} failed, of {self.cfg.runs}; table in '
                 f'{os.path.join(self.out, "campaign.csv")}')
        if interrupted:
            return 130
        return 1 if failed else 0

    # -------------------------------------------------------------- outputs
    def write_outputs(self) -> None:
        """``campaign.csv``, ``summary.md`` and ``capture_vs_rate.png`` from the rows."""
        rows = self._sorted_rows()
        write_table(os.path.join(self.out, 'campaign.csv'), rows)
        write_text_atomic(os.path.join(self.out, 'summary.md'),
                          summary_markdown(self.cfg, rows, self.base))
        plot_capture_vs_rate(os.path.join(self.out, 'capture_vs_rate.png'), self.cfg, rows,
                             self.base)


def _progress_line(result: Dict[str, Any], done: int, total: int, elapsed: float) -> str:
    status = result.get('status')
    wall = result.get('wall_time_s')
    wall_txt = f', {wall:.1f} s wall' if isinstance(wall, (int, float)) else ''
    if status == 'captured':
        hold = result.get('hold_median_deg')
        hold_txt = '' if hold is None else f', hold median {hold:.2f} deg'
        what = (f'captured at {result["capture_time_s"]:g} s, final '
                f'{result["final_angle_deg"]:.2f} deg{hold_txt}')
    elif status == 'not_captured':
        what = f'not captured, final {result["final_angle_deg"]:.1f} deg'
    else:
        what = f'{status}: {str(result.get("message", "")).splitlines()[0][:200]}'
    return (f'[montecarlo] {done}/{total} run {result["index"]}: {what}{wall_txt} '
            f'(campaign {elapsed:.0f} s)')


def sigterm_as_interrupt() -> Any:
    """Make SIGTERM stop the campaign like Ctrl-C (main thread only); returns the old handler."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    return signal.signal(signal.SIGTERM, handler)
