"""What the bag says, read once for both reports (``summary.md`` and ``report.html``): the
series of the topics they draw in stamp order, on ``header.stamp`` [ns] (sim time) and in
seconds from one ``t0`` (the first ``/sim/state`` stamp), the time axis of their plots, the
controller spans of ``/adcs/controller_status``, the pointing and the estimate errors."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, NamedTuple, Optional, Sequence, Tuple

import numpy as np
from scipy.spatial.transform import Rotation

from adcs_nodes.bag import cdr_stamp_ns, open_bag, raw_messages, stamp_kind
from adcs_nodes.tools.analyse.metrics import angle_between_deg, slerp_at

STATE_TOPIC, FAULTS_TOPIC = '/sim/state', '/sim/faults'
#: A controller phase is "settled" when the truth stays within this angle of the target over
#: its last ``SETTLED_WINDOW_S`` or its second half if shorter (ASSUMPTION: 10 deg for the last
#: 10 minutes, issue 36).
SETTLED_DEG, SETTLED_WINDOW_S = 10.0, 600.0


@dataclass
class TopicStats:
    """A topic's type and its messages' stamps [ns] (log times for a type without a header)."""

    msgtype: str
    from_header: bool
    stamps: List[int] = field(default_factory=list)

    def rate_hz(self) -> Optional[float]:
        span_s = (max(self.stamps) - min(self.stamps)) * 1e-9 if self.stamps else 0.0
        return (len(self.stamps) - 1) / span_s if span_s > 0.0 else None


def _series(*keys: str):
    return field(default_factory=lambda: {'t': [], **{k: [] for k in keys}})


@dataclass
class RunData:
    """The series of a bag, ``{'t': [stamp ns], 's': [s from t0], key: [value]}`` each."""

    t0: int = 0
    stats: Dict[str, TopicStats] = field(default_factory=dict)
    state: Dict[str, list] = _series('q_orbit_body', 'q_eci_body', 'w_eci', 'w_orbit')
    env: Dict[str, list] = _series('b_eci', 'n')
    mag: Dict[str, list] = _series('b')
    wheels: Dict[str, list] = _series('h', 'speed')
    wheel_names: List[str] = field(default_factory=list)
    est: Dict[str, list] = _series('q_eci_body', 'w_eci', 'cov')
    target: Dict[str, list] = _series('q', 'frame', 'judged')
    status: Dict[str, list] = _series('active', 'mode', 'switch_count', 'last_fault')
    diag: Dict[str, list] = _series('rejected', 'last')
    cmd: Dict[str, list] = _series('source', 'dipole')
    faults: Dict[str, list] = _series('active', 'message', 'kind', 'target')


def _vec(name: str) -> Callable[[Any], List[float]]:
    def get(msg) -> List[float]:               # a Vector3 or Quaternion field as [x, y, z(, w)]
        v = getattr(msg, name)
        return [v.x, v.y, v.z] + ([v.w] if hasattr(v, 'w') else [])
    return get


#: What the pass keeps of each topic: ``{topic: (series of RunData, {key: getter})}``.
_FIELDS = {
    STATE_TOPIC: ('state', {'q_orbit_body': _vec('q_orbit_body'), 'q_eci_body': _vec(
        'q_eci_body'), 'w_eci': _vec('omega_body_eci_body'),
        'w_orbit': _vec('omega_body_orbit_body')}),
    '/sim/environment': ('env', {'b_eci': _vec('b_eci'), 'n': lambda m: float(m.orbit_rate)}),
    '/sensors/magnetometer': ('mag', {'b': _vec('magnetic_field')}),
    '/sim/wheels': ('wheels', {'h': lambda m: [float(x) for x in m.momentum],
                               'speed': lambda m: [float(x) for x in m.speed]}),
    '/adcs/attitude_estimate': ('est', {'q_eci_body': _vec('q_eci_body'),
                                        'w_eci': _vec('omega_body_eci_body'),
                                        'cov': lambda m: list(m.covariance)}),
    '/adcs/attitude_target': ('target', {'q': _vec('q_ref_body'),
                                         'frame': lambda m: m.header.frame_id or 'orbit',
                                         'judged': lambda m: m.profile != 'maneuver'}),
    '/adcs/controller_status': ('status', {
        'active': lambda m: m.active, 'mode': lambda m: m.mode,
        'switch_count': lambda m: int(m.switch_count), 'last_fault': lambda m: m.last_fault}),
    '/adcs/estimator/diagnostics': ('diag', {'rejected': lambda m: int(m.rejected_count),
                                             'last': lambda m: str(m.last_rejection)}),
    '/adcs/actuator_command': ('cmd', {'source': lambda m: str(m.source),
                                       'dipole': _vec('dipole_body')}),
}

#: The last result of each reader: ``{slot: ((bag path, its files' newest mtime, key), value)}``.
_LAST: Dict[str, Tuple[tuple, Any]] = {}


def cached(slot: str, bag, key: Any, read: Callable[[], Any]) -> Any:
    """``read()``, or its last result in ``slot`` for the same ``key`` and unchanged ``bag``
    (one read of a bag for both reports and the paper table and figures)."""
    try:
        mtime = max(os.stat(os.path.join(bag, f)).st_mtime_ns for f in os.listdir(bag)) \
            if os.path.isdir(bag) else os.stat(bag).st_mtime_ns
    except (OSError, ValueError):
        return read()                    # the reader names what is wrong with the bag
    full = (os.path.abspath(bag), mtime, key)
    if _LAST.get(slot, ((),))[0] != full:
        _LAST[slot] = (full, read())
    return _LAST[slot][1]


def read_run(bag_path) -> RunData:
    """The series of ``bag_path`` in one pass (kept for the next reader of the same bag);
    ``FileNotFoundError``, ``ValueError`` naming the bag."""
    return cached('run', bag_path, None, lambda: _read(bag_path))


def _read(bag_path) -> RunData:
    data = RunData()
    with open_bag(bag_path) as reader:
        kinds = {c.topic: stamp_kind(reader.typestore, c.msgtype) for c in reader.connections}
        for conn in reader.connections:
            data.stats.setdefault(conn.topic, TopicStats(conn.msgtype, bool(kinds[conn.topic])))
        for conn, t_log, raw in raw_messages(reader, reader.connections, bag_path):
            stamp = cdr_stamp_ns(raw) if kinds[conn.topic] else None
            data.stats[conn.topic].stamps.append(stamp if stamp is not None else t_log)
            if stamp is not None and (conn.topic in _FIELDS or conn.topic == FAULTS_TOPIC):
                _store(data, conn.topic, stamp, reader.deserialize(raw, conn.msgtype))
    _finish(data)
    return data


def _store(data: RunData, topic: str, t: int, msg) -> None:
    if topic == FAULTS_TOPIC:            # one row per announced fault
        for st in msg.status:
            values = {kv.key: kv.value for kv in st.values}
            for key, value in (('t', t), ('active', not str(st.message).startswith('cleared')),
                               ('message', st.message), ('kind', values.get('kind', '')),
                               ('target', values.get('target', st.hardware_id))):
                data.faults[key].append(value)
        return
    name, fields = _FIELDS[topic]
    series = getattr(data, name)
    series['t'].append(t)
    for key, get in fields.items():
        series[key].append(get(msg))
    if topic == '/sim/wheels' and not data.wheel_names:
        data.wheel_names = list(msg.names)


def _finish(data: RunData) -> None:
    """Every series in stamp order, ``t0`` and the seconds from it."""
    stamped = [min(st.stamps) for st in data.stats.values() if st.from_header and st.stamps]
    data.t0 = min(data.state['t'] or stamped or [0])
    for series in (data.state, data.env, data.mag, data.wheels, data.est, data.target,
                   data.status, data.diag, data.cmd, data.faults):
        order = np.argsort(np.asarray(series['t'], dtype=np.int64), kind='stable')
        for key in series:
            series[key] = [series[key][i] for i in order]
        series['s'] = [(t - data.t0) * 1e-9 for t in series['t']]


def ragged(rows: Sequence[Sequence[float]]) -> np.ndarray:
    """Rows of unequal length as one (n, longest) array, NaN where a row is short."""
    out = np.full((len(rows), max((len(r) for r in rows), default=0)), np.nan)
    for i, row in enumerate(rows):
        out[i, :len(row)] = row
    return out


def samples(series: Dict[str, list]) -> List[Dict[str, Any]]:
    """A series as one dict per sample."""
    return [dict(zip(series, values)) for values in zip(*series.values())]


def spans(t: Sequence[Any], labels: Sequence[str], t_end: Any) -> List[Tuple[Any, Any, str]]:
    """``[(start, end, label)]`` of consecutive equal ``labels`` at ``t``, the last to
    ``t_end``: the controller phases of ``controller_status.active``, modes, command sources."""
    out: List[Tuple[Any, Any, str]] = []
    for ti, lab in zip(t, labels):
        if out and out[-1][2] == lab:
            continue
        if out:
            out[-1] = (out[-1][0], ti, out[-1][2])
        out.append((ti, t_end, lab))
    return out


class TimeAxis(NamedTuple):
    """Sim time in ``unit`` (``scale`` seconds each) on a plot's x axis."""
    scale: float
    unit: str

    @property
    def label(self) -> str:
        return f'sim time [{self.unit}]'

    def __call__(self, t_s: Sequence[float]) -> np.ndarray:
        return np.asarray(t_s, dtype=float) / self.scale


def time_axis(t_end_s: float, orbit_period_s: Optional[float] = None) -> TimeAxis:
    """The unit of a run of ``t_end_s``: orbits from half an orbit, else min over 20 min, s."""
    if orbit_period_s and t_end_s >= 0.5 * orbit_period_s:
        return TimeAxis(orbit_period_s, 'orbits')
    return TimeAxis(60.0, 'min') if t_end_s > 1200.0 else TimeAxis(1.0, 's')


def orbit_period_s(data: RunData) -> Optional[float]:
    """``2 pi / n`` of the last positive orbit rate on ``/sim/environment`` [s], or None."""
    rates = [n for n in data.env['n'] if n > 0.0]
    return 2.0 * math.pi / rates[-1] if rates else None


def pointing_deg(data: RunData) -> Optional[np.ndarray]:
    """Angle of the truth to the guidance target held since its last sample [deg] at each
    ``/sim/state`` stamp (NaN before the first target; ``eci`` targets against ``q_eci_body``,
    others against ``q_orbit_body``); None without a state or a target."""
    if not (data.target['t'] and data.state['t']):
        return None
    t = np.asarray(data.state['t'], dtype=np.int64)
    k = np.searchsorted(np.asarray(data.target['t'], dtype=np.int64), t, side='right') - 1
    k_held = np.maximum(k, 0)
    frames = np.asarray(data.target['frame'])[k_held]
    truth = np.where((frames == 'eci')[:, None], np.asarray(data.state['q_eci_body']),
                     np.asarray(data.state['q_orbit_body']))
    return np.where(k >= 0, angle_between_deg(truth, np.asarray(data.target['q'])[k_held]),
                    np.nan)


def controller_phases(data: RunData, t0: int) -> List[Dict[str, Any]]:
    """Per span of one forwarded controller (``controller_status.active``): its times [s from
    ``t0``], the truth's angle to the guidance target at its end and its largest over the
    span's last ``SETTLED_WINDOW_S`` (or second half) [deg], within ``SETTLED_DEG`` or not."""
    angle = pointing_deg(data)
    if angle is None or not data.status['t']:
        return []
    t = np.asarray(data.state['t'], dtype=np.int64)
    out = []
    for start, end, name in spans(data.status['t'], data.status['active'], int(t[-1]) + 1):
        span = (t >= start) & (t < end) & np.isfinite(angle)
        if not span.any():
            continue
        window_ns = min(SETTLED_WINDOW_S * 1e9, (t[span][-1] - t[span][0]) / 2)
        worst = float(np.max(angle[span & (t >= t[span][-1] - window_ns)]))
        out.append({'controller': name or '(none)', 'from_s': (start - t0) / 1e9,
                    'to_s': (min(end, int(t[-1])) - t0) / 1e9,
                    'end_angle_deg': float(angle[span][-1]), 'last_window_max_deg': worst,
                    'settled': worst <= SETTLED_DEG})
    return out


def estimate_error(data: RunData) -> Optional[Dict[str, Any]]:
    """The estimates inside the truth's span against the truth slerped to their stamps:
    ``t`` [ns], ``s`` [s], angle ``deg`` of ``q_est^* q_true``, per body axis ``err`` (its
    rotation vector) and 3-sigma ``sigma3`` [deg], ``rate`` error [rad/s], ``on_grid`` (how
    many are stamped on a truth sample); None: no estimate inside."""
    if not (data.est['t'] and data.state['t']):
        return None
    ts, te = np.asarray(data.state['s']), np.asarray(data.est['s'])
    inside = (te >= ts[0]) & (te <= ts[-1])
    if not inside.any():
        return None
    q_true = slerp_at(ts, data.state['q_eci_body'], te[inside])
    q_est = np.asarray(data.est['q_eci_body'], dtype=float)[inside]
    axes = (Rotation.from_quat(q_est).inv() * Rotation.from_quat(q_true)).as_rotvec()
    w_true = np.asarray(data.state['w_eci'], dtype=float)
    w_at = np.stack([np.interp(te[inside], ts, w_true[:, k]) for k in range(3)], axis=1)
    cov = np.asarray(data.est['cov'], dtype=float)[inside]
    sigma3 = np.full(axes.shape, np.nan)
    if cov.ndim == 2 and cov.shape[1] == 36:
        known = cov[:, 0] >= 0.0                     # -1: the estimator gives no covariance
        sigma3[known] = 3.0 * np.degrees(np.sqrt(np.clip(cov[known][:, [0, 7, 14]], 0.0, None)))
    return {'t': np.asarray(data.est['t'], dtype=np.int64)[inside], 's': te[inside],
            'deg': angle_between_deg(q_est, q_true), 'err': np.degrees(axes), 'sigma3': sigma3,
            'rate': np.linalg.norm(np.asarray(data.est['w_eci'], dtype=float)[inside] - w_at,
                                   axis=1), 'on_grid': int(np.isin(te[inside], ts).sum())}
