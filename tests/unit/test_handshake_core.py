"""The start handshake's pure part (``adcs_nodes.core.handshake``): expectations parsed and
checked against matched counts, and the bounded wait for an external driver."""
import pytest

from adcs_nodes.core import handshake
from adcs_nodes.core.handshake import DriverWait, parse_expectations, unmet


def test_expectations_are_parsed_resolved_and_checked():
    exp = parse_expectations(['pub:adcs/cmd=2', '', 'sub:/sensors/mag=1'],
                             lambda t: t if t.startswith('/') else '/' + t)
    assert exp == [('pub', '/adcs/cmd', 2), ('sub', '/sensors/mag', 1)]
    counts = {('pub', '/adcs/cmd'): 1}
    assert unmet(exp, lambda k, t: counts.get((k, t)), 'est') == [
        'pub:/adcs/cmd 1/2', 'sub:/sensors/mag (no such endpoint in est)']
    assert unmet(exp, lambda k, t: counts.get((k, t)), 'est', known=lambda k, t: 3)[0] == \
        'pub:/adcs/cmd 1/2 (discovery knows 3)'
    counts.update({('pub', '/adcs/cmd'): 2, ('sub', '/sensors/mag'): 1})
    assert unmet(exp, lambda k, t: counts.get((k, t)), 'est') == []


@pytest.mark.parametrize('bad', ['pub:/x', 'sub:/x=two', 'both:/x=1', 'nothing'])
def test_a_bad_entry_is_refused_with_the_form_wanted(bad):
    with pytest.raises(ValueError, match='want "pub:<topic>=<n>"'):
        parse_expectations([bad], str)


def test_the_driver_wait_is_bounded_and_says_so_every_10_s():
    w = DriverWait()
    assert w.check([], 0.0) == (False, None)                  # nothing missing
    waiting, line = w.check(['/sensors/mag'], 100.0)
    assert waiting and line[0] == 'warning' and '/sensors/mag' in line[1]
    assert w.check(['/sensors/mag'], 100.0 + handshake.EXTERNAL_WAIT_LOG_S - 0.1) == (True, None)
    assert w.check(['/sensors/mag'], 100.0 + handshake.EXTERNAL_WAIT_LOG_S)[1] is not None
    waiting, line = w.check(['/sensors/mag'], 100.0 + handshake.EXTERNAL_WAIT_S + 0.1)
    assert not waiting and line[0] == 'warning' and 'starting without it' in line[1]
    assert w.check(['/sensors/mag'], 1e6) == (False, None)    # gave up: never again
