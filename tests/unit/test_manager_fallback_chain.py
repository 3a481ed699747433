"""The manager's fallback list (issue 21): a wheel controller whose command is unusable (a
refusal: its wheels left cannot cover the demand) hands over to the magnetic law, which needs
no wheel, before the safe B-dot; each step is said in the fault."""
import numpy as np
import pytest

from adcs_nodes.core.control import Command, Estimate
from adcs_nodes.core.manager import ControllerManagerCore

MPI = np.array([0.0, 0.0, 0.0])
MAG = np.array([1.0, 0.0, 0.0])
BDOT = np.array([0.0, 2.0, 0.0])
WHEEL_FAULT = 'wheel wheel_x stuck since t = 1 s: the 2 healthy wheels of 3 span 2 axes'


def cmd(dipole, wheels=(0.0, 0.0, 0.0), reason='', refused=False):
    return Command(np.asarray(dipole, float), np.asarray(wheels, float), np.zeros(3), reason,
                   refused=refused)


def mgr(fallback=('magnetic',), **kw):
    return ControllerManagerCore(['mpi', 'magnetic', 'bdot'], 'bdot', initial='mpi',
                                 max_dipole_Am2=5.0, max_wheel_torque=[0.01] * 3,
                                 fallback=fallback, **kw)


def commands(t, mpi_ok=True, mag=MAG):
    wheels = (0.001, 0.0, 0.0) if mpi_ok else (0.0,) * 3
    return {'mpi': (t, cmd(MPI, wheels, '' if mpi_ok else WHEEL_FAULT, not mpi_ok)),
            'magnetic': (t, cmd(mag, ())), 'bdot': (t, cmd(BDOT, ()))}


def test_a_failed_wheel_controller_hands_over_to_the_magnetic_law_with_the_reason():
    m = mgr()
    out, st = m.step(0.0, commands(0.0))
    assert st['source'] == 'mpi' and out.wheel_torque[0] == 0.001
    for k in range(1, 4):
        out, st = m.step(float(k), commands(float(k), mpi_ok=False))
        assert st['source'] == 'magnetic' and st['active'] == 'mpi' and st['fallback']
        np.testing.assert_array_equal(out.dipole_body, MAG)
        assert np.all(out.wheel_torque == 0.0)            # no NaN to an actuator
    assert st['missed_frames'] == 3
    assert st['last_fault'] == f'mpi: {WHEEL_FAULT}; fallback to magnetic'
    assert 'non-finite' not in st['last_fault']
    out, st = m.step(4.0, commands(4.0))                  # usable again: forwarded again
    assert st['source'] == 'mpi' and st['fault'] == ''


def test_the_safe_controller_is_the_last_resort_and_each_refusal_is_said():
    m = mgr()
    out, st = m.step(1.0, commands(1.0, mpi_ok=False, mag=[99.0, 0.0, 0.0]))
    assert st['source'] == 'bdot'
    np.testing.assert_array_equal(out.dipole_body, BDOT)
    assert '; fallback magnetic: out of range: dipole_body[0] = 99' in st['fault']
    assert st['fault'].endswith('; fallback to bdot')


def test_a_stale_estimate_skips_the_magnetic_law_which_needs_it():
    m = mgr(estimate_period_s=1.0)
    est = Estimate(np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3), 1e-3, True)
    _, st = m.step(1.0, commands(1.0, mpi_ok=False), est, estimate_t=1.0)
    assert st['source'] == 'magnetic'
    _, st = m.step(2.0, commands(2.0, mpi_ok=False), est, estimate_t=0.0)     # stale
    assert st['source'] == 'bdot'
    assert 'fallback magnetic: estimator stale' in st['fault']


def test_without_a_fallback_list_it_goes_straight_to_the_safe_controller():
    _, st = mgr(fallback=()).step(1.0, commands(1.0, mpi_ok=False))
    assert st['source'] == 'bdot' and 'magnetic' not in st['fault']


def test_latched_fallback_makes_the_forwarded_controller_the_active_one():
    m = mgr(latch_fallback=True)
    _, st = m.step(1.0, commands(1.0, mpi_ok=False))
    assert st['active'] == 'magnetic' and st['source'] == 'magnetic'
    _, st = m.step(2.0, commands(2.0))
    assert st['source'] == 'magnetic' and st['fault'] == ''


@pytest.mark.parametrize('fallback', [['bdot'], ['fuzzy'], ['magnetic', 'magnetic']])
def test_a_bad_fallback_list_is_refused(fallback):
    with pytest.raises(ValueError, match='fallback must list configured controllers'):
        mgr(fallback=fallback)


def test_the_scenario_validator_refuses_a_bad_fallback_with_the_key(tmp_path):
    import os

    import yaml

    from adcs_nodes.scenario import ScenarioError, load_scenario
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    with open(os.path.join(root, 'scenarios', 'demo_mission.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['manager']['fallback'] = ['bdot']
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump(sc))
    with pytest.raises(ScenarioError, match='manager.fallback') as exc:
        load_scenario(str(path))
    assert str(path) in str(exc.value)
