"""Every registered controller (``registry.entries('controller')``: magnetic, bdot, fuzzy,
reference_slew, mpi, and any plugin's) driven with degenerate inputs on three spacecraft
(three axis wheels and magnetorquers, a four-wheel pyramid, magnetorquers only): a controller
either refuses (``Command.refused`` with a reason, or ``ValueError`` at construction for a
spacecraft it cannot fly) or returns a finite command inside the actuator limits, checked by
the same boundary check the controller component applies (:func:`command_fields`); an exception
escaping ``update`` or a NaN out fails. The target quaternion is also checked where it enters
(:func:`target_of`: normalised, or refused when zero, NaN or not finite)."""
import math

import numpy as np
import pytest

from adcs_nodes import registry
from adcs_nodes.components.controller import target_of
from adcs_nodes.core.command_health import command_fields
from adcs_nodes.core.control import Command, ControlInputs, Estimate, Target
from adcs_nodes.core.samples import AttitudeTarget

PYRAMID = [[math.sin(0.955) * math.cos(a), math.sin(0.955) * math.sin(a), math.cos(0.955)]
           for a in np.radians([45.0, 135.0, 225.0, 315.0])]
SPACECRAFT = {'three_wheels': np.eye(3).tolist(), 'pyramid': PYRAMID, 'no_wheels': []}
MAX_DIPOLE = [5.0, 5.0, 5.0]
Q_TILT = np.array([0.1, -0.2, 0.05, 0.97])
B_BODY = np.array([2e-5, -1e-5, 3e-5])


def _ctx(axes):
    n = len(axes)
    return {'inertia_kgm2': np.diag([2.0, 2.5, 1.8]), 'max_dipole_Am2': MAX_DIPOLE,
            'wheel_axes_body': np.asarray(axes, float).reshape(n, 3),
            'wheel_max_torque_Nm': [0.01] * n, 'wheel_max_momentum_Nms': [0.2] * n,
            'wheel_inertia_kgm2': [3e-4] * n, 'period_s': 1.0, 'epoch': None, 'seed': 1,
            'reference': None}


def _estimate(q=Q_TILT, w=(0.002, -0.001, 0.003), valid=True):
    return Estimate(np.asarray(q, float), np.asarray(w, float), 1.1e-3, valid,
                    np.asarray(q, float))


def _cases(n):
    """``(name, ControlInputs)``: nominal, then each degenerate input."""
    good = dict(estimate=_estimate(), target=Target(), b_body=B_BODY, b_body_model=B_BODY,
                wheel_speed_rad_s=np.full(n, 10.0), wheel_momentum_Nms=np.full(n, 3e-3))
    stuck = np.ones(n, bool)
    stuck[:1] = False
    cases = {
        'nominal': {},
        'nan estimate': dict(estimate=_estimate(q=[np.nan, 0, 0, 1])),
        'invalid estimate': dict(estimate=_estimate(valid=False)),
        'zero estimate quaternion': dict(estimate=_estimate(q=[0, 0, 0, 0])),
        'no estimate': dict(estimate=None),
        'huge target': dict(target=Target(1e300 * Q_TILT)),
        'unnormalised target': dict(target=Target(3.0 * Q_TILT)),
        'zero target': dict(target=Target(np.zeros(4))),
        'nan target': dict(target=Target(np.array([np.nan, 0, 0, 1]))),
        'huge rate': dict(estimate=_estimate(w=(1e300, -1e300, 1e300))),
        'no field': dict(b_body=None, b_body_model=None),
        'zero field': dict(b_body=np.zeros(3), b_body_model=np.zeros(3)),
        'nan field': dict(b_body=np.full(3, np.nan), b_body_model=None),
        'huge field': dict(b_body=np.full(3, 1e300)),
        'nan wheel speeds': dict(wheel_speed_rad_s=np.full(n, np.nan),
                                 wheel_momentum_Nms=np.full(n, np.nan)),
        'wrong wheel count': dict(wheel_speed_rad_s=np.zeros(n + 1),
                                  wheel_momentum_Nms=np.zeros(n + 1)),
        'stuck wheel': dict(wheel_ok=stuck, backup_dipole_Am2=np.array(MAX_DIPOLE)),
        'stuck wheel, no magnetorquer': dict(wheel_ok=stuck),
        'zero healthy wheels': dict(wheel_ok=np.zeros(n, bool),
                                    backup_dipole_Am2=np.array(MAX_DIPOLE)),
        'singular allocation, no field': dict(wheel_ok=np.arange(n) == 0, b_body=None,
                                              b_body_model=None,
                                              backup_dipole_Am2=np.array(MAX_DIPOLE)),
    }
    return [(name, ControlInputs(**{**good, **change})) for name, change in cases.items()]


def _build(entry, axes):
    try:
        return entry.build(entry.defaults(), _ctx(axes))
    except ValueError as exc:               # a spacecraft it cannot fly, said at construction
        assert str(exc)
        return None


@pytest.mark.parametrize('craft', sorted(SPACECRAFT))
@pytest.mark.parametrize('name', sorted(registry.entries('controller')))
def test_degenerate_inputs_give_a_bounded_finite_command_or_a_stated_refusal(name, craft):
    entry = registry.entries('controller')[name]
    axes = SPACECRAFT[craft]
    core = _build(entry, axes)
    if core is None:
        assert 'wheels' in entry.actuators and not axes
        return
    n = len(axes)
    n_cmd = getattr(core, 'n_wheels', n)
    refusals = []
    for case, inputs in _cases(n):
        core.reset()
        for k, t in enumerate((0.0, 1.0, 2.0)):         # a first frame (dt 0), then two more
            cmd = core.update(inputs, t, 0.0 if k == 0 else 1.0)
            assert isinstance(cmd, Command), (name, case)
            if cmd.refused:
                assert cmd.reason, (name, case)
                refusals.append(case)
                continue
            why = command_fields(cmd, np.array(MAX_DIPOLE), np.full(n_cmd, 0.01),
                                 np.full(3, np.inf))[1]
            assert why == '', (name, craft, case, why)
            assert np.all(np.isfinite(np.asarray(cmd.torque_body, float))), (name, case)
    # only the allocation can refuse, and only when the wheels left cannot be covered
    assert set(refusals) <= {'stuck wheel, no magnetorquer', 'singular allocation, no field',
                             'zero healthy wheels'}, refusals


@pytest.mark.parametrize('q,ok', [([0.0, 0.0, 0.0, 3.0], True), ([1e300, 0.0, 0.0, 1e300], True),
                                  ([1.7e308, 1.7e308, 0.0, 0.0], True), ([0.0] * 4, False),
                                  ([np.nan, 0.0, 0.0, 1.0], False), ([np.inf, 0, 0, 1], False),
                                  ([1e-300, 0.0, 0.0, 0.0], False)])
def test_the_target_quaternion_is_normalised_or_refused_where_it_enters(q, ok):
    x = AttitudeTarget(0, 'orbit', np.array(q, float), np.zeros(3), np.zeros(3), 0.0, 'hold')
    target = target_of(x)
    if not ok:
        assert target is None
        return
    assert np.linalg.norm(target.q_ref_body) == pytest.approx(1.0, abs=1e-15)
    expected = np.array(q, float) / np.max(np.abs(q))
    np.testing.assert_allclose(target.q_ref_body, expected / np.linalg.norm(expected),
                               atol=1e-15)


class _Malformed:
    """A plugin core with a bug: its dipole has shape (0,) (issue 38 item 3), then a NaN."""

    def __init__(self, dipole):
        self.dipole = dipole

    def update(self, inputs, t, dt):
        return Command(np.asarray(self.dipole, float), np.zeros(0), np.zeros(3))


@pytest.mark.parametrize('dipole,why', [
    ([], 'malformed dipole_body: shape (0,), expected (3,)'),
    ([np.nan, 0.0, 0.0], 'non-finite (NaN or inf) dipole_body: [nan  0.  0.]'),
    ([9.0, 0.0, 0.0], 'out of range: dipole_body[0] = 9 A m^2 exceeds the limit 5 A m^2')])
def test_a_malformed_output_is_stopped_at_the_controller_and_the_manager_falls_back(dipole,
                                                                                    why):
    from adcs_nodes.components.controller import ControllerComponent, command_of
    from adcs_nodes.core.manager import ControllerManagerCore
    comp = ControllerComponent(_Malformed(dipole), 'plug', {'max_dipole_Am2': MAX_DIPOLE,
                                                            'reference': None}, None)
    out = comp.step(0, {}, lambda key: True)
    assert out.source == f'plug: {why}'
    assert out.dipole_body_Am2.shape == (3,) and np.all(out.dipole_body_Am2 == 0.0)
    manager = ControllerManagerCore(['bdot', 'plug'], 'bdot', initial='plug',
                                    max_dipole_Am2=MAX_DIPOLE)
    bdot = Command(np.array([0.1, 0.0, 0.0]), np.zeros(0), np.zeros(3))
    cmd, status = manager.step(0.0, {'plug': (0.0, command_of(out)), 'bdot': (0.0, bdot)})
    assert status['source'] == 'bdot' and status['fault'] == f'plug: {why}; fallback to bdot'
    np.testing.assert_array_equal(cmd.dipole_body, bdot.dipole_body)
