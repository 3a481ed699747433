"""The launcher's lifecycle client: ``configure`` then ``activate`` of the managed nodes."""
from __future__ import annotations

import math
import time
from typing import Dict, List, Optional, Tuple

#: Wall-clock limit for a managed node to become active after it was started [s].
LIFECYCLE_DEADLINE_S = 120.0


class Transitions:
    """Drives ``configure`` then ``activate`` of the managed nodes without blocking; after
    :data:`RESEND_S` unanswered, ``get_state`` says what to send (never a transition twice)."""

    #: seconds without an answer before the node's state is asked
    RESEND_S = 5.0

    def __init__(self, node, names: List[str], deadline_s: float = LIFECYCLE_DEADLINE_S):
        from lifecycle_msgs.msg import State, Transition
        from lifecycle_msgs.srv import ChangeState, GetState

        self._srv = ChangeState
        self._get_srv = GetState
        self._ids = {'configure': Transition.TRANSITION_CONFIGURE,
                     'activate': Transition.TRANSITION_ACTIVATE}
        #: primary state id -> the transition due next ('' once active)
        self._next = {State.PRIMARY_STATE_UNCONFIGURED: 'configure',
                      State.PRIMARY_STATE_INACTIVE: 'activate',
                      State.PRIMARY_STATE_ACTIVE: ''}
        self._node = node
        self.clients = {n: node.create_client(ChangeState, f'/{n}/change_state')
                        for n in names}
        self._get_clients: Dict[str, object] = {}
        #: node -> 'starting' (no service yet), 'configure', 'activate' (awaiting the
        #: answer), 'get_state' (asking after a lost answer) or 'active'
        self.step = {n: 'starting' for n in names}
        self._sent_at: Dict[str, float] = {}
        self._token: Dict[str, int] = {n: 0 for n in names}
        self.resent: Dict[str, int] = {n: 0 for n in names}   # lost answers, per node
        self.failed: Dict[str, str] = {}     # node -> the transition it refused
        self.deadline = time.monotonic() + deadline_s
        self.deadline_s = deadline_s
        #: per node: its deadline (moved on by a restart), the last answer or first request
        self._deadlines: Dict[str, float] = {n: self.deadline for n in names}
        self._heard: Dict[str, float] = {}
        self.unanswered_s = math.inf         # (the launcher sets HEAL_UNANSWERED_S)

    def postpone(self, name: str, seconds: float) -> None:
        """Report ``name`` as unanswered again ``seconds`` from now (at the earliest)."""
        self._heard[name] = time.monotonic() - self.unanswered_s + seconds

    def reset(self, name: str) -> None:
        """Start ``name`` again from 'starting' (its process was restarted), a full deadline."""
        self._token[name] += 1
        self.step[name] = 'starting'
        self._heard.pop(name, None)
        self._sent_at.pop(name, None)
        self._deadlines[name] = time.monotonic() + self.deadline_s

    @property
    def pending(self) -> bool:
        """True while a node is not active yet (and none failed)."""
        return not self.failed and any(s != 'active' for s in self.step.values())

    def poll(self) -> Optional[Tuple[str, str]]:
        """Send what is due; ``(node, transition | 'deadline' | 'unanswered')`` or None."""
        if self.failed:
            return next(iter(self.failed.items()))
        now = time.monotonic()
        for name, step in self.step.items():
            if step == 'starting' and self.clients[name].service_is_ready():
                self._call(name, 'configure')
                self._heard.setdefault(name, now)
            elif step not in ('starting', 'active') and \
                    now - self._sent_at[name] > self.RESEND_S:
                self.resent[name] += 1
                self._ask_state(name)
        late = [n for n, s in self.step.items() if s != 'active']
        for name in late:
            if now > self._deadlines[name]:
                return name, 'deadline'
        for name in late:
            if name in self._heard and now - self._heard[name] > self.unanswered_s:
                return name, 'unanswered'
        return None

    def _send(self, name: str, step: str, client, request, on_answer) -> None:
        self._token[name] += 1
        token = self._token[name]
        self.step[name] = step
        self._sent_at[name] = time.monotonic()
        future = client.call_async(request)
        future.add_done_callback(
            lambda f: on_answer(name, step, f) if self._token[name] == token else None)

    def _call(self, name: str, transition: str) -> None:
        request = self._srv.Request()
        request.transition.id = self._ids[transition]
        self._send(name, transition, self.clients[name], request, self._answered)

    def _ask_state(self, name: str) -> None:
        if name not in self._get_clients:
            self._get_clients[name] = self._node.create_client(self._get_srv,
                                                               f'/{name}/get_state')
        self._send(name, 'get_state', self._get_clients[name], self._get_srv.Request(),
                   self._state_answered)

    def _answered(self, name: str, transition: str, future) -> None:
        result = future.result() if not future.cancelled() else None
        self._heard[name] = time.monotonic()
        if result is None or not result.success:
            self.failed.setdefault(name, transition)
        elif transition == 'configure':
            self._call(name, 'activate')
        else:
            self.step[name] = 'active'

    def _state_answered(self, name: str, _step: str, future) -> None:
        result = future.result() if not future.cancelled() else None
        if result is not None:
            self._heard[name] = time.monotonic()
        due = self._next.get(result.current_state.id) if result is not None else None
        if due is None:          # no answer, or a transition still under way: ask again later
            return
        if due:
            self._call(name, due)
        else:
            self.step[name] = 'active'
