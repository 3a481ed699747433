"""Fuzzy eigenaxis controller of paper 003: tables, memberships, inference, torque limit."""
import math

import numpy as np
import pytest

from adcs_nodes.core import attitude
from adcs_nodes.core.control import ControlInputs, Estimate, Target
from adcs_nodes.core.control import fuzzy as fz

skfuzzy = pytest.importorskip('skfuzzy')

# Table 1 and Table 2 retyped from the paper (original text, 003_842f39ead8378523.txt).
PAPER_TABLE1 = """
Б	П	ПБ	ПС	ПМ	Н	ОМ	ОС	ОБ	О
С	П	П	ПБ	Н	ОБ	О	О	О	О
М	ПБ	ПС	Н	ОС	ОБ	О	О	О	О
ОМ	ПС	ОМ	ОС	О	О	О	О	О	О
Н	ПБ	О	О	О	О	О	О	О	О
"""
PAPER_TABLE1_HEADER = 'ОБ	ОС	ОМ	ООМ	Н	ПОМ	ПМ	ПС	ПБ'
PAPER_TABLE2 = """
ОБ	ПБ	ПБ	ПБ	ПС	Н
ОС	ПБ	ПБ	ПС	Н	ОС
Н	ПБ	ПС	Н	ОС	ОБ
ПС	ПС	Н	ОС	ОБ	ОБ
ПБ	Н	ОС	ОБ	ОБ	ОБ
"""
PAPER_TABLE2_HEADER = 'ОБ	ОС	Н	ПС	ПБ'


def _rows(text):
    return [line.split('\t') for line in text.strip().splitlines()]


def test_table1_is_the_papers_table_exactly():
    assert tuple(PAPER_TABLE1_HEADER.split('\t')) == fz.DPHI_TERMS
    rows = _rows(PAPER_TABLE1)
    assert [(r[0], tuple(r[1:])) for r in rows] == list(fz.TABLE1_ROWS_PRINTED)
    for r in rows:
        assert [fz.TABLE1[r[0]][c] for c in fz.DPHI_TERMS] == r[1:]


def test_table2_is_the_papers_table_exactly_and_is_clip_of_minus_sum():
    assert tuple(PAPER_TABLE2_HEADER.split('\t')) == fz.G_TERMS
    for r in _rows(PAPER_TABLE2):
        assert [fz.TABLE2[r[0]][c] for c in fz.G_TERMS] == r[1:]
    idx = fz.table2_indices() - 2                    # ordinals -2..2
    i, j = np.meshgrid(np.arange(-2, 3), np.arange(-2, 3), indexing='ij')
    np.testing.assert_array_equal(idx, np.clip(-(i + j), -2, 2))


def test_table1_readings():
    mk = {t: k for k, t in enumerate(fz.MK_TERMS)}
    h = fz.DPHI_TERMS.index('Н')
    printed = fz.table1_indices('as_printed')
    rev = fz.table1_indices('reversed')
    # As printed: at the target and at rest the rule says O (non-zero torque); at a big angle
    # at rest it says H (no torque): the paper's end state (3) would not be an equilibrium.
    assert printed[0, h] == mk['О'] and printed[4, h] == mk['Н']
    # Reversed: zero torque at rest on target, full acceleration from rest at М.
    assert rev[0, h] == mk['Н'] and rev[2, h] == mk['ОБ']
    np.testing.assert_array_equal(rev, printed[::-1])
    with pytest.raises(ValueError, match='table1_rows'):
        fz.table1_indices('upside_down')


@pytest.mark.parametrize('peaks', [fz.DEFAULTS['phi_peaks_deg'], fz.DEFAULTS['dphi_peaks_deg_s'],
                                   fz.DEFAULTS['g_peaks_deg_s'], fz.DEFAULTS['dg_peaks_deg_s2']])
def test_input_memberships_partition_their_universe(peaks):
    p = np.asarray(peaks, dtype=float)
    x = np.linspace(p[0] - 5.0, p[-1] + 5.0, 4001)
    mu = fz.triangular_memberships(x, p)
    np.testing.assert_allclose(mu.sum(axis=1), 1.0, atol=1e-12)
    assert mu.min() >= 0.0 and mu.max() <= 1.0
    assert np.all((mu > 0).sum(axis=1) <= 2)
    np.testing.assert_allclose(fz.triangular_memberships(p, p), np.eye(len(p)), atol=1e-15)


def test_output_terms_partition_the_inner_output_universe():
    m = fz.Mamdani([0, 1], [0, 1], fz.DEFAULTS['mk_peaks_Nm'], fz.DEFAULTS['mk_half_width_Nm'],
                   [[0, 1], [1, 2]])
    inner = (m.x >= m.out_peaks[0]) & (m.x <= m.out_peaks[-1])
    np.testing.assert_allclose(m.out_mf[:, inner].sum(axis=0), 1.0, atol=1e-12)


def test_inference_hand_computed():
    # Outputs 0, 1, 2 with half-width 0.5 (feet touch). x1 = 0.25: mu = (0.75, 0.25);
    # x2 = 0: mu = (1, 0). Rules fired: (0,0)->0 at 0.75 and (1,0)->1 at 0.25. A triangle of
    # half-width w clipped at h has area w h (2 - h), centroid at its peak:
    # (0 * 0.5*0.75*1.25 + 1 * 0.5*0.25*1.75) / (0.46875 + 0.21875) = 0.21875 / 0.6875.
    m = fz.Mamdani([0.0, 1.0], [0.0, 1.0], [0.0, 1.0, 2.0], 0.5, [[0, 1], [1, 2]], n_points=601)
    assert m(0.25, 0.0)[0] == pytest.approx(0.21875 / 0.6875, abs=1e-12)
    # Table 2 case: |phidot_g| halfway between Н and ПС, derivative Н: rules (Н,Н)->Н and
    # (ПС,Н)->ОС at 0.5; the union is symmetric about the midpoint of the two output peaks.
    m2 = fz.Mamdani([-0.2, -0.1, 0.0, 0.1, 0.2], [-0.2, -0.1, 0.0, 0.1, 0.2],
                    [-0.5, -0.25, 0.0, 0.25, 0.5], 0.25, fz.table2_indices(), n_points=601)
    assert m2(0.05, 0.0)[0] == pytest.approx(-0.125, abs=1e-12)
    assert m2(0.0, 0.0)[0] == pytest.approx(0.0, abs=1e-12)


def _skfuzzy_mamdani(in1, in2, out_peaks, hw, table_labels, terms1, terms2, terms_out, x, v1,
                     v2):
    """Independent Mamdani with scikit-fuzzy primitives and a loop over the rules."""
    def input_mu(peaks, value):
        u = np.union1d(np.linspace(peaks[0], peaks[-1], 2001), peaks)
        value = min(max(value, peaks[0]), peaks[-1])
        out = []
        for k, p in enumerate(peaks):
            a = peaks[k - 1] if k > 0 else p
            c = peaks[k + 1] if k < len(peaks) - 1 else p
            out.append(skfuzzy.interp_membership(u, skfuzzy.trimf(u, [a, p, c]), value))
        return out
    mu1, mu2 = input_mu(in1, v1), input_mu(in2, v2)
    agg = np.zeros_like(x)
    for i, t1 in enumerate(terms1):
        for j, t2 in enumerate(terms2):
            p = out_peaks[terms_out.index(table_labels[t1][t2])]
            mf = skfuzzy.trimf(x, [p - hw, p, p + hw])
            agg = np.fmax(agg, np.fmin(min(mu1[i], mu2[j]), mf))
    return skfuzzy.defuzz(x, agg, 'centroid')


@pytest.mark.parametrize('reading', ['reversed', 'as_printed'])
def test_table1_inference_matches_scikit_fuzzy(reading):
    d = fz.DEFAULTS
    m = fz.Mamdani(d['phi_peaks_deg'], d['dphi_peaks_deg_s'], d['mk_peaks_Nm'],
                   d['mk_half_width_Nm'], fz.table1_indices(reading))
    labels = {}
    for k, (label, cells) in enumerate(fz.TABLE1_ROWS_PRINTED):
        key = label if reading == 'as_printed' else fz.PHI_TERMS[k]
        labels[key] = dict(zip(fz.DPHI_TERMS, cells))
    rng = np.random.default_rng(11)
    v1 = np.concatenate([rng.uniform(-5, 100, 25), [0.0, 12.0, 35.0]])
    v2 = np.concatenate([rng.uniform(-5, 5, 25), [0.0, -0.5, 4.0]])
    ours = m(v1, v2)
    for a, b, o in zip(v1, v2, ours):
        ref = _skfuzzy_mamdani(d['phi_peaks_deg'], d['dphi_peaks_deg_s'], d['mk_peaks_Nm'],
                               d['mk_half_width_Nm'], labels, fz.PHI_TERMS, fz.DPHI_TERMS,
                               fz.MK_TERMS, m.x, a, b)
        assert o == pytest.approx(ref, abs=1e-6)


def test_table2_inference_matches_scikit_fuzzy():
    d = fz.DEFAULTS
    m = fz.Mamdani(d['g_peaks_deg_s'], d['dg_peaks_deg_s2'], d['mgk_peaks_Nm'],
                   d['mgk_half_width_Nm'], fz.table2_indices())
    rng = np.random.default_rng(12)
    for a, b in zip(rng.uniform(0, 0.3, 20), rng.uniform(-0.3, 0.3, 20)):
        ref = _skfuzzy_mamdani(d['g_peaks_deg_s'], d['dg_peaks_deg_s2'], d['mgk_peaks_Nm'],
                               d['mgk_half_width_Nm'], fz.TABLE2, fz.G_TERMS, fz.G_TERMS,
                               fz.G_TERMS, m.x, a, b)
        assert m(a, b)[0] == pytest.approx(ref, abs=1e-6)


def _inputs(q_eci_body, w, target=None):
    est = Estimate(q_orbit_body=q_eci_body, omega_body_eci_body=np.asarray(w, float),
                   omega0=0.0, q_eci_body=q_eci_body)
    return ControlInputs(estimate=est, target=target or Target(frame='eci'))


J = np.diag([250.0, 200.0, 180.0])


@pytest.mark.parametrize('saturation', ['scale', 'clip'])
def test_torque_never_exceeds_the_per_axis_limit(saturation):
    c = fz.FuzzyEigenaxisController(J, 1.0, saturation=saturation)
    rng = np.random.default_rng(5)
    for _ in range(300):
        q = attitude.normalize(rng.normal(size=4))
        w = rng.normal(scale=0.05, size=3)
        cmd = c.update(_inputs(q, w), 0.0, 0.1)
        assert np.all(np.abs(cmd.torque_body) <= 1.0 + 1e-12)
        if saturation == 'scale':   # direction kept
            full = cmd.info['torque_unlimited']
            assert np.linalg.norm(np.cross(cmd.torque_body, full)) <= 1e-9 * (
                1 + np.linalg.norm(full))
            assert float(cmd.torque_body @ full) >= 0.0


def test_torque_direction_points_to_the_target_from_rest():
    c = fz.FuzzyEigenaxisController(J, 1.0)
    q = attitude.from_euler_321(*np.radians([16.5, -7.5, 34.0]))
    cmd = c.update(_inputs(q, np.zeros(3)), 0.0, 0.1)
    phi, e = cmd.info['phi'], cmd.info['e_phi']
    acc = np.linalg.solve(J, cmd.torque_body)
    assert math.degrees(phi) == pytest.approx(39.34, abs=0.01)
    assert float(acc @ e) < 0.0                                  # drives phi down
    np.testing.assert_allclose(np.cross(acc, e), 0.0, atol=1e-12)  # about the eigenaxis
    assert np.max(np.abs(cmd.torque_body)) == pytest.approx(1.0)   # at the limit from rest


def test_target_equilibrium_depends_on_table1_reading():
    q = attitude.identity()
    rev = fz.FuzzyEigenaxisController(J, 1.0, table1_rows='reversed')
    lit = fz.FuzzyEigenaxisController(J, 1.0, table1_rows='as_printed')
    np.testing.assert_allclose(rev.update(_inputs(q, np.zeros(3)), 0, 0.1).torque_body, 0.0,
                               atol=1e-12)
    assert np.linalg.norm(lit.update(_inputs(q, np.zeros(3)), 0, 0.1).torque_body) > 0.1


def test_orbit_and_eci_targets_give_the_same_error():
    q_eci_orbit = attitude.from_euler_321(0.3, -0.2, 1.1)
    q_orbit_body = attitude.from_euler_321(0.1, 0.2, -0.3)
    q_orbit_ref = attitude.from_euler_321(-0.2, 0.1, 0.4)
    q_eci_body = attitude.multiply(q_eci_orbit, q_orbit_body)
    w = np.array([0.001, -0.002, 0.0015])
    est = Estimate(q_orbit_body, w, 0.0, q_eci_body=q_eci_body)   # omega0 = 0: same rates
    t_orbit = Target(q_orbit_ref, frame='orbit')
    t_eci = t_orbit.in_frame('eci', est)
    a = fz.FuzzyEigenaxisController(J).update(ControlInputs(est, t_orbit), 0, 0.1)
    b = fz.FuzzyEigenaxisController(J).update(ControlInputs(est, t_eci), 0, 0.1)
    np.testing.assert_allclose(a.torque_body, b.torque_body, atol=1e-12)
    assert a.info['phi'] == pytest.approx(attitude.angle_between(q_orbit_body, q_orbit_ref))


def test_orbit_target_uses_the_rate_relative_to_the_orbit_frame():
    # Body on the orbit frame, rotating with it (omega = omega0 about the orbit normal):
    # zero error and zero relative rate, hence zero torque.
    q = attitude.from_euler_321(0.0, 0.0, 0.0)
    w0 = 0.0011
    est = Estimate(q, np.array([0.0, w0, 0.0]), w0, q_eci_body=q)
    cmd = fz.FuzzyEigenaxisController(J).update(ControlInputs(est, Target()), 0, 0.1)
    np.testing.assert_allclose(cmd.torque_body, 0.0, atol=1e-12)


def test_bad_data_gives_zero_command_with_reason():
    c = fz.FuzzyEigenaxisController(J)
    q = attitude.identity()
    bad = [ControlInputs(None, Target()),
           _inputs(q, [np.nan, 0, 0]),
           ControlInputs(Estimate(q, np.zeros(3), 0.0), Target(frame='eci')),   # no q_eci
           _inputs(q, np.zeros(3), Target(np.array([np.nan, 0, 0, 1.0]), frame='eci')),
           _inputs(q, np.zeros(3), Target(np.zeros(4), frame='eci'))]
    for inp in bad:
        cmd = c.update(inp, 0.0, 0.1)
        assert cmd.reason and cmd.is_finite() and not np.any(cmd.torque_body)


def test_bad_configuration_raises():
    with pytest.raises(ValueError):
        fz.FuzzyEigenaxisController(J, table1_rows='sideways')
    with pytest.raises(ValueError, match='increasing'):
        fz.FuzzyEigenaxisController(J, phi_peaks_deg=(0, 10, 5, 30, 90))
    with pytest.raises(ValueError, match='unknown'):
        fz.FuzzyEigenaxisController(J, phi_peak=(0, 1))
    with pytest.raises(ValueError):
        fz.FuzzyEigenaxisController(-J)
    with pytest.raises(ValueError):
        fz.FuzzyEigenaxisController(J, saturation='soft')


def test_wheel_allocation_realises_the_torque():
    axes = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]]) / np.array(
        [[1], [1], [1], [math.sqrt(3)]])
    c = fz.FuzzyEigenaxisController(J, 1.0, wheel_axes_body=axes,
                                    wheel_max_torque_Nm=[5.0] * 4)
    q = attitude.from_euler_321(0.3, -0.1, 0.5)
    inp = ControlInputs(Estimate(q, np.zeros(3), 0.0, q_eci_body=q), Target(frame='eci'),
                        wheel_momentum_Nms=np.zeros(4))
    cmd = c.update(inp, 0.0, 0.1)
    assert cmd.wheel_torque.shape == (4,)
    np.testing.assert_allclose(-axes.T @ cmd.wheel_torque, cmd.info['torque_demand'],
                               atol=1e-12)


def test_registry_entries_build_and_share_the_core_defaults():
    from adcs_nodes import registry
    entry = registry.get('controller', 'fuzzy')
    defaults = entry.defaults()
    for key, value in fz.DEFAULTS.items():
        np.testing.assert_allclose(defaults[key], value, err_msg=key)
    ctx = dict(inertia_kgm2=J, wheel_axes_body=np.zeros((0, 3)), wheel_max_torque_Nm=[])
    assert isinstance(entry.build(entry.validate({}), ctx), fz.FuzzyEigenaxisController)
    ref = registry.get('controller', 'reference_slew')
    assert ref.build(ref.validate({}), ctx).n_wheels == 0
    with pytest.raises(ValueError):
        entry.validate({'table1_rows': 'sideways'})


def test_output_terms_without_rules_never_fire():
    # Only term 0 (peak -1) and term 1 (peak 0) are used; the trailing term 2 has no rule.
    m = fz.Mamdani([0.0, 1.0], [0.0, 1.0], [-1.0, 0.0, 1.0], 0.5, [[0, 0], [0, 1]],
                   n_points=601)                 # grid step 0.005: peaks and feet on the grid
    s = m.strengths([0.0, 1.0, 0.5], [0.0, 1.0, 0.5])
    np.testing.assert_allclose(s, [[1, 0, 0], [0, 1, 0], [0.5, 0.5, 0]])
    np.testing.assert_allclose(m([0.0, 1.0], [0.0, 1.0]), [-1.0, 0.0], atol=1e-12)


@pytest.mark.parametrize('angle_deg', [180.0])
def test_slews_to_any_inertial_target_including_180_deg(angle_deg):
    """On the FrameLoop: paper003_slew with the fuzzy controller (its registry defaults, as
    ``FuzzyEigenaxisController(J)``) fed the true state, the target held in the orbit frame."""
    import os

    from adcs_nodes import registry
    from adcs_nodes.tools.analyse.papers import paper003
    from adcs_nodes.scenario import load_scenario
    from adcs_nodes.tools.analyse.study import run_topics
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    sc = load_scenario(os.path.join(root, 'scenarios', 'paper003_slew.yaml'))
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    q0 = initial_quaternion(paper003.EULER0_DEG)
    np.testing.assert_allclose(q0, sc['initial']['q_orbit_body_xyzw'], atol=1e-8)
    q_t = attitude.multiply(q0, attitude.from_axis_angle(axis, math.radians(angle_deg)))
    defaults = {f'controllers.fuzzy.{k}': v for k, v in
                registry.get('controller', 'fuzzy').defaults().items()}
    topics = run_topics(sc, paper003.TOPICS, 90.0, {
        **defaults, 'initial.q_orbit_body_xyzw': q0.tolist(), 'manager.initial': 'fuzzy',
        'guidance.profile': [{'t_s': 0.0, 'type': 'hold', 'q_xyzw': q_t.tolist()}]},
        ideal=True)
    run = paper003.series(topics, sc)
    assert set(run['source'][1:]) == {'fuzzy'}
    assert run['phi'][0] == pytest.approx(math.radians(angle_deg), abs=1e-9)
    assert math.degrees(run['phi'][-1]) < 0.05
    assert np.abs(run['omega'][-1]).max() < math.radians(0.01)   # w.r.t. the target frame
    assert np.abs(run['torque']).max() <= 1.0 + 1e-12


def initial_quaternion(euler_deg) -> np.ndarray:
    """``q_ref_body`` (scalar last) of paper 003's Euler-Krylov angles (psi, theta, gamma)
    [deg] (3-2-1)."""
    from adcs_nodes.core.control.eigenaxis import dcm_euler_321
    psi, theta, gamma = (math.radians(a) for a in euler_deg)
    return attitude.from_matrix(dcm_euler_321(psi, theta, gamma).T)
