"""One onboard reference per stamp (issue 13): sharing and the last-stamp cache change no
number; the truth is a private reference built directly from the models."""
from datetime import datetime, timezone

import numpy as np

from adcs_nodes.core.estimation.onboard import OnboardReference, make_onboard_reference
from adcs_nodes.core.geomag import make_field
from adcs_nodes.core.orbit import make_orbit

EPOCH = datetime(2026, 1, 1, tzinfo=timezone.utc)
ORBIT = {'type': 'circular', 'altitude_km': 690.0, 'inclination_deg': 98.0, 'raan_deg': 0.0,
         'arg_latitude0_deg': 0.0}
FIELD = {'model': 'igrf_dipole'}


def test_same_configuration_shares_one_instance_and_values_are_unchanged():
    a = make_onboard_reference(dict(ORBIT), dict(FIELD), EPOCH)
    b = make_onboard_reference(dict(reversed(list(ORBIT.items()))), dict(FIELD), EPOCH)
    other = make_onboard_reference({**ORBIT, 'inclination_deg': 97.0}, FIELD, EPOCH)
    assert a is b and other is not a
    private = OnboardReference(make_orbit(ORBIT, EPOCH), make_field(FIELD, EPOCH))
    for t in (0.0, 2.0, 2.0, 1234.5, 2.0):
        got, want = a.at(t), private.at(t)
        for x, y in zip(got, want):
            assert np.array_equal(np.asarray(x), np.asarray(y))
    assert not np.array_equal(other.at(1234.5).b_orbit, a.at(1234.5).b_orbit)


def test_callers_get_their_own_arrays():
    ref = make_onboard_reference(ORBIT, FIELD, EPOCH)
    first = ref.at(10.0)
    keep = first.b_orbit.copy()
    first.b_orbit[:] = 0.0
    first.q_eci_orbit[:] = 0.0
    second = ref.at(10.0)
    assert np.array_equal(second.b_orbit, keep) and np.linalg.norm(second.q_eci_orbit) > 0.5
