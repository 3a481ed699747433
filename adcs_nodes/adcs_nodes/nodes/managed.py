"""Managed (lifecycle) flight-software nodes: :class:`ManagedLockstepNode`.

The estimator, the controllers, the controller manager and guidance are ROS 2 managed nodes
(``rclpy.lifecycle``); the states, ``autostart`` and how ``adcs run`` drives them are in
``docs/topics.md``, "Lifecycle". ``configure`` reads the parameters and builds the core and
every endpoint; ``cleanup`` destroys them, and a new ``configure`` during a lockstep run
rejoins it at the world's frame (:mod:`adcs_nodes.core.frame_schedule`). Inactive: frames are
processed, the lifecycle publishers drop the outputs; status, progress and diagnostics go on.

Run-time parameter changes: only a registered controller's own parameters are writable
(:data:`REBUILT_AT_RUN_TIME`): validated when set, applied at the next frame boundary by
rebuilding the core (from its reset state); a value set to what it is changes nothing.
"""
from __future__ import annotations

import traceback
from typing import Any, Dict, List, Optional

from rclpy.lifecycle import LifecycleNodeMixin, LifecyclePublisher, TransitionCallbackReturn
from rclpy.node import Node

from adcs_nodes.core.lockstep import NS_PER_S
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes.lockstep_node import NODE_OPTIONS, LockstepNode

#: Node attributes of the parameter layer (``adcs_nodes.nodes.params``) that exist before
#: ``configure`` (the ``autostart`` parameter) and grow in it: restored by ``cleanup``.
_SAVED_ATTRS = ('_adcs_specs', '_adcs_prefixes', '_asked')
#: Registry kinds whose own parameters a node applies at run time: the core is rebuilt from
#: its entry with the new values at the next frame boundary. A controller starts again from
#: its reset state (as a controller switched in does); an estimator would lose its filter
#: and a sensor its seeded noise stream, so their parameters are read-only.
REBUILT_AT_RUN_TIME = ('controller',)


class ManagedLockstepNode(LifecycleNodeMixin, LockstepNode):
    """A :class:`LockstepNode` with the ROS 2 lifecycle (see the module docstring).

    A subclass puts what its constructor did (read parameters, build the core, create
    endpoints) in :meth:`configure`, and may override :meth:`activated`. Attributes it needs
    before ``configure`` (a constructor argument) are set before ``super().__init__``.
    """

    def __init__(self, name: str, **kwargs: Any) -> None:
        Node.__init__(self, name, **NODE_OPTIONS, **kwargs)   # (no undeclared parameters)
        LifecycleNodeMixin.__init__(self)
        self.done = False
        self.exit_code = 0
        #: why the last ``configure`` failed ('' if it did not)
        self.configure_error = ''
        self._outputs_managed = False     # publishers created now are lifecycle publishers
        self._active = False
        self._saved: Optional[Dict[str, Any]] = None
        self._world_seen_ns = -1          # sim time seen before a cleanup (-1: none)
        self._params_pending: Dict[str, Any] = {}
        autostart = self.param('autostart', True, 'configure and activate at start (false: '
                               'wait for the lifecycle services)')
        if autostart:   # (a failed configure raises: the caller reports it, exit code 2)
            self._autostarting = True
            if self.trigger_configure() != TransitionCallbackReturn.SUCCESS:
                raise ValueError(self.configure_error or 'configure failed')
            if self.trigger_activate() != TransitionCallbackReturn.SUCCESS:
                raise ValueError('activate failed')
            self._autostarting = False

    # ------------------------------------------------------------------ subclass hooks
    def configure(self) -> None:
        """Read and validate the parameters, build the core, create the endpoints."""
        raise NotImplementedError

    def activated(self) -> None:
        """Called once the outputs are enabled (e.g. to publish a latched status)."""

    @property
    def lifecycle_state(self) -> str:
        """Label of the current lifecycle state (``unconfigured``, ``inactive``, ...)."""
        return self._state_machine.current_state[1]

    @property
    def active(self) -> bool:
        """True in the ``active`` state (outputs enabled)."""
        return self._active

    # ------------------------------------------------------------------ run-time parameters
    def _rebuilt_entry(self):
        """The registry entry whose core this node rebuilds on a run-time change, or None."""
        entry = getattr(self, 'entry', None)
        return entry if getattr(entry, 'kind', None) in REBUILT_AT_RUN_TIME else None

    def applies_at_run_time(self, name: str) -> bool:
        """Whether a run-time change of ``name`` takes effect (else it is read-only): the own
        parameters of a registered controller."""
        entry = self._rebuilt_entry()
        return entry is not None and any(p.name == name for p in entry.params)

    def _held(self, attr: str) -> Any:
        """``attr`` (``core``, ``ctx``) of the node's frame component, else of the node."""
        for holder in (getattr(self, 'component', None), self):
            if holder is not None and hasattr(holder, attr):
                return getattr(holder, attr)
        return None

    def _build_core(self, changes: Dict[str, Any]):
        """A core of this node's entry, its current parameters overlaid by ``changes``."""
        entry = self._rebuilt_entry()
        values = {p.name: changes[p.name] if p.name in changes
                  else node_params._plain(self.get_parameter(p.name).value)
                  for p in entry.params}
        return entry.build(entry.validate(values), self._held('ctx'))

    def check_parameters(self, changes: Dict[str, Any]) -> str:
        """The controller must build with the new values (e.g. magnetic's k > beta /
        (2 alpha)): the reason if not, else ''. The values that differ from the current ones
        are kept for :meth:`parameters_set`."""
        if self._rebuilt_entry() is None or self._held('ctx') is None:
            return ''
        try:
            self._build_core(changes)
        except ValueError as exc:
            return f'{", ".join(changes)}: {exc}'
        self._checked = {n: v for n, v in changes.items()
                         if v != node_params._plain(self.get_parameter(n).value)}
        return ''

    def parameters_set(self, names: List[str]) -> None:
        """Run-time change accepted: applied at the next frame boundary. A value set to what
        it is already changes nothing (the controller is not restarted)."""
        checked = getattr(self, '_checked', {})
        self._params_pending.update({n: checked[n] for n in names if n in checked})
        if not any(n in checked for n in names):
            self.get_logger().info(f'parameters {", ".join(names)}: unchanged values, '
                                   'nothing to apply')
        self._checked = {}

    def apply_parameters(self) -> None:
        """At a frame boundary: the controller core is rebuilt with the parameters changed
        since the last frame (the same object, so every holder sees it; it starts from its
        reset state)."""
        if not self._params_pending or self._rebuilt_entry() is None:
            return
        names, self._params_pending = sorted(self._params_pending), {}
        core, new = self._held('core'), self._build_core({})
        if core is None or type(new) is not type(core) or not hasattr(core, '__dict__'):
            self.get_logger().error(f'parameters {", ".join(names)} set but not applied: no '
                                    'controller core to rebuild')
            return
        vars(core).clear()
        vars(core).update(vars(new))
        self.get_logger().info(f'parameters {", ".join(names)} applied from this frame on '
                               f'(t={self.sim_t_ns / NS_PER_S:g} s; the controller restarts '
                               'from its reset state)')

    # ------------------------------------------------------------------ endpoints
    def create_publisher(self, *args: Any, **kwargs: Any):
        """Publishers created by :meth:`configure` are lifecycle publishers (silent unless
        active); the lockstep bookkeeping ones, created before, are plain."""
        if not getattr(self, '_outputs_managed', False) or 'publisher_class' in kwargs:
            return super().create_publisher(*args, **kwargs)
        pub = super().create_publisher(*args, publisher_class=LifecyclePublisher, **kwargs)
        self.add_managed_entity(pub)
        return pub

    def _entities(self) -> Dict[str, set]:
        return {'publishers': set(self.publishers), 'subscriptions': set(self.subscriptions),
                'timers': set(self.timers), 'services': set(self.services),
                'clients': set(self.clients), 'waitables': set(self.waitables)}

    # ------------------------------------------------------------------ transitions
    def on_configure(self, state) -> TransitionCallbackReturn:
        """``configure``: parameters, core, endpoints (the module docstring)."""
        self.configure_error = ''
        self._saved = {
            'entities': self._entities(), 'names': set(vars(self)),
            'parameters': dict(self._parameters), 'descriptors': dict(self._descriptors),
            'on_set': list(self._on_set_parameters_callbacks),
            'attrs': {a: _copy(getattr(self, a)) for a in _SAVED_ATTRS if hasattr(self, a)}}
        try:   # configured again during a run: rejoin at the world's frame, not at 0
            self.setup_lockstep(rejoin=self._world_seen_ns >= 0)
            self._outputs_managed = True
            self.add_ready_check(lambda: [] if self._active else
                                 [f'{self.get_name()} is not active (lifecycle)'])
            self.configure()
        except ValueError as exc:
            self.configure_error = str(exc)
        except Exception as exc:   # a bug, not a bad value: keep the traceback in the log
            self.configure_error = f'{type(exc).__name__}: {exc}'
            self.get_logger().error(traceback.format_exc())
        finally:
            self._outputs_managed = False
        if self.configure_error:
            if not getattr(self, '_autostarting', False):
                self.get_logger().error(f'configuration error: {self.configure_error}')
            self._undo_configure()
            return TransitionCallbackReturn.FAILURE
        return super().on_configure(state)

    def on_activate(self, state) -> TransitionCallbackReturn:
        """``activate``: enable the outputs; the handshake may now say ready."""
        ret = super().on_activate(state)
        if ret == TransitionCallbackReturn.SUCCESS:
            self._active = True
            self.activated()
        return ret

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        """``deactivate``: frames go on, outputs are dropped."""
        self._active = False
        return super().on_deactivate(state)

    def on_cleanup(self, state) -> TransitionCallbackReturn:
        """``cleanup``: back to ``unconfigured`` (the sim time seen is kept, so a new
        ``configure`` rejoins the run at the world's frame)."""
        self._active = False
        schedule = getattr(self, 'schedule', None)
        if schedule is not None and schedule.seen_ns >= 0:
            self._world_seen_ns = schedule.seen_ns
            self.get_logger().info(f'cleanup at sim t={schedule.seen_ns / NS_PER_S:g} s: a '
                                   'new configure rejoins the run at the world\'s frame')
        self._undo_configure()
        return super().on_cleanup(state)

    def on_shutdown(self, state) -> TransitionCallbackReturn:
        """``shutdown``: outputs off, the process ends (``done``)."""
        self._active = False
        ret = super().on_shutdown(state)
        self.done = True
        return ret

    def on_error(self, state) -> TransitionCallbackReturn:
        """An error in a transition: back to ``unconfigured`` (rclpy's default)."""
        self._active = False
        self._undo_configure()
        return super().on_error(state)

    def _undo_configure(self) -> None:
        """Destroy what ``configure`` created and restore the parameters as they were."""
        saved, self._saved = self._saved, None
        if saved is None:
            return
        before = saved['entities']
        now = self._entities()
        for pub in now['publishers'] - before['publishers']:
            self._managed_entities.discard(pub)
            self.destroy_publisher(pub)      # (and its QoS event handlers)
        for kind, destroy in (('subscriptions', self.destroy_subscription),
                              ('timers', self.destroy_timer),
                              ('services', self.destroy_service),
                              ('clients', self.destroy_client)):
            for entity in now[kind] - before[kind]:
                destroy(entity)
        for waitable in set(self.waitables) - before['waitables']:   # action servers
            destroy = getattr(waitable, 'destroy', None)
            if destroy is not None:
                destroy()
            if waitable in set(self.waitables):
                self.remove_waitable(waitable)
        # parameters: rclpy refuses to undeclare read-only ones, so the tables are restored;
        # a value changed at run time is kept for the next configure
        params, descs = saved['parameters'], saved['descriptors']
        current = dict(self._parameters)
        self._parameters.clear()
        self._descriptors.clear()
        for name, param in params.items():
            self._parameters[name] = current.get(name, param)
            self._descriptors[name] = descs[name]
        self._on_set_parameters_callbacks[:] = saved['on_set']
        for attr in _SAVED_ATTRS:
            if attr in saved['attrs']:
                setattr(self, attr, saved['attrs'][attr])
        # what configure set on the node (core, endpoints, counters, handshake state) goes;
        # rclpy's own name-mangled attributes stay
        for attr in set(vars(self)) - saved['names']:
            if '__' not in attr:
                delattr(self, attr)


def _copy(value: Any) -> Any:
    """Shallow copy of a dict, set or list (the saved parameter-layer attributes)."""
    return type(value)(value) if isinstance(value, (dict, set, list)) else value
