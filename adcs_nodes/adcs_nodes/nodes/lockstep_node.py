"""Base class of every lockstep node: parameters, start handshake, timing, status.

Start handshake (no fixed sleeps, DESIGN section 6)
---------------------------------------------------
The launcher knows the whole graph, so it tells each node how many DDS endpoints must be
matched before it is ready: parameter ``expected_matches`` is a list of ``"pub:<topic>=<n>"``
(that many subscriptions matched to our publisher) and ``"sub:<topic>=<n>"`` (that many
publishers matched to our subscription). When all hold, the node publishes its name on the
latched topic ``lockstep/ready``. The clock master (dynamics) starts frame 0 only when every node
in its ``wait_for_nodes`` list said ready. A node started alone (``ros2 run``) has no
expectations and is ready at once.

Time: ``/clock`` carries ``epoch + elapsed``; nodes convert stamps to elapsed integer
nanoseconds at the edge (``elapsed_ns``) so frame arithmetic is exact.

Timing modes (parameter ``timing_mode``, DESIGN section 6)
----------------------------------------------------------
* ``lockstep``: deterministic with the simulator. Inputs are declared ``frame`` (awaited with
  the frame's stamp when due), ``previous`` (awaited with the stamp of the producer frame before
  t, e.g. the actuator command an estimator's prediction needs) or ``latest`` (never awaited;
  only for inputs that do not change the output). A due input missing ``timeout_s`` of wall
  time is a missed frame; after ``dead_after_frames`` misses in a row its producer is dead and
  no longer awaited until it publishes again.
* ``live``: against real drivers; the default of a flight-software node started alone (no
  ``expected_matches``, ``duration_s`` or ``frame_period_s`` given; the launcher sets
  ``timing_mode: lockstep``). Every ``period_s`` of the ROS clock (``use_sim_time`` or wall)
  the node fires once with the newest sample of each input, at the newest new stamp of its
  ``frame`` inputs (or the clock's time minus ``live_latency_s`` when none is new): the true
  time difference, no epoch counting, no replay of missed frames. A sample stamped zero,
  more than ``max_future_s``
  ahead of the clock, more than ``max_sample_age_s`` old, or not newer than the one before is
  rejected and counted by reason (:attr:`LockstepNode.rejected_samples`).
* sample timing (``external_inputs``: an ``external: true`` sensor's topic, or every sensor
  in ``--real-time``; :meth:`LockstepNode.external_samples`): never awaited; the node says
  ready only once a publisher is matched on each such topic (at most
  :data:`EXTERNAL_WAIT_S`); nothing usable for ``dead_after_frames`` of the input's periods
  starves the node (logged with the topic, in the run summary: the launcher ends the run
  degraded, exit 3). In ``--real-time`` the simulated world's nodes still await their frame
  inputs; flight software fires with the latest values.
* run summary: at its last frame a flight-software node logs :data:`SUMMARY_PREFIX` and
  :meth:`LockstepNode.run_summary` as JSON (samples used per topic, rejected by reason,
  superseded, filter resets, starved inputs); ``adcs run`` prints one line per node.
* QoS: every publisher and subscription accepts ``qos_overrides.<topic>.*`` parameters
  (``QoSOverridingOptions.with_default_policies()``); in live mode ``sensors/*`` inputs are
  subscribed best-effort (``SensorDataQoS``), which matches both kinds of driver.
* Simulated-world nodes (``SIMULATED_WORLD = True``) run in lockstep only.
"""
from __future__ import annotations

import copy
import json
import time
from typing import Any, Callable, Dict, List, Optional, Tuple

from rclpy.node import Node
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy,
                       qos_profile_sensor_data)
from rclpy.qos_overriding_options import QoSOverridingOptions
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from adcs_msgs.msg import LockstepStatus
from adcs_nodes.components.base import DEFAULT_EPOCH, epoch_to_ns, parse_epoch  # noqa: F401
from adcs_nodes.core.lockstep import (  # noqa: F401 (MAX_LAG_FRAMES: re-exported)
    MAX_LAG_FRAMES, NS_PER_S, PROGRESS_EVERY, REVIVE_HOLD_FRAMES, FrameSync, InputKind,
    input_kind, seconds_to_ns)
from adcs_nodes.core.sample_timing import REASONS, SampleQueue, admit
from adcs_nodes.nodes import cdr
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes import publisher_guard
from adcs_nodes.nodes.convert import stamp_ns, to_stamp
from adcs_nodes.nodes.diagnostics import Diagnostics

#: Reliable, keep-last QoS deep enough that no frame is lost in lockstep.
QOS_DATA = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                      history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.VOLATILE)
#: Latched (transient local) QoS for status-like topics.
QOS_LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         history=HistoryPolicy.KEEP_LAST,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
QOS_READY = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                       history=HistoryPolicy.KEEP_LAST,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)

#: The launcher's progress monitor (``tools.launcher._Monitor``): its node name, and the one
#: node whose ``lockstep/status`` it takes (content filter ``node = %0 OR missed_frames > 0``).
MONITOR_NODE, MONITOR_STATUS_OF = 'adcs_launcher', 'dynamics'
#: Wall time [s] between the clock master's periodic statuses when the monitor is their only
#: reader (its progress line and stall notice; at 2000 frames/s one per sim second cost 10 %
#: of a composed run's CPU, issue 13). Final statuses and missed frames are never held back.
MONITOR_STATUS_WALL_S = 0.1
#: Timing modes of a node (see the module docstring).
LOCKSTEP, LIVE = 'lockstep', 'live'
#: Parameters only the launcher (or a lockstep test) gives: any of them means lockstep.
LAUNCH_PARAMS = ('expected_matches', 'duration_s', 'frame_period_s')
#: Topic prefixes subscribed best-effort (SensorDataQoS) in live mode.
SENSOR_PREFIXES = ('sensors/', '/sensors/')
#: Reasons a live sample is rejected (keys of ``LockstepNode.rejected_samples``).
#: ``undecodable``: raw CDR bytes that do not decode (only a stranger on the domain sends them;
#: ``nodes/cdr.py``), in either timing mode.
REJECT_REASONS = REASONS + ('undecodable',)
#: Wall seconds a consumer of an external driver's topic waits, before it says ready, for a
#: publisher on that topic to be matched; then it starts without it (and is starved: the run
#: is degraded, with the topic named).
EXTERNAL_WAIT_S = 60.0
#: Wall seconds between two "waiting for the driver" lines.
EXTERNAL_WAIT_LOG_S = 10.0
#: The line a flight-software node logs at its last frame, followed by its summary as JSON
#: (the launcher prints it per node: ``tools.launcher.node_summaries``).
SUMMARY_PREFIX = 'run summary '


#: ``rclpy.node.Node`` options of every lockstep node: what the params file or ``-p`` gives is
#: declared at once (so an unknown name can be refused with a did-you-mean), and nothing
#: undeclared can be set at run time (:class:`adcs_nodes.nodes.params.SpecParameters` says
#: why, with a did-you-mean).
NODE_OPTIONS = {'allow_undeclared_parameters': False,
                'automatically_declare_parameters_from_overrides': True}
#: Registry kinds whose own parameters a node applies at run time: the core is rebuilt from
#: its entry with the new values at the next frame boundary. A controller starts again from
#: its reset state (as a controller switched in does); an estimator would lose its filter
#: and a sensor its seeded noise stream, so their parameters are read-only.
REBUILT_AT_RUN_TIME = ('controller',)


class LockstepNode(node_params.SpecParameters, Node):
    """rclpy node with the project's parameter, handshake, timing and status conventions.

    Parameters common to every node: ``epoch`` (ISO UTC of sim time 0), ``frame_period_s``
    (base frame), ``timeout_s`` (wall-clock wait for a missing input), ``seed``,
    ``expected_matches`` (start handshake), ``real_time`` (latest-value mode),
    ``timing_mode`` (``lockstep`` | ``live``), ``dead_after_frames`` (missed frames in a row
    before a producer is dead), ``status_period_s`` (sim seconds between ``lockstep/status``),
    and in live mode ``max_sample_age_s``, ``max_future_s`` and ``live_latency_s``.

    Run-time parameter changes (``ros2 param set``): only the own parameters of a registered
    controller (:data:`REBUILT_AT_RUN_TIME`) are writable; they are validated when set and
    applied at the next frame boundary. Every other parameter is read-only (see
    :mod:`adcs_nodes.nodes.params`).
    """

    #: True for the simulator's own nodes: they run in lockstep only.
    SIMULATED_WORLD = False

    def __init__(self, name: str, **kwargs: Any) -> None:
        Node.__init__(self, name, **NODE_OPTIONS, **kwargs)
        self.setup_lockstep()

    def setup_lockstep(self) -> None:
        """Read the common parameters and create the lockstep endpoints (status, progress,
        ready, ``/diagnostics``); ValueError for a bad value. A plain node calls it from its
        constructor, a managed one (:class:`ManagedLockstepNode`) when it is configured."""
        self.done = False
        self.exit_code = 0
        self.epoch = parse_epoch(self.param('epoch', DEFAULT_EPOCH))
        self.epoch_ns = epoch_to_ns(self.epoch)
        self.frame_ns = seconds_to_ns(self.param('frame_period_s', 1.0))
        if self.frame_ns <= 0:
            raise ValueError('frame_period_s must be positive')
        self.timeout_s = float(self.param('timeout_s', 5.0))
        if not self.timeout_s > 0:
            raise ValueError('timeout_s must be positive')
        self.seed = int(self.param('seed', 0))
        self.real_time = bool(self.param('real_time', False))
        self.dead_after = self.param('dead_after_frames', 3)
        if isinstance(self.dead_after, bool) or not isinstance(self.dead_after, int) \
                or self.dead_after < 1:
            raise ValueError(f'dead_after_frames must be an integer >= 1, got '
                             f'{self.dead_after!r}')
        # read once at start (read-only: the handshake polls it every 20 ms)
        self._expected_raw = list(self.param('expected_matches', ['']) or [])
        self.timing_mode = self._timing_mode()
        self._external_inputs = [n for n in self.param('external_inputs', []) if n]
        self.max_sample_age_s = float(self.param('max_sample_age_s', 5.0))
        self.max_future_s = float(self.param('max_future_s', 0.5))
        # ASSUMPTION: 50 ms covers a driver's publish-to-receive latency on one machine
        self.live_latency_ns = seconds_to_ns(self.param('live_latency_s', 0.05))
        if self.live_latency_ns < 0:
            raise ValueError('live_latency_s must be >= 0')
        if not (self.max_sample_age_s > 0 and self.max_future_s >= 0):
            raise ValueError('max_sample_age_s must be > 0 and max_future_s >= 0')
        killed_at = float(self.param('killed_at_s', -1.0))   # a node_killed fault
        self.killed_at_ns: Optional[int] = seconds_to_ns(killed_at) if killed_at >= 0 else None
        self.killed = False
        self.status_period_ns = seconds_to_ns(self.param('status_period_s', 1.0))
        if self.status_period_ns <= 0:
            raise ValueError('status_period_s must be positive')
        #: live mode: rejected samples by reason (see REJECT_REASONS), and the last reason
        self.rejected_samples: Dict[str, int] = {r: 0 for r in REJECT_REASONS}
        self.last_rejected_sample = ''
        #: samples replaced by a newer one before any frame used them (live and sample timing)
        self.superseded_samples = 0
        #: samples used per input name (frame inputs: each new stamp a frame took)
        self._used_counts: Dict[str, int] = {}
        self._used_mark: Dict[str, int] = {}
        #: sample timing: inputs with nothing usable for dead_after_frames of their periods:
        #: ``{name: {'since_s': last usable stamp (0: none), 'frames': starved frames}}``
        self.starved: Dict[str, Dict[str, float]] = {}
        self._status_mark = -1
        self._lockstep_status_wall = time.monotonic()
        self.frames = 0
        self.sim_t_ns = 0            # elapsed sim time of the last frame this node processed
        self.missed_frames = 0
        self.last_missed_input = ''
        self._wall0 = time.monotonic()
        self._ready_sent = False
        self._ready_pub = self.create_publisher(String, 'lockstep/ready', QOS_READY)
        self._status_pub = cdr.raw_publisher(
            self.create_publisher(LockstepStatus, 'lockstep/status', QOS_DATA))
        # flow control: every PROGRESS_EVERY frames (and at the last frame of the run) a node
        # reports how far it got; the clock master never runs more than MAX_LAG_FRAMES ahead
        self._progress_pub = cdr.raw_publisher(
            self.create_publisher(LockstepStatus, 'lockstep/progress', QOS_DATA))
        self.duration_ns = seconds_to_ns(self.param('duration_s', 0.0))
        self._progress_mark = -1
        self._pubs: Dict[str, Any] = {}
        self._subs: Dict[str, Any] = {}
        self.diagnostics = Diagnostics(self)     # /diagnostics once per sim second (frame_done)
        self._on_ready: Optional[Callable[[], None]] = None
        # lockstep/status: once per status_period_s of sim time (frame_done), plus once per
        # wall second while the node is stalled (no frame for 2 s), plus the final one
        self.create_timer(1.0, self._status_watchdog)

    # ------------------------------------------------------------------ parameters
    def param(self, name: str, default: Any, doc: str = '') -> Any:
        """Value of parameter ``name`` (declared with ``default`` if not given).

        A name spec'd in :data:`adcs_nodes.nodes.params.COMMON`, or documented by ``doc`` or
        the class's ``PARAM_DOCS`` ("meaning [unit]"), is declared with a descriptor (``ros2
        param describe``) and its type checked; every name asked for is "known" to
        :func:`adcs_nodes.nodes.params.refuse_unknown`.
        """
        self._asked = getattr(self, '_asked', set())
        self._asked.add(name)
        spec = node_params.COMMON.get(name)
        doc = doc or getattr(self, 'PARAM_DOCS', {}).get(name, '')
        if spec is None:    # (a plugin's parameter: typed from its default)
            spec = node_params.infer(name, default, doc or name.replace('_', ' '))
        if name in getattr(self, '_adcs_specs', {}):
            value = self.get_parameter(name).value
            return list(value) if spec.type.endswith('[]') else value
        return node_params.declare(self, spec)

    def section(self, prefix: str, defaults: Dict[str, Any],
                merge: bool = True, docs: Optional[Dict[str, str]] = None) -> Dict[str, Any]:
        """Parameters ``prefix.*`` as a dict (for model factories).

        Each given key is declared with its spec (:func:`adcs_nodes.nodes.params.
        declare_section`: validated, described with unit and range, read-only); a key the
        section does not have is refused with a did-you-mean. With ``merge`` the given keys
        override ``defaults``; without it ``defaults`` are used only when no key is given,
        for sections that select their own variant (``orbit.type: tle`` has other keys than
        the default circular orbit). ``docs`` is not used (the specs describe the keys).
        """
        given = node_params.declare_section(self, prefix)
        if merge:
            return {**defaults, **given}
        return given if given else dict(defaults)

    # ------------------------------------------------------------------ run-time changes
    def _rebuilt_entry(self):
        """The registry entry whose core this node rebuilds on a run-time change, or None."""
        entry = getattr(self, 'entry', None)
        return entry if getattr(entry, 'kind', None) in REBUILT_AT_RUN_TIME else None

    def applies_at_run_time(self, name: str) -> bool:
        """Whether a run-time change of parameter ``name`` takes effect (else it is declared
        read-only): the own parameters of a registered controller."""
        entry = self._rebuilt_entry()
        return entry is not None and any(p.name == name for p in entry.params)

    def _core_and_context(self):
        """The core object this node steps and its build context (on the node's frame
        component or on the node)."""
        holders = [h for h in (getattr(self, 'component', None), self) if h is not None]
        core = next((getattr(h, 'core') for h in holders if hasattr(h, 'core')), None)
        ctx = next((getattr(h, 'ctx') for h in holders if hasattr(h, 'ctx')), None)
        return core, ctx

    def _build_core(self, changes: Dict[str, Any]):
        """A core of this node's entry with its current parameters overlaid by ``changes``."""
        entry = self._rebuilt_entry()
        values = {p.name: changes[p.name] if p.name in changes
                  else node_params._plain(self.get_parameter(p.name).value)
                  for p in entry.params}
        return entry.build(entry.validate(values), self._core_and_context()[1])

    def check_parameters(self, changes: Dict[str, Any]) -> str:
        """Set-parameters check beyond the specs: the controller must build with the new
        values (e.g. magnetic's k > beta / (2 alpha)); the reason if not, else ''."""
        if self._rebuilt_entry() is None or self._core_and_context()[1] is None:
            return ''
        try:
            self._build_core(changes)
        except ValueError as exc:
            return f'{", ".join(changes)}: {exc}'
        return ''

    def parameters_set(self, names: List[str]) -> None:
        """Run-time change accepted: applied at the next frame boundary."""
        self._params_pending = getattr(self, '_params_pending', set()) | set(names)

    def apply_parameters(self) -> None:
        """At a frame boundary: the controller core is rebuilt with the parameters changed
        since the last frame (the same object, so every holder of it sees the change; it
        starts from its reset state)."""
        names = getattr(self, '_params_pending', None)
        if not names or self._rebuilt_entry() is None:
            return
        self._params_pending = set()
        core, _ = self._core_and_context()
        new = self._build_core({})
        if core is None or type(new) is not type(core) or not hasattr(core, '__dict__'):
            self.get_logger().error(f'parameters {", ".join(sorted(names))} set but not '
                                    'applied: no controller core to rebuild')
            return
        vars(core).clear()
        vars(core).update(vars(new))
        self.get_logger().info(f'parameters {", ".join(sorted(names))} applied from this '
                               f'frame on (t={self.sim_t_ns / NS_PER_S:g} s; the controller '
                               'restarts from its reset state)')

    # ------------------------------------------------------------------ endpoints
    def publisher(self, msg_type, topic: str, qos: QoSProfile = QOS_DATA):
        """Create a publisher (QoS overridable by parameters) registered for the handshake."""
        pub = self.create_publisher(
            msg_type, topic, copy.copy(qos),   # rclpy applies overrides to the profile in place
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
        self._pubs[pub.topic_name] = pub
        return cdr.raw_publisher(pub)      # raw CDR (issue 13; ADCS_RAW_CDR=0: typed)

    def subscription(self, msg_type, topic: str, callback, qos: QoSProfile = QOS_DATA):
        """Create a subscription (QoS overridable by parameters) registered for the handshake.

        Raw CDR (issue 13, ``nodes/cdr.py``): for a type the codec generator covers, the
        subscription takes the bytes and ``callback`` gets the decoded message (same class
        and fields as a typed take); ``ADCS_RAW_CDR=0`` in the environment: typed."""
        codec = cdr.raw_codec(msg_type)
        if codec is not None:     # bytes that do not decode: dropped, counted, warned
            callback = cdr.decoding(callback, codec, lambda exc: self._reject_sample(
                topic, 'undecodable', f'a message that does not decode was dropped ({exc})'))
        sub = self.create_subscription(
            msg_type, topic, callback,
            copy.copy(qos),   # (overrides mutate the profile)
            qos_overriding_options=QoSOverridingOptions.with_default_policies(),
            raw=codec is not None)
        self._subs[sub.topic_name] = sub
        return sub

    # ------------------------------------------------------------------ timing mode
    def _timing_mode(self) -> str:
        """``lockstep`` or ``live`` from ``timing_mode``, else from how the node was started."""
        given = str(self.param('timing_mode', '') or '')
        if given not in ('', LOCKSTEP, LIVE):
            raise ValueError(f'timing_mode must be {LOCKSTEP!r} or {LIVE!r}, got {given!r}')
        if self.SIMULATED_WORLD:
            if given == LIVE:
                raise ValueError(f'{self.get_name()} is part of the simulated world: '
                                 'timing_mode live is for flight software only')
            return LOCKSTEP
        if given:
            return given
        given_params = getattr(self, '_parameter_overrides', {})   # params file, -p, overrides
        launched = [n for n in LAUNCH_PARAMS if n in given_params
                    and given_params[n].value not in (None, '', [''], [], 0, 0.0)]
        if launched or self.real_time:
            return LOCKSTEP
        return LIVE

    @property
    def live(self) -> bool:
        """True in live mode."""
        return self.timing_mode == LIVE

    # ------------------------------------------------------------------ frame inputs
    def lockstep_inputs(self, inputs: Dict[str, Tuple], period_s: float,
                        on_frame: Callable[[int, Dict[str, Any], List[str]], None]) -> None:
        """Fire ``on_frame`` at t = 0, P, 2P, ... when the inputs due then have arrived.

        Parameters
        ----------
        inputs : dict
            ``{name: (msg_type, topic, period_s)}`` or ``{name: (msg_type, topic, period_s,
            kind)}``; ``period_s`` is the producer's period (0: never waited for, always the
            latest) and ``kind`` one of ``'frame'`` (default: awaited with the frame's stamp
            when due), ``'previous'`` (awaited with the stamp of the producer's frame before
            t; the value is exactly that message, or None when it timed out or its producer is
            dead) or ``'latest'``. Messages need ``header.stamp``.
        period_s : float
            This node's own period P (a multiple of ``frame_period_s``).
        on_frame : callable
            ``on_frame(t_ns, msgs, missing)``: elapsed sim time, ``{name: msg or None}`` (see
            ``kind``), and the due inputs that timed out (empty in a normal frame and always
            in live mode).

        Notes
        -----
        Frame t is considered once ``/clock`` or any input stamped >= t has arrived (so a
        node never runs ahead of the simulation). A due input missing ``timeout_s`` of wall
        time after that is counted as a missed frame and the frame fires without it; after
        ``dead_after_frames`` such frames in a row it is no longer awaited until it publishes
        again. In ``real_time`` mode the node never waits: it fires with the latest values as
        soon as time has reached t. In live mode see the module docstring.
        """
        self._own_period_ns = seconds_to_ns(period_s)
        if self._own_period_ns <= 0 or (not self.live and self._own_period_ns % self.frame_ns):
            raise ValueError(f'period_s: {period_s} s is not a positive multiple of the frame '
                             f'{self.frame_ns / NS_PER_S:g} s')
        specs: Dict[str, Tuple[int, InputKind]] = {}
        self._topics_of: Dict[str, str] = {}
        # inputs in sample timing (an external driver's, or every sensor in real-time mode):
        # never awaited, each sample used once at its own stamp (see external_samples)
        self.external = set() if self.live else {
            n for n in self._external_inputs if n in inputs}
        self.samples = SampleQueue(self.external, self._own_period_ns,
                                   seconds_to_ns(self.max_future_s),
                                   seconds_to_ns(self.max_sample_age_s))
        self._ext_used: Dict[str, int] = {}
        self._ext_period_ns: Dict[str, int] = {}   # the producer's declared period
        for name, spec in inputs.items():
            if len(spec) not in (3, 4):
                raise ValueError(f'input {name}: want (msg_type, topic, period_s[, kind])')
            msg_type, topic, p_s = spec[:3]
            kind = input_kind(spec[3] if len(spec) == 4 else InputKind.FRAME)
            p_ns = seconds_to_ns(p_s) if p_s else 0
            if not self.live and p_ns % self.frame_ns:
                raise ValueError(f'input {name}: period {p_s} s is not a multiple of the frame')
            if name in self.external:
                self._ext_period_ns[name] = p_ns
            if kind is InputKind.LATEST or name in self.external:
                p_ns = 0
            specs[name] = (p_ns, kind if p_ns else InputKind.LATEST)
            qos = QOS_DATA
            if (self.live or name in self.external) and topic.startswith(SENSOR_PREFIXES):
                qos = qos_profile_sensor_data     # a best-effort driver matches too
            cb = self._live_cb(name) if self.live else (
                self._external_cb(name) if name in self.external else self._input_cb(name))
            sub = self.subscription(msg_type, topic, cb, qos)
            self._topics_of[name] = sub.topic_name
        self.sync = FrameSync(specs, dead_after=self.dead_after,
                              revive_hold_ns=REVIVE_HOLD_FRAMES * self.frame_ns)
        self._frame_inputs = [n for n in specs if n not in self.external]
        self._on_frame = on_frame
        self._ext_wait_t0: Optional[float] = None
        self._ext_wait_logged = 0.0
        self._ext_gave_up = False
        self._next_t = 0
        self._seen_t = -1
        self._wait_since: Optional[float] = None
        if self.live:
            self._live_latest: Dict[str, Tuple[int, Any]] = {}
            self._live_used: Dict[str, int] = {}
            #: the sample of each trigger input last taken for a frame (a late one never is)
            self._live_taken: Dict[str, Tuple[int, Any]] = {}
            self._live_last_t: Optional[int] = None
            self._live_read: Dict[str, int] = {}     # the stamp each input's last tick read
            self._live_triggers = [n for n, (p, k) in specs.items() if k is InputKind.FRAME]
            self.create_timer(self._own_period_ns / NS_PER_S, self._live_tick)
            self.get_logger().info(
                f'timing_mode live: fires every {period_s:g} s of the ROS clock '
                f'(use_sim_time={self.get_parameter("use_sim_time").value}) with the newest '
                f'samples; set timing_mode:=lockstep to run with the simulator')
            return
        # /clock says that time has reached t even when no input is due then (a 2 s
        # estimator between 10 s magnetometer samples); it is never waited for
        self.subscription(Clock, '/clock', self._on_clock_tick)
        self.create_timer(min(0.05, self.timeout_s / 4.0), self._frame_watchdog)

    def _on_clock_tick(self, msg: Clock) -> None:
        t = self.elapsed_ns(stamp_ns(msg.clock))
        if t > self._seen_t:
            self._seen_t = t
            self._try_fire()
        # on every tick: an input stamped ahead of the clock (the environment runs one frame
        # ahead) may have moved _seen_t past a progress mark already
        self.report_progress(self._seen_t)

    def input_arrived(self, name: str) -> None:
        """Hook called on every message of a lockstep input before it is stored."""

    def _input_cb(self, name: str) -> Callable[[Any], None]:
        def cb(msg: Any) -> None:
            self.input_arrived(name)
            t = self.elapsed_ns(stamp_ns(msg.header.stamp))
            if self.sync.add(name, t, msg):
                self.get_logger().info(
                    f'{self._topics_of[name]} publishes again (stamped t={t / NS_PER_S:g} s, '
                    f'come before frame t={self._next_t / NS_PER_S:g} s): used and awaited '
                    'again after '
                    f'{REVIVE_HOLD_FRAMES} frames (t > '
                    f'{(t + self.sync.revive_hold_ns) / NS_PER_S:g} s)')
            if t > self._seen_t:
                self._seen_t = t
            self._try_fire()
        # expected_publishers given: only the launched producer's messages reach cb
        guard = publisher_guard.for_node(self)
        return cb if guard is None else guard.wrap(lambda: self._topics_of[name], cb)

    def _try_fire(self) -> None:
        while self._seen_t >= self._next_t:
            t = self._next_t
            # real-time mode: flight software fires with the latest values; the simulated
            # world (a sensor reading the truth of its frame) still awaits them, or it would
            # measure the state of the frame before (the /clock tick comes first: the
            # magnetometer of paper000_estimation --real-time was 2 s late, 10 deg at 5 deg/s)
            if (not self.real_time or self.SIMULATED_WORLD) and not self.sync.ready(t):
                if self._wait_since is None:
                    self._wait_since = time.monotonic()
                return
            self._fire(t, [])

    def _external_cb(self, name: str) -> Callable[[Any], None]:
        """A sample of an input in sample timing: checked and queued by stamp for the frame
        that covers it (:class:`adcs_nodes.core.sample_timing.SampleQueue`), or refused and
        counted by reason."""
        def cb(msg: Any) -> None:
            self.input_arrived(name)
            s = stamp_ns(msg.header.stamp)
            t = self.elapsed_ns(s)
            why = self.samples.offer(name, s, t, self.epoch_ns + max(self._seen_t, 0), msg)
            if why is not None:
                self._reject_sample(name, *why)
                return
            self.sync.add(name, t, msg)
        return cb

    def external_samples(self, t_ns: int) -> List[Tuple[int, str, Any]]:
        """The samples in sample timing that frame ``t_ns`` takes, in stamp order:
        ``(elapsed stamp, input name, message)``, each returned once (those stamped up to one
        own period before the frame; :meth:`SampleQueue.take`)."""
        return self.samples.take(t_ns)

    def _stops_at(self, t: int) -> bool:
        """True from the frame of this node's ``node_killed`` fault (``killed_at_s``) on:
        the node fires no frame and publishes nothing more (no progress, no status), as a
        crashed process; in a graph run the launcher then kills its process."""
        if self.killed_at_ns is None or t < self.killed_at_ns:
            return False
        if not self.killed:
            self.killed, self._final_sent = True, True     # (publish_status: nothing more)
            self.get_logger().error(
                f'killed by the scenario (a node_killed fault) at t={t / NS_PER_S:g} s: this '
                'node publishes nothing more')
        self._next_t = 2 ** 62                # (_try_fire: no frame is ever due again)
        self._wait_since = None
        return True

    def _fire(self, t: int, missing: List[str]) -> None:
        if self._stops_at(t):
            return
        msgs = {name: self.sync.value(name, t) for name in self.sync.names}
        self._wait_since = None
        self._next_t = t + self._own_period_ns
        self.sync.prune(t)
        self.frames += 1
        self.sim_t_ns = t
        self.apply_parameters()              # run-time parameter changes: at frame boundaries
        self._on_frame(t, msgs, missing)
        self._count_used(msgs)
        if self.external:
            self._external_done(t, msgs)
        last = self.is_last_frame(t, self._own_period_ns)
        if last and not self.SIMULATED_WORLD:
            self.get_logger().info(SUMMARY_PREFIX + json.dumps(self.run_summary(),
                                                               sort_keys=True))
        self.frame_done(t, final=last)
        if last:
            self.report_progress(max(t, self._seen_t), final=True)

    def _count_used(self, msgs: Dict[str, Any]) -> None:
        """Samples used by a frame: each new stamp of a frame-timed input, once."""
        for n in self._frame_inputs:
            m = msgs.get(n)
            if m is not None:
                s = stamp_ns(m.header.stamp)
                if s > self._used_mark.get(n, -1):
                    self._used_mark[n] = s
                    self._used_counts[n] = self._used_counts.get(n, 0) + 1

    def _external_done(self, t: int, msgs: Dict[str, Any]) -> None:
        """After frame ``t``: the samples in sample timing its consumer did not take itself
        (a controller reads the newest one) are covered now: the newest is used, the older
        ones never read by a frame are superseded; then the starvation check."""
        left = self.external_samples(t)
        prev = dict(self._ext_used)
        for n in self.external:
            if msgs.get(n) is not None:
                s = stamp_ns(msgs[n].header.stamp)
                if s > prev.get(n, -1):
                    self._used_counts[n] = self._used_counts.get(n, 0) + 1
                self._ext_used[n] = s
        for s_el, n, _ in left:
            s = self.epoch_ns + s_el
            if prev.get(n, -1) < s < self._ext_used.get(n, -1):
                self.superseded_samples += 1
        self._check_starved(t)

    def last_usable_ns(self, name: str) -> Optional[int]:
        """Elapsed stamp of the last usable sample of input ``name`` in sample timing (one
        that passed the timing checks; a consumer that checks more overrides it), or None."""
        return self.samples.last_usable(name)

    def _check_starved(self, t: int) -> None:
        """Sample timing: an input with nothing usable for ``dead_after_frames`` of its
        periods (the larger of the producer's declared period and this node's) starves this
        node: logged once per episode with the topic, counted per frame, and in the run
        summary (the launcher then says the run is degraded, exit 3)."""
        for n in sorted(self.external):
            period = max(self._own_period_ns, self._ext_period_ns.get(n, 0))
            last = self.last_usable_ns(n)
            since = 0 if last is None else last
            topic = self._topics_of.get(n, n)
            ent = self.starved.get(n)
            if t - since > self.dead_after * period:
                if ent is None or ent.get('over', False):
                    ent = self.starved.setdefault(n, {'since_s': since / NS_PER_S, 'frames': 0,
                                                      'episodes': 0})
                    ent['since_s'], ent['over'] = since / NS_PER_S, False
                    ent['episodes'] += 1
                    self.get_logger().error(
                        f'{topic}: nothing usable for more than {self.dead_after} periods of '
                        f'{period / NS_PER_S:g} s (last usable sample at t={since / NS_PER_S:g}'
                        f' s, now t={t / NS_PER_S:g} s): this node is starved and the run is '
                        'degraded')
                ent['frames'] += 1
            elif ent is not None and not ent.get('over', False):
                ent['over'] = True
                self.get_logger().info(f'{topic}: usable samples again at t={t / NS_PER_S:g} s')

    def used_counts(self) -> Dict[str, int]:
        """Samples used per input name (a node whose component knows better overrides it)."""
        return dict(self._used_counts)

    def run_summary(self) -> Dict[str, Any]:
        """What this node did with its inputs, by topic: ``samples_used``, ``rejected`` by
        reason (timing reasons, and the component's own checks when it has them),
        ``superseded``, filter ``resets``, ``starved`` inputs, frames and missed frames."""
        topics = getattr(self, '_topics_of', {})
        rejected = {r: n for r, n in self.rejected_samples.items() if n}
        for r, n in dict(getattr(self, 'rejected_by', {}) or {}).items():
            if n:
                rejected[r] = rejected.get(r, 0) + int(n)
        return {'frames': int(self.frames), 'missed_frames': int(self.missed_frames),
                'samples_used': {topics.get(n, n): int(v)
                                 for n, v in sorted(self.used_counts().items())},
                'rejected': rejected, 'superseded': int(self.superseded_samples),
                'resets': int(self.resets) if hasattr(self, 'resets') else None,
                'starved': {topics.get(n, n): {'since_s': e['since_s'],
                                               'frames': int(e['frames'])}
                            for n, e in sorted(self.starved.items())}}

    def _frame_watchdog(self) -> None:
        if self._wait_since is None or time.monotonic() - self._wait_since < self.timeout_s:
            return
        t = self._next_t
        names = self.sync.missing(t)
        missing = [self._topics_of[n] for n in names]
        applied = ', '.join(
            f'{self._topics_of[n]}: ' + ('none (a previous-frame input)'
                                         if self.sync.kind(n) is InputKind.PREVIOUS
                                         else 'its latest earlier sample, if any')
            for n in names)
        self.count_missed(missing, t, f'going on without it ({applied})')
        for n in self.sync.record_misses(t):
            self.get_logger().error(
                f'{self._topics_of[n]} missed {self.dead_after} frames in a row: its producer '
                'is treated as dead and no longer awaited until it publishes again')
        self._fire(t, missing)
        self._try_fire()

    # ------------------------------------------------------------------ live mode
    def _reject_sample(self, name: str, reason: str, text: str) -> None:
        self.rejected_samples[reason] += 1
        topic = getattr(self, '_topics_of', {}).get(name, name)   # (inputs set up or not)
        self.last_rejected_sample = f'{topic}: {text}'
        self.get_logger().warning(
            f'sample rejected ({reason}): {self.last_rejected_sample} '
            f'(rejected so far: {sum(self.rejected_samples.values())})',
            throttle_duration_sec=5.0)

    def _live_cb(self, name: str) -> Callable[[Any], None]:
        def cb(msg: Any) -> None:
            self.input_arrived(name)
            s = stamp_ns(msg.header.stamp)
            cur = self._live_latest.get(name)
            why = admit(s, self.get_clock().now().nanoseconds, None if cur is None else cur[0],
                        seconds_to_ns(self.max_future_s), seconds_to_ns(self.max_sample_age_s))
            if why is not None:
                self._reject_sample(name, *why)
                return
            if cur is not None and cur[0] > self._live_read.get(name, -1):
                self.superseded_samples += 1          # no tick read it
            self._live_latest[name] = (s, msg)
        return cb

    def _live_tick(self) -> None:
        """Live mode: one frame with the newest samples (see the module docstring)."""
        now = self.get_clock().now().nanoseconds
        if now <= 0:
            return                              # use_sim_time and no /clock yet
        last = self._live_last_t
        new = []
        for n in self._live_triggers:
            ent = self._live_latest.get(n)
            if ent is None or ent[0] <= self._live_used.get(n, -1):
                continue
            self._live_used[n] = ent[0]
            if last is not None and self.elapsed_ns(ent[0]) <= last:
                self._reject_sample(n, 'late', 'arrived after a later frame was processed')
                # never used: the frame reads the sample taken before it (not fresh)
                self._live_latest[n] = self._live_taken.get(n)
                if self._live_latest[n] is None:
                    del self._live_latest[n]
                continue
            self._live_taken[n] = ent
            new.append(ent[0])
        # nothing new: fire at the clock's time minus the expected transport latency, so a
        # sample taken just before now and still on its way is not made "late"
        t = self.elapsed_ns(max(new) if new else now - self.live_latency_ns)
        if last is not None and t <= last:
            return                              # clock did not advance
        if self._stops_at(t):
            return
        max_age = self.max_sample_age_s * NS_PER_S
        msgs = {}
        for n in self.sync.names:
            ent = self._live_latest.get(n)
            msgs[n] = None if ent is None or now - ent[0] > max_age else ent[1]
            if ent is not None:
                self._live_read[n] = ent[0]
        self._live_last_t = t
        self.frames += 1
        self.sim_t_ns = t
        self.apply_parameters()              # run-time parameter changes: at frame boundaries
        self._on_frame(t, msgs, [])
        self._live_prev = {n: stamp_ns(m.header.stamp) for n, m in msgs.items() if m is not None}
        self.frame_done(t)

    def fresh(self, name: str, msg: Any, t_ns: int) -> bool:
        """True when ``msg``, the value of input ``name`` in frame ``t_ns``, is a new sample.

        Lockstep: stamped exactly ``t_ns``. Live: newer than the sample of that input in the
        frame before (stamps are not on a frame grid there).
        """
        if msg is None:
            return False
        s = stamp_ns(msg.header.stamp)
        if name in getattr(self, 'external', ()):     # sample timing: newer than last used
            return s > self._ext_used.get(name, -1)
        if not self.live:
            return self.elapsed_ns(s) == int(t_ns)
        prev = getattr(self, '_live_prev', {}).get(name)
        return prev is None or s > prev

    def timing_diagnostics(self) -> Dict[str, str]:
        """Key-value timing health for ``/diagnostics``: mode, frames, missed frames, dead
        inputs, rejected samples by reason."""
        sync = getattr(self, 'sync', None)
        topics = getattr(self, '_topics_of', {})
        dead = [topics.get(n, n) for n in sync.dead()] if sync is not None else []
        out = {'timing_mode': self.timing_mode, 'frames': str(self.frames),
               'missed_frames': str(self.missed_frames),
               'last_missed_input': self.last_missed_input,
               'dead_inputs': ', '.join(dead),
               'rejected_samples': str(sum(self.rejected_samples.values())),
               'last_rejected_sample': self.last_rejected_sample}
        out.update({f'rejected_{r}': str(v) for r, v in self.rejected_samples.items()})
        out['superseded_samples'] = str(self.superseded_samples)
        out['starved_inputs'] = ', '.join(topics.get(n, n) for n, e in self.starved.items()
                                          if not e.get('over', False))
        guard = getattr(self, '_publisher_guard', None)
        if guard is not None:                 # publisher identity (publisher_guard)
            out.update(guard.core.diagnostic_values())
        return out

    # ------------------------------------------------------------------ handshake
    def _expectations(self) -> List[tuple]:
        out = []
        for item in self._expected_raw:
            if not item:
                continue
            try:
                kind, rest = item.split(':', 1)
                topic, n = rest.rsplit('=', 1)
                out.append((kind, self.resolve_topic_name(topic), int(n)))
            except ValueError as exc:
                raise ValueError(f'bad expected_matches entry {item!r} '
                                 '(want "pub:<topic>=<n>" or "sub:<topic>=<n>")') from exc
        return out

    def add_ready_check(self, check: Callable[[], List[str]]) -> None:
        """Also wait, before ready, until ``check()`` (what is still missing) is empty."""
        self._ready_checks = getattr(self, '_ready_checks', []) + [check]

    def unmatched(self, graph_view: bool = False) -> List[str]:
        """Handshake expectations not met yet, as readable strings; with ``graph_view``, also
        how many peer endpoints this node's discovery knows on that topic (more known than
        matched: discovered but not matched; as few: never discovered)."""
        missing = [m for check in getattr(self, '_ready_checks', []) for m in check()]
        for kind, topic, n in self._expectations():
            table = self._pubs if kind == 'pub' else self._subs
            ent = table.get(topic)
            if ent is None:
                missing.append(f'{kind}:{topic} (no such endpoint in {self.get_name()})')
                continue
            have = ent.get_subscription_count() if kind == 'pub' else ent.get_publisher_count()
            if have < n:
                missing.append(f'{kind}:{topic} {have}/{n}')
                if graph_view:
                    known = (self.count_subscribers(topic) if kind == 'pub'
                             else self.count_publishers(topic))
                    missing[-1] += f' (discovery knows {known})'
        return missing

    def _external_unmatched(self) -> List[str]:
        """The topics of inputs in sample timing with no publisher matched yet (an external
        driver not started, on another domain, or with a QoS that cannot match): the node
        says ready only once each has one, or after :data:`EXTERNAL_WAIT_S` of wall time
        (then it starts without it and is starved). Not part of :meth:`unmatched`, so the
        launcher's self-healing never restarts a node for a driver that is not there."""
        external = getattr(self, 'external', ())
        if not external or self._ext_gave_up:
            return []
        missing = sorted(self._topics_of[n] for n in external
                         if self._subs[self._topics_of[n]].get_publisher_count() < 1)
        if not missing:
            return []
        now = time.monotonic()
        if self._ext_wait_t0 is None:
            self._ext_wait_t0 = now
        waited = now - self._ext_wait_t0
        if waited > EXTERNAL_WAIT_S:
            self._ext_gave_up = True
            self.get_logger().error(
                f'no publisher on {", ".join(missing)} after {EXTERNAL_WAIT_S:g} s: starting '
                'without it (this node will be starved and the run degraded)')
            return []
        if self._ext_wait_logged == 0.0 or now - self._ext_wait_logged >= EXTERNAL_WAIT_LOG_S:
            self._ext_wait_logged = now
            self.get_logger().warning(
                f'waiting for a publisher on {", ".join(missing)} (an external driver: start '
                f'it on this run\'s ROS_DOMAIN_ID; any QoS) for {waited:.0f} s; the run starts '
                f'when it is matched, or without it after {EXTERNAL_WAIT_S:g} s')
        return missing

    def start_handshake(self, on_ready: Optional[Callable[[], None]] = None) -> None:
        """Poll matching every 20 ms; when complete publish ready and call ``on_ready``."""
        self._on_ready = on_ready
        self._hs_t0 = time.monotonic()
        self._hs_warned = 0.0
        self._hs_timer = self.create_timer(0.02, self._check_ready)

    def _check_ready(self) -> None:
        missing = self.unmatched()
        if missing:
            waited = time.monotonic() - self._hs_t0
            if waited - self._hs_warned > 10.0:
                self._hs_warned = waited
                self.get_logger().warning(f'still waiting for endpoints after {waited:.0f} s: '
                                          + ', '.join(self.unmatched(graph_view=True)))
            return
        if self._external_unmatched():
            return
        self._hs_timer.cancel()
        self.destroy_timer(self._hs_timer)
        if getattr(self, '_publisher_guard', None) is not None:
            self._publisher_guard.lock()      # guarded inputs: the launched producers only
        self._ready_sent = True
        self._ready_pub.publish(String(data=self.get_name()))
        if self._on_ready is not None:
            self._on_ready()

    # ------------------------------------------------------------------ time and status
    def elapsed_ns(self, stamp_ns: int) -> int:
        """Elapsed sim time of an absolute stamp."""
        return int(stamp_ns) - self.epoch_ns

    def stamp(self, elapsed_ns: int):
        """Absolute ``builtin_interfaces/Time`` of an elapsed sim time."""
        return to_stamp(self.epoch_ns + int(elapsed_ns))

    def count_missed(self, inputs: List[str], t_ns: int,
                     applied: str = 'going on without it') -> None:
        """Record a frame whose inputs ``inputs`` timed out, and log what is applied."""
        self.missed_frames += 1
        self.last_missed_input = ','.join(inputs)
        self.get_logger().warning(
            f'frame t={t_ns / NS_PER_S:.3f} s: no {self.last_missed_input} within '
            f'{self.timeout_s:g} s wall; {applied} (missed frames: {self.missed_frames})')

    def report_progress(self, seen_ns: int, final: bool = False) -> None:
        """Publish ``lockstep/progress`` every PROGRESS_EVERY frames of sim time this node
        has received (``seen_ns``: every message stamped up to it is read) and once when it
        has processed its last frame of the run (``final``); the clock master uses it for
        flow control and to end the run only when every node is done."""
        mark = seen_ns // (PROGRESS_EVERY * self.frame_ns)
        if (mark == self._progress_mark and not final) or self.killed:
            return
        self._progress_mark = mark
        msg = LockstepStatus()
        msg.header.stamp = self.stamp(seen_ns)
        msg.node = self.get_name()
        msg.frames = int(self.frames)
        msg.missed_frames = int(self.missed_frames)
        msg.final = bool(final)
        self._progress_pub.publish(msg)

    def is_last_frame(self, t_ns: int, period_ns: int) -> bool:
        """True when frame ``t_ns`` is this node's last one of a run of ``duration_s``."""
        return self.duration_ns > 0 and t_ns + period_ns > self.duration_ns

    def frame_done(self, t_ns: int, final: bool = False) -> None:
        """Bookkeeping after frame ``t_ns``: ``lockstep/status`` once per ``status_period_s``
        of sim time (stamped with it) and at the node's last frame (``final``)."""
        self.sim_t_ns = t_ns
        self.diagnostics.frame(t_ns)
        mark = t_ns // self.status_period_ns
        if final or (mark != self._status_mark and not self._status_held()):
            self._status_mark = mark
            self.publish_status(final=final)

    def _status_held(self) -> bool:
        """True when a periodic status would go only to the launcher's monitor (the same
        readers as when last asked) and the last one is less than
        :data:`MONITOR_STATUS_WALL_S` of wall time old (see there)."""
        return (getattr(self, '_status_monitor_only', False) and not self.missed_frames
                and time.monotonic() - self._lockstep_status_wall < MONITOR_STATUS_WALL_S
                and self._status_pub.get_subscription_count() == self._status_readers_n)

    def _status_watchdog(self) -> None:
        """A stalled node (no frame for 2 s of wall time) still reports once a second."""
        if time.monotonic() - self._lockstep_status_wall >= 2.0:
            self.publish_status()

    def _status_wanted(self) -> bool:
        """Whether a ``lockstep/status`` now would reach a reader (issue 13: 15 % of the
        composed CPU a frame went to statuses nobody kept).

        No: nobody subscribes (the topic is volatile, so a later subscriber would not get it
        either); or the only subscribers are the launcher's monitor, this node is not the one
        it follows and has no missed frames, so its content filter drops the status anyway.
        The subscribers' node names are asked again whenever their count changes, and every
        0.2 s of wall time while discovery has not given all of them yet (rmw then says
        ``_NODE_NAME_UNKNOWN_``); until it has, a reader counts as someone else (publish)."""
        n = self._status_pub.get_subscription_count()
        if not n:
            return False
        if self.missed_frames:
            return True
        now = time.monotonic()
        if n != getattr(self, '_status_readers_n', -1) or (
                not self._status_readers_known and now >= self._status_recheck_at):
            try:
                names = [i.node_name for i in
                         self.get_subscriptions_info_by_topic(self._status_pub.topic_name)]
            except Exception:   # noqa: BLE001 - no graph information: publish
                names = []
            known = len(names) == n and all(
                name and not name.startswith('_NODE_NAME_UNKNOWN') for name in names)
            self._status_monitor_only = known and all(name == MONITOR_NODE for name in names)
            self._status_readers_n, self._status_readers_known = n, known
            self._status_recheck_at = now + 0.2
        return not self._status_monitor_only or self.get_name() == MONITOR_STATUS_OF

    def publish_status(self, final: bool = False) -> None:
        """Publish ``lockstep/status`` (frames, missed frames, wall time), stamped with the
        sim time of the last frame processed.

        After the ``final`` one nothing more is published, so the final status stays the
        latest a listener has.
        """
        if getattr(self, '_final_sent', False):
            return
        self._final_sent = bool(final)
        self._lockstep_status_wall = time.monotonic()
        if not self._status_wanted():
            return
        msg = LockstepStatus()
        msg.header.stamp = self.stamp(self.sim_t_ns)   # sim time of the last frame
        msg.node = self.get_name()
        msg.frames = int(self.frames)
        msg.missed_frames = int(self.missed_frames)
        msg.last_missed_input = self.last_missed_input
        msg.wall_time = time.monotonic() - self._wall0
        msg.final = bool(final)
        self._status_pub.publish(msg)
