"""One frame-synchronisation rule whatever the order of arrival (issue 38 item 1).

A consumer does not wait for a dead input, so the world may run ahead of it (the controllers
stop waiting for a dead estimate; the star tracker's returning sample then reaches the
estimator before the estimator has counted its own third miss). What the consumer does in
each frame (the inputs it misses and the value it takes of each) must not depend on that:
the same producers' messages, delivered in stamp order frame by frame (the FrameLoop) or up
to ``hold`` frames ahead of the consumer (the graph under load; the clock master keeps the
world within the re-admission hold of every node), give the same frames.

Each producer publishes or is silent in each of its frames (random runs of silence); every
message stamped at or before a frame has arrived when the frame fires (what the lockstep
waits for), messages stamped later have arrived up to a random, non-decreasing lead.
"""
from hypothesis import given, settings
from hypothesis import strategies as st

from adcs_nodes.core.lockstep import FrameSync

P = 10                                    # base frame [ns]
FRAMES = 40
SPECS = {'a': P, 'b': 2 * P, 'cmd': (P, 'previous')}


def published(pattern, period):
    """Stamps a producer publishes: its frames where ``pattern`` (cycled) is True."""
    return [k * P for k in range(0, FRAMES + 8) if k % (period // P) == 0
            and pattern[(k // (period // P)) % len(pattern)]]


def run(messages, leads, dead_after, hold):
    """The consumer's frames: ``[(t, missing, values)]``, messages delivered up to
    ``t + leads[t]`` before frame ``t`` fires."""
    sync = FrameSync(SPECS, dead_after=dead_after, revive_hold_ns=hold * P)
    pending = sorted((s, name) for name, stamps in messages.items() for s in stamps)
    out = []
    for k in range(FRAMES):
        t = k * P
        while pending and pending[0][0] <= t + leads[k] * P:
            s, name = pending.pop(0)
            sync.add(name, s, (name, s))
        missing = sync.missing(t)
        if missing:
            sync.record_misses(t)
        values = {n: sync.value(n, t) for n in sync.names}
        sync.prune(t)
        out.append((t, missing, values))
    return out


PATTERN = st.lists(st.booleans(), min_size=1, max_size=12)


@settings(max_examples=400, deadline=None)
@given(a=PATTERN, b=PATTERN, cmd=PATTERN, dead_after=st.integers(1, 3),
       hold=st.integers(0, 6),
       steps=st.lists(st.integers(0, 3), min_size=FRAMES, max_size=FRAMES))
def test_frames_do_not_depend_on_how_far_ahead_the_world_is(a, b, cmd, dead_after, hold,
                                                            steps):
    messages = {'a': published(a, P), 'b': published(b, 2 * P), 'cmd': published(cmd, P)}
    leads, lead = [], 0
    for k, step in enumerate(steps):       # non-decreasing world time, within the hold
        lead = min(max(lead - 1 + step, 0), hold)
        leads.append(lead)
    in_order = run(messages, [0] * FRAMES, dead_after, hold)
    assert run(messages, leads, dead_after, hold) == in_order


def test_the_issue_case_a_return_seen_before_the_third_miss():
    """The star tracker silent from 30 s, back at 35 s; its 35 s sample reaches the estimator
    before its miss of 32 s is counted (the world ran ahead): not used, held, as in the
    plain engine (the composed engine used it and resumed at 35 s)."""
    star = [k * P for k in range(FRAMES) if not 30 <= k < 35]
    late = [0] * 32 + [3] + [0] * (FRAMES - 33)           # frame 32 fires after 35 arrived
    for leads in ([0] * FRAMES, late):
        frames = run({'a': star, 'b': [], 'cmd': []}, leads, 3, 5)
        used = [t // P for t, _, v in frames if v['a'] is not None and v['a'][1] == t]
        assert used == list(range(30)) + list(range(41, FRAMES)), leads   # held to 35 + 5
