"""FrameSync's ordered per-input queues (issue 13) against a naive reference synchroniser.

Truth: :class:`NaiveSync`, written here from the timing rules of DESIGN section 6 with plain
scans and sorts (the form ``FrameSync`` had before the queues): the latest message at or before
a frame is the maximum of the stamps not after it, the history keeps the newest ``history``
stamps, pruning keeps the newest stamp before the frame; misses are in a row when no message is
stamped between the stamps they lacked, a dead input returns with its first message stamped
after its death (stored already or arriving later) and is held for ``hold`` after it (issue 38).
Random sequences of arrivals (in order, out of order, duplicated stamps), queries, prunes and
misses must give the same answers from both.
"""
from hypothesis import given, settings
from hypothesis import strategies as st

from adcs_nodes.core.lockstep import FrameSync

P = 10          # base frame [ns] of the test (any positive integer works)
SPECS = {'env': P, 'mag': 2 * P, 'cmd': (3 * P, 'previous'), 'live': 0}


class NaiveSync:
    """Reference: every query scans all stored stamps."""

    def __init__(self, specs, history, dead_after, hold=0):
        self.inp = {}
        for name, spec in specs.items():
            period, kind = spec if isinstance(spec, tuple) else (spec, 'frame')
            self.inp[name] = {'p': period, 'kind': kind if period else 'latest',
                              'msgs': {}, 'latest': None, 'misses': 0, 'dead': False,
                              'revived': -1, 'held': False, 'last': -1, 'died': -1}
        self.history, self.dead_after, self.hold = history, dead_after, hold

    def required(self, name, t):
        i = self.inp[name]
        if i['p'] == 0:
            return None
        if i['kind'] == 'previous':
            return None if t <= 0 else ((t - 1) // i['p']) * i['p']
        return t if t % i['p'] == 0 else None

    def add(self, name, s, v):
        i = self.inp[name]
        if i['dead']:
            if s <= i['died']:
                return False            # stale: dropped
            self.revive(i, s)           # a return: not stored, awaited after the hold
            return True
        if i['held'] and s <= i['revived']:
            return False                # within the hold: not stored
        i['msgs'][s] = v
        if len(i['msgs']) > self.history:
            del i['msgs'][min(i['msgs'])]
        if i['latest'] is None or s >= i['latest'][0]:
            i['latest'] = (s, v)
        return False

    def missing(self, t):
        return [n for n, i in self.inp.items() if not i['dead'] and t > i['revived']
                and self.required(n, t) is not None and self.required(n, t) not in i['msgs']]

    def value(self, name, t):
        i = self.inp[name]
        if i['kind'] == 'previous':
            s = self.required(name, t)
            return None if s is None else i['msgs'].get(s)
        older = [s for s in i['msgs'] if s <= t]
        if older:
            return i['msgs'][max(older)]
        if i['latest'] is not None and i['latest'][0] <= t:
            return i['latest'][1]
        return None

    def prune(self, t):
        for i in self.inp.values():
            for s in sorted(s for s in i['msgs'] if s < t)[:-1]:
                del i['msgs'][s]

    def revive(self, i, s):
        i['dead'], i['held'], i['misses'], i['last'] = False, True, 0, -1
        i['revived'] = s + self.hold
        for k in [k for k in i['msgs'] if i['died'] < k <= i['revived']]:
            del i['msgs'][k]
        if i['latest'] is not None and i['died'] < i['latest'][0] <= i['revived']:
            i['latest'] = (max(i['msgs']), i['msgs'][max(i['msgs'])]) if i['msgs'] else None

    def record_misses(self, t):
        newly = []
        for n in self.missing(t):
            i = self.inp[n]
            s = self.required(n, t)
            between = any(i['last'] < k < s for k in i['msgs'])
            i['misses'] = 1 if between else i['misses'] + 1
            i['last'] = s
            if self.dead_after and i['misses'] >= self.dead_after:
                i['dead'], i['died'] = True, s
                newly.append(n)
                later = [k for k in i['msgs'] if k > s]
                if later:
                    self.revive(i, min(later))
        return newly


OPS = st.lists(st.tuples(st.sampled_from(['add', 'add', 'add', 'value', 'missing', 'prune',
                                          'miss']),
                         st.sampled_from(sorted(SPECS)),
                         st.integers(min_value=-2, max_value=40)), max_size=200)


@settings(max_examples=300, deadline=None)
@given(ops=OPS, history=st.integers(min_value=1, max_value=6),
       dead_after=st.integers(min_value=0, max_value=3), hold=st.sampled_from([0, P, 5 * P]))
def test_queues_answer_as_the_naive_scan(ops, history, dead_after, hold):
    sync = FrameSync(SPECS, history=history, dead_after=dead_after, revive_hold_ns=hold)
    ref = NaiveSync(SPECS, history, dead_after, hold)
    for k, (op, name, x) in enumerate(ops):
        t = x * P // 2          # stamps on and between frames
        if op == 'add':
            assert sync.add(name, t, (name, t, k)) == ref.add(name, t, (name, t, k))
        elif op == 'value':
            assert sync.value(name, t) == ref.value(name, t), (name, t)
        elif op == 'missing':
            assert sync.missing(t) == ref.missing(t)
            assert sync.ready(t) == (not ref.missing(t))
        elif op == 'prune':
            sync.prune(t)
            ref.prune(t)
        else:
            assert sync.record_misses(t) == ref.record_misses(t)
        for n in SPECS:       # the stored stamps stay the same set, in ascending order
            assert sync._inputs[n].stamps == sorted(ref.inp[n]['msgs'])
            assert sync.value(n, None) == (None if ref.inp[n]['latest'] is None
                                           else ref.inp[n]['latest'][1])


def test_an_old_message_beyond_the_history_is_not_kept():
    sync = FrameSync({'a': P}, history=2)
    for s in (3 * P, 4 * P, P):          # P arrives last and is the oldest: dropped at once
        sync.add('a', s, s)
    assert sync.missing(P) == ['a'] and sync.value('a', 2 * P) is None
    assert sync.value('a', 3 * P) == 3 * P and sync.value('a', None) == 4 * P
