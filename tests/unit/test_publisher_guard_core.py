"""Publisher identity bookkeeping (issue 12, ``adcs_nodes.nodes.publisher_guard``).

The rules under test (docs/security.md): after the handshake lock a guarded topic is accepted
only from the locked GIDs; a refused message never consumes its stamp (so the true message of
a frame still gets through after a forged one); a stamp already accepted is a duplicate; an
unguarded topic is never checked. No ROS needed.
"""
import pytest

from adcs_nodes.nodes.publisher_guard import PublisherGuard, gid_hex, parse_expected

CMD = '/adcs/actuator_command'
ENV = '/sim/environment'
TRUE = bytes(range(16))
FORGER = bytes(range(16, 32))


def locked_guard(**kw):
    g = PublisherGuard({CMD: 'controller_manager', ENV: 'environment'}, **kw)
    g.lock(CMD, [TRUE])
    g.lock(ENV, [bytes(16)])
    return g


def test_parse_expected_entries():
    assert parse_expected(['adcs/actuator_command=controller_manager', '',
                           ' sim/environment = environment ']) == {
        'adcs/actuator_command': 'controller_manager', 'sim/environment': 'environment'}
    assert parse_expected([]) == {}
    for bad in (['adcs/actuator_command'], ['=controller_manager'], ['topic=']):
        with pytest.raises(ValueError, match='want'):
            parse_expected(bad)
    with pytest.raises(ValueError, match='twice'):
        parse_expected(['a=x', 'a=y'])


def test_before_the_lock_every_guarded_message_is_refused():
    g = PublisherGuard({CMD: 'controller_manager'})
    assert not g.locked
    assert g.check(CMD, TRUE, 0) == 'before_handshake'
    assert g.check('/other', FORGER, 0) is None        # not guarded: accepted as before
    g.lock(CMD, [TRUE])
    assert g.locked
    assert g.check(CMD, TRUE, 0) is None               # the refused one did not use stamp 0


def test_foreign_publisher_refused_and_its_stamp_left_to_the_true_one():
    g = locked_guard()
    for k in range(5):
        t = k * 2_000_000_000
        assert g.check(CMD, FORGER, t) == 'foreign_publisher'      # forged first
        assert g.check(CMD, TRUE, t) is None                       # the true one still used
        assert g.check(CMD, FORGER, t) == 'foreign_publisher'      # and forged after
    assert g.check(ENV, TRUE, 0) == 'foreign_publisher'    # locked per topic
    assert g.check('/sim/state', FORGER, 0) is None


def test_duplicate_stamp_from_the_locked_publisher_or_in_process():
    g = locked_guard()
    assert g.check(CMD, TRUE, 4) is None
    assert g.check(CMD, TRUE, 4) == 'duplicate_stamp'
    assert g.check(CMD, None, 4) == 'duplicate_stamp'      # in-process delivery: stamp only
    assert g.check(CMD, None, 6) is None
    assert g.check(CMD, TRUE, 6) == 'duplicate_stamp'
    assert g.check(ENV, bytes(16), 4) is None               # stamps are per topic


def test_stamps_older_than_the_remembered_window_are_refused():
    g = locked_guard(history=3)
    for t in (10, 20, 30, 40):
        assert g.check(CMD, TRUE, t) is None
    # 10 left the window (3 stamps: 20, 30, 40): it can no longer be told from a duplicate
    assert g.check(CMD, TRUE, 10) == 'old_stamp'
    assert g.check(CMD, TRUE, 5) == 'old_stamp'
    assert g.check(CMD, TRUE, 20) == 'duplicate_stamp'
    assert g.check(CMD, TRUE, 25) is None                   # inside the window, not seen
    with pytest.raises(ValueError):
        PublisherGuard({CMD: 'x'}, history=0)


def test_lock_errors_and_new_publishers_reported_once():
    g = PublisherGuard({CMD: 'controller_manager'})
    with pytest.raises(ValueError, match='controller_manager'):
        g.lock(CMD, [])
    with pytest.raises(KeyError):
        g.lock('/not/guarded', [TRUE])
    assert g.new_publishers(CMD, [FORGER]) == []            # not locked yet: nothing to say
    g.lock(CMD, [TRUE])
    assert g.new_publishers(CMD, [TRUE, FORGER]) == [FORGER]
    assert g.new_publishers(CMD, [TRUE, FORGER]) == []
    other = bytes([7] * 16)
    assert g.new_publishers(CMD, [other, FORGER]) == [other]


def test_counts_and_diagnostic_values():
    g = locked_guard()
    assert g.count(CMD, 'foreign_publisher', 'a') == 1
    assert g.count(CMD, 'foreign_publisher', 'b') == 2
    assert g.count(ENV, 'foreign_publisher', 'c') == 1
    assert g.count(CMD, 'duplicate_stamp', 'd') == 1
    with pytest.raises(KeyError):
        g.count(CMD, 'no_such_reason', 'e')
    d = g.diagnostic_values()
    assert d['security_events'] == '4'
    assert d['security_foreign_publisher'] == '3'
    assert d['security_duplicate_stamp'] == '1'
    assert d['security_second_publisher'] == '0'
    assert d['last_security_event'] == 'd'
    assert gid_hex(b'\x01\xff') == '01ff' and gid_hex(None) == '-'


def test_graph_names_the_producer_of_each_guarded_input():
    """The launcher's graph: dynamics and the manager are guarded, each subscribed lockstep
    topic names the one node of the graph that publishes it; their events are recorded."""
    import os

    from adcs_nodes.graph import build_graph
    from adcs_nodes.scenario import load_scenario
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    sc = load_scenario(os.path.join(root, 'scenarios', 'paper000_control.yaml'))
    nodes = {n.name: n for n in build_graph(sc, 100.0, record=True)}
    assert nodes['dynamics'].params['expected_publishers'] == [
        'sim/environment=environment', 'adcs/actuator_command=controller_manager']
    assert sorted(nodes['controller_manager'].params['expected_publishers']) == [
        'adcs/attitude_estimate=estimator',
        'adcs/controllers/bdot/command=bdot_controller',
        'adcs/controllers/magnetic/command=magnetic_controller']
    guarded = [n for n in nodes.values() if 'expected_publishers' in n.params]
    assert sorted(n.name for n in guarded) == ['controller_manager', 'dynamics']
    recorded = [p.split('=')[0] for p in nodes['recorder'].params['topics']]
    assert 'adcs/security_events' in recorded
    assert 'sub:adcs/security_events=2' in nodes['recorder'].params['expected_matches']
    # free tumble: no command producer, only the environment is named
    sc = load_scenario(os.path.join(root, 'scenarios', 'free_tumble.yaml'))
    nodes = {n.name: n for n in build_graph(sc, 100.0)}
    assert nodes['dynamics'].params['expected_publishers'] == ['sim/environment=environment']


def test_the_expected_node_re_creating_its_publisher_is_locked_to_once_the_old_is_gone():
    """A lifecycle cleanup and configure gives the expected node a new publisher GID: taken
    only when none of the locked ones is left (a second publisher beside the first is not)."""
    from adcs_nodes.nodes.publisher_guard import PublisherGuard
    g = PublisherGuard({'/cmd': 'bdot_controller'})
    old, new, stranger = b'\x01' * 16, b'\x02' * 16, b'\x03' * 16
    g.lock('/cmd', [old])
    assert g.check('/cmd', new, 10) == 'foreign_publisher'
    assert not g.relock('/cmd', [new], present=[old, new])     # the old one is still there
    assert not g.relock('/cmd', [], present=[stranger])         # not the expected node's
    assert g.relock('/cmd', [new], present=[new])
    assert g.check('/cmd', new, 10) is None and g.check('/cmd', old, 12) == 'foreign_publisher'
    assert not g.relock('/cmd', [new], present=[new])           # already locked to it
    assert g.diagnostic_values()['relocks'] == '1'
