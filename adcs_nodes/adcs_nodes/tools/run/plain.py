"""``adcs run --engine plain``: the FrameLoop to the end of the run, its bag written by
:class:`BagSink` (the same MCAP bytes a recorded graph run has, without rclpy)."""
from __future__ import annotations

import os
from typing import Any, Dict, Optional, Sequence, Tuple

from sim_node.engine import EngineError, Frame, FrameLoop


class BagSink:
    """Writes frames to a rosbag2 MCAP bag, as the recorder does (message definitions
    embedded; log time = the message's sim time, so the bag reads like a recorded one).

    Each core sample becomes the message its topic's converter makes
    (:func:`adcs_nodes.inputs.converter`, what the nodes publish), encoded by the project's
    CDR encoder (:mod:`adcs_nodes.msgs.cdr`: byte-identical to a typed publish): no rclpy.
    """

    def __init__(self, path: str, scenario_text: Optional[str] = None,
                 flush_every_frames: int = 200, topics: Sequence[str] = ()) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        from adcs_nodes.bag import BAG_VERSION, ensure_type, make_typestore
        self._ensure_type = ensure_type
        self.path = path
        self._store = make_typestore()
        self._writer = Writer(path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        try:
            self._writer.open()
        except OSError as exc:
            raise EngineError(f'cannot create the bag {path}: {exc.strerror or exc}') from None
        self._writer.set_custom_data('recorder', 'sim_node.engine (plain engine)')
        self._conns: Dict[str, Tuple[Any, Any]] = {}
        #: the scenario's ``record.topics`` (relative names; empty: every data topic)
        self._only = {t.lstrip('/') for t in topics}
        self._frames = 0
        self._flush_every = max(1, int(flush_every_frames))
        self.messages = 0
        if scenario_text is not None:
            with open(os.path.join(path, 'scenario.yaml'), 'w') as fh:
                fh.write(scenario_text)

    def _connection(self, topic: str, sample: Any) -> Tuple[Any, Any, Any]:
        got = self._conns.get(topic)
        if got is None:
            from adcs_nodes.bag import offered_qos
            from adcs_nodes.graph import topic_type
            from adcs_nodes.inputs import converter
            from adcs_nodes.msgs.cdr import codec
            msgtype = topic_type(topic)
            if not self._ensure_type(self._store, msgtype):
                raise EngineError(f'no .msg definition found for {msgtype}')
            name = topic if topic.startswith('/') else '/' + topic    # resolved, as recorded
            to_msg = converter(topic).to_msg
            got = self._conns[topic] = (
                self._writer.add_connection(name, msgtype, typestore=self._store,
                                            offered_qos_profiles=offered_qos(name)),
                to_msg, codec(type(to_msg(sample, self._epoch_ns))).encode)
        return got

    def write(self, frame: Frame) -> None:
        """Write one frame's samples (flushed to the file every ``flush_every_frames``)."""
        from adcs_nodes.bag import flush_writer
        t_log = self._clock_ns(frame.t_ns)
        for topic, sample in frame.outputs:
            if self._only and topic.lstrip('/') not in self._only:
                continue
            conn, to_msg, encode = self._connection(topic, sample)
            self._writer.write(conn, t_log, encode(to_msg(sample, self._epoch_ns)))
            self.messages += 1
        self._frames += 1
        if self._frames % self._flush_every == 0:
            flush_writer(self._writer)

    def _clock_ns(self, t_ns: int) -> int:
        return self._epoch_ns + t_ns

    def bind(self, loop: FrameLoop) -> 'BagSink':
        """Log times from ``loop``'s epoch."""
        self._epoch_ns = loop.epoch_ns
        return self

    def close(self) -> None:
        """Finish the bag (index, metadata)."""
        if self._writer is not None:
            from adcs_nodes.distro import close_writer
            close_writer(self._writer)      # the real ROS distro in the metadata
            self._writer = None


def run_plain(sc: Dict[str, Any], duration_s: Optional[float] = None,
              record: Optional[str] = None, progress: bool = True,
              out=None) -> Any:
    """``adcs run SCENARIO --engine plain``: the FrameLoop to the end, the bag if asked.

    Returns a :class:`adcs_nodes.tools.run.launcher.RunResult`: exit code 0, 3 (degraded: the
    manager could not forward the active controller in some frames) or 130 (Ctrl-C: the bag
    keeps every frame run so far, closed properly), and 2 when the bag cannot be written (disk
    full: the frames written so far are kept).
    """
    import signal
    import sys
    import time

    import yaml

    from adcs_nodes.tools.run.launcher import EXIT_DEGRADED, RunResult
    out = out or sys.stderr
    loop = FrameLoop.from_scenario(sc, duration_s)
    duration = loop.duration_ns / 1e9
    sink = None
    if record:
        if os.path.exists(record):
            raise EngineError(f'the bag {record} exists already (give a new directory)')
        sink = BagSink(record, topics=(sc.get('record') or {}).get('topics') or ()).bind(loop)
        effective = {k: v for k, v in sc.items() if not k.startswith('_')}
        effective['duration_s'] = duration
        with open(os.path.join(record, 'scenario.yaml'), 'w') as fh:
            fh.write(f'# effective scenario of this bag (from {sc.get("_path", "?")})\n')
            yaml.safe_dump(effective, fh, sort_keys=False)
    stop = []
    old = signal.signal(signal.SIGINT, lambda *_: stop.append(True))
    t0, cpu0, last = time.monotonic(), time.process_time(), 0.0
    code, message = 0, 'done'
    try:
        for frame in loop.run():
            if sink is not None:
                try:
                    sink.write(frame)
                except OSError as exc:
                    code, message = 2, f'the bag could not be written: {exc.strerror or exc}'
                    break
            now = time.monotonic()
            if progress and now - last > 0.5:
                last = now
                print(f'\r[adcs] plain: {frame.t_ns / 1e9:9.0f} / {duration:g} s sim',
                      end='', file=out, flush=True)
            if stop:
                code, message = 130, 'interrupted (Ctrl-C): the bag keeps every frame run'
                break
    finally:
        signal.signal(signal.SIGINT, old)
        if sink is not None:
            try:
                sink.close()
            except OSError as exc:
                code, message = 2, f'the bag could not be closed: {exc.strerror or exc}'
    if progress:
        print('', file=out)
    wall = time.monotonic() - t0
    manager = getattr(loop, 'manager', None)
    st = manager.core.status() if manager is not None else {}
    from sim_node.faults import lost_text
    why = ['lost ' + ', '.join(lost)] if (lost := lost_text(sc.get('faults') or [],
                                                            loop.t_ns / 1e9)) else []
    if st.get('missed_frames', 0) > 0:
        why.append(f'the controller manager could not forward the active controller in '
                   f'{st["missed_frames"]} frames (last fault: {st.get("last_fault") or "?"})')
    if code == 0 and why:         # (the launcher's words for a degraded graph run)
        code, message = EXIT_DEGRADED, 'done, DEGRADED: ' + '; '.join(why)
    message += f' (plain engine: {time.process_time() - cpu0:.2f} s CPU)'
    return RunResult(code, loop.t_ns / 1e9 if not loop.done else duration, wall, loop.k,
                     0, record, '', message, loop.k / wall if wall > 0 else 0.0)
