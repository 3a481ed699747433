"""What a launched run says: its :class:`RunResult`, the closing message (degraded, lost,
restarts, per-node sample summaries), and the scenario stored beside its bag."""
from __future__ import annotations

import glob
import json
import os
import re
from dataclasses import dataclass
from typing import Any, Dict, List, Optional

import yaml

from adcs_nodes.tools.run.launcher.isolation import disk_full

#: Exit code of a run that completed but lost its controller or estimator for a while.
EXIT_DEGRADED = 3


@dataclass
class RunResult:
    """Outcome of a run."""

    exit_code: int
    sim_time_s: float
    wall_time_s: float
    frames: int
    missed_frames: int
    bag: Optional[str]
    run_dir: str
    message: str
    #: lockstep throughput measured by the clock master from frame 0 to its end [frames/s]
    frames_per_s: float = 0.0
    #: nodes restarted before frame 0 (self-healing), per node
    restarts: Optional[Dict[str, int]] = None


def external_devices(sc: Dict[str, Any]) -> List[str]:
    """One line per sensor the scenario marks ``external``: no simulated node, a driver."""
    from adcs_nodes import registry
    out = []
    for name, cfg in sc.get('sensors', {}).items():
        if cfg.get('external'):
            entry = registry.get('sensor', name)
            out.append(f'external {name}: no simulated node; expecting a driver publishing '
                       f'{entry.node[3]} ({entry.node[4]}) on ROS_DOMAIN_ID of this run '
                       '(docs/topics.md); frame 0 waits until its publisher is matched (at '
                       'most 60 s)')
    return out


_SUMMARY = re.compile(r'\[([A-Za-z0-9_./]+)\]: run summary (\{.*\})\s*$', re.M)


def node_summaries(run_dir: str) -> Dict[str, Dict[str, Any]]:
    """Each flight node's run summary (the JSON it logs at its last frame), by node name."""
    out: Dict[str, Dict[str, Any]] = {}
    for path in sorted(glob.glob(os.path.join(run_dir, 'logs', '*.log'))):
        try:
            with open(path, encoding='utf-8', errors='replace') as fh:
                text = fh.read()
        except OSError:
            continue
        for m in _SUMMARY.finditer(text):
            try:
                out[m.group(1).rsplit('.', 1)[-1]] = json.loads(m.group(2))
            except ValueError:
                continue
    return out


def summary_lines(summaries: Dict[str, Dict[str, Any]]) -> List[str]:
    """One line per node with inputs: samples used, rejected, superseded, filter resets."""
    lines = []
    for name, s in sorted(summaries.items()):
        used = s.get('samples_used') or {}
        if not used and not s.get('rejected') and not s.get('starved'):
            continue
        rejected = ', '.join(f'{r} {n}' for r, n in sorted(s.get('rejected', {}).items()))
        lines.append(f'{name}: samples used ' + (', '.join(
            f'{t} {n}' for t, n in sorted(used.items())) or 'none')
            + f'; rejected {rejected or "none"}; superseded {s.get("superseded", 0)}'
            + ('' if s.get('resets') is None else f'; filter resets {s["resets"]}'))
    return lines


def starved_text(summaries: Dict[str, Dict[str, Any]]) -> str:
    """The degraded reason of nodes starved of a topic for too long ('' if none)."""
    return '; '.join(
        f'{name} got nothing usable from {topic} (external or sample-timed input) for '
        f'{e["frames"]} of its frames from sim t = {e["since_s"]:g} s'
        for name, s in sorted(summaries.items())
        for topic, e in sorted((s.get('starved') or {}).items()))


def write_failed_text(error: str, bag: Optional[str]) -> str:
    return (f'the recorder stopped: {error} ({bag}). The run was stopped; the bag keeps what '
            'was written before (adcs export / adcs report read it)')


def degraded_text(sc: Dict[str, Any], lost: Dict[str, float], kills: Dict[str, Any],
                  sim_s: float, controller_status) -> str:
    """Why the run lost its controller or estimator for part of the time ('' if not)."""
    from sim_node.faults import lost_text
    why = []
    names = [f'{n} (died at sim t = {t:g} s)' for n, t in sorted(lost.items()) if n not in kills]
    if kills:
        names += lost_text(sc.get('faults') or [], sim_s)
    if names:
        why.append('lost ' + ', '.join(names))
    st = controller_status
    if st is not None and st.missed_frames > 0:
        why.append(f'the controller manager could not forward the active controller in '
                   f'{st.missed_frames} frames (last fault: {st.last_fault or "?"})')
    return '; '.join(why)


def closing_text(code: int, message: str, monitor, run_dir: str, bag: Optional[str],
                 security_events: int, restart_notes: List[str], degraded: str):
    """``(exit code, message)`` at the end of a run, with what the watch loop ended with."""
    if monitor.recorder_error and code == 0:
        code, message = 1, write_failed_text(monitor.recorder_error, bag)
    if security_events:
        message += (f'\n[adcs] security: dynamics refused {security_events} lockstep messages '
                    'from an unexpected publisher or with a repeated stamp '
                    '(adcs/security_events in the bag; docs/security.md)')
    if monitor.recorder_lost:
        message += (f'\n[adcs] WARNING: the bag misses {monitor.recorder_lost} message(s) that '
                    f'the middleware reported lost (last on {monitor.recorder_lost_topic}; '
                    'docs/reliability.md)')
    if restart_notes:
        message += (f'\n[adcs] restarts: {len(restart_notes)} before frame 0 (self-healing: '
                    + '; '.join(restart_notes) + ')')
    summaries = node_summaries(run_dir)
    degraded = '; '.join(d for d in (degraded, starved_text(summaries)) if d)
    if degraded and code == 0:
        code, message = EXIT_DEGRADED, f'done, DEGRADED: {degraded}'
    elif degraded:
        message += f'\n[adcs] degraded: {degraded}'
    return code, message + ''.join(f'\n[adcs] {line}' for line in summary_lines(summaries))


def transition_failed_text(name: str, transition: str, log: str, tail: str, stack: str = '',
                           unanswered_s: float = 0.0, restarts: int = 0, step: str = '',
                           deadline_s: float = 0.0):
    """Exit code and message for a managed node that was not made active."""
    if transition == 'configure':
        reasons = [ln.split('configuration error:', 1)[1].strip()
                   for ln in tail.splitlines() if 'configuration error:' in ln]
        why = reasons[-1] if reasons else 'no reason in its log'
        return 2, (f'node {name} refused its configuration (lifecycle configure failed): '
                   f'{why}; last lines of its log ({log}):\n{tail}')
    if transition == 'unanswered':
        return 1, (f'node {name} did not answer its lifecycle requests for {unanswered_s:g} s, '
                   f'also after {restarts} restart(s) before frame 0; last lines of its log '
                   f'({log}):\n{stack or tail}')
    if transition == 'deadline':
        return 1, (f'node {name} was not active {deadline_s:g} s after its start (lifecycle: '
                   f'{step}); last lines of its log ({log}):\n{stack or tail}')
    return 1, (f'node {name} refused the lifecycle transition {transition}; last lines of its '
               f'log ({log}):\n{tail}')


def save_scenario(sc: Dict[str, Any], record: Optional[str], duration_s: float) -> str:
    """Store the effective scenario as ``<bag>/scenario.yaml``; ``''``, or why not."""
    if not record or not os.path.isdir(record):
        return ''
    data = {k: v for k, v in sc.items() if not k.startswith('_')}
    data['duration_s'] = duration_s
    path = os.path.join(record, 'scenario.yaml')
    try:
        with open(path, 'w') as fh:
            fh.write(f'# effective scenario of this bag (from {sc.get("_path", "?")})\n')
            yaml.safe_dump(data, fh, sort_keys=False)
    except OSError as exc:
        try:
            os.unlink(path)   # a cut scenario.yaml would mislead adcs report
        except OSError:
            pass
        why = 'disk full' if disk_full(exc) else (exc.strerror or str(exc))
        return f'could not write {path}: {why} (the bag is kept)'
    return ''
