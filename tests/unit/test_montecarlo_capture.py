"""``adcs montecarlo``'s capture test per scenario (:mod:`adcs_nodes.tools.campaigns.capture`):
the angle between the body and the attitude the scenario's guidance commands.

paper001_mpi: a 3-run campaign of 400 s on the plain engine (real run processes), judged
against paper 001's profile: the angle is computed here again from the run's ``series.npz``
with numpy alone (the paper's 3-1-2 Euler hold attitude written out as matrices, not through
the package), so a capture measured to the orbit frame fails. The target the plain worker
records is the one the run published (a bag of the same run), bit for bit; a profile in the
ECI frame is judged on the plain engine as the graph engine reads its bag. paper000_control:
the numbers are those of the angle to the orbit frame (the recorded target is the identity),
and a campaign from before the guidance target resumes with them; a paper001 campaign from
before is refused with the reason, and a paper001 run from before the worker recorded the
target is run again. The default initial-rate bound follows the scenario's paper;
``--max-rate-deg-s`` wins.
"""
import argparse
import json
import math
import os
import shutil

import numpy as np
import pytest

from adcs_nodes.tools import campaigns as mc
from adcs_nodes.tools.analyse.metrics import angle_between_deg
from adcs_nodes.tools.campaigns.cli import config_from_args, main
from adcs_nodes.scenario import load_scenario

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
P000 = os.path.join(ROOT, 'scenarios', 'paper000_control.yaml')
P001 = os.path.join(ROOT, 'scenarios', 'paper001_mpi.yaml')
DURATION = 400.0          # paper 001: maneuver 0-200 s, then the hold at (40, -40, 20) deg
MANEUVER_END_S = 200.0
HOLD_EULER312_DEG = (40.0, -40.0, 20.0)


# ---------------------------------------------------------------------- independent numpy
def _passive(axis, a):
    """Passive elementary rotation about body axis ``axis`` (0, 1, 2) by ``a`` [rad]."""
    c, s = math.cos(a), math.sin(a)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m = np.eye(3)
    m[i, i] = m[j, j] = c
    m[i, j], m[j, i] = s, -s
    return m


def r_orbit_target(euler312_deg):
    """``R_orbit_target`` of paper 001's 3-1-2 angles (phi, theta, psi) w.r.t. its LVLH:
    ``C_bo = Ry(theta) Rx(phi) Rz(psi)`` (v_body = C_bo v_lvlh), and the project's orbit
    frame is LVLH turned half a turn about x (``diag(1, -1, -1)``)."""
    phi, theta, psi = np.radians(euler312_deg)
    c_bo = _passive(1, theta) @ _passive(0, phi) @ _passive(2, psi)
    return np.diag([1.0, -1.0, -1.0]) @ c_bo.T


def r_of_q(q):
    """Rotation matrices (n, 3, 3) of scalar-last quaternions (v_frame = R v_body)."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], 1)


def angle_deg(r_a, r_b):
    """Angle of the rotation between (n, 3, 3) and (3, 3) matrices [deg]."""
    tr = np.einsum('ij,nij->n', r_b, r_a)              # trace(R_b^T R_a)
    return np.degrees(np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0)))


def capture_time(t, e, band=5.0, hold=10.0):
    """First time e < band after the last e >= hold (None: never)."""
    out = np.flatnonzero(e >= hold)
    start = out[-1] + 1 if out.size else 0
    inside = np.flatnonzero(e[start:] < band)
    return float(t[start + inside[0]]) if inside.size else None


# ---------------------------------------------------------------------- paper 001 campaign
@pytest.fixture(scope='module')
def campaign001(tmp_path_factory):
    """``adcs montecarlo paper001_mpi.yaml --runs 3 --duration 400 --engine plain``."""
    out = tmp_path_factory.mktemp('mc001') / 'c'
    code = main([P001, '--runs', '3', '--duration', f'{DURATION:g}', '--engine', 'plain',
                 '--out', str(out)])
    assert code == 0
    return out, [mc.load_result(mc.run_dir_of(str(out), i)) for i in range(3)]


def test_paper001_capture_is_the_angle_to_the_guidance_target(campaign001):
    out, results = campaign001
    with open(out / 'campaign.json', encoding='utf-8') as fh:
        identity = json.load(fh)
    assert identity['capture_reference'] == 'guidance target'
    assert identity['max_rate_deg_s'] == 0.3             # paper 001's default bound
    r_target = r_orbit_target(HOLD_EULER312_DEG)
    captured = 0
    for i, res in enumerate(results):
        assert res['capture_reference'] == 'guidance target' and res['engine'] == 'plain'
        assert np.abs(res['dispersion']['omega_body_eci_body_deg_s']).max() <= 0.3
        with np.load(os.path.join(mc.run_dir_of(str(out), i), mc.SERIES_FILE)) as s:
            t, q = s['t_s'], s['q_orbit_body']
        hold = t >= MANEUVER_END_S           # the maneuver's samples are not judged
        e = angle_deg(r_of_q(q[hold]), r_target)
        assert res['final_angle_deg'] == pytest.approx(e[-1], abs=1e-5), i
        assert res['capture_time_s'] == capture_time(t[hold], e), i
        assert res['status'] == ('captured' if capture_time(t[hold], e) else 'not_captured')
        captured += res['status'] == 'captured'
    assert captured >= 1


def test_paper001_capture_is_not_measured_to_the_orbit_frame(campaign001):
    """The defect: to the orbit frame no paper001 run is captured (its targets are 40-180 deg
    away from it); to the guidance target some are."""
    out, results = campaign001
    for i, res in enumerate(results):
        with np.load(os.path.join(mc.run_dir_of(str(out), i), mc.SERIES_FILE)) as s:
            to_orbit = angle_deg(r_of_q(s['q_orbit_body']), np.eye(3))
        if res['status'] == 'captured':
            assert abs(res['final_angle_deg'] - to_orbit[-1]) > 10.0, i
    assert any(r['status'] == 'captured' for r in results)
    text = (out / 'summary.md').read_text()
    assert 'the angle between the body and the guidance target' in text
    assert 'initial rate components uniform in +-0.3 deg/s' in text
    assert 'magnetometer' not in text          # paper 001 has none: no bias to speak of


def test_the_worker_records_the_published_target(campaign001, tmp_path):
    """Run 0 again on the plain engine with a bag: the ``adcs/attitude_target`` it published
    is the target the worker recorded in ``series.npz``, bit for bit, and the bag's metrics
    (the graph engine's reading) are the plain result's."""
    from adcs_nodes.bag import read_messages
    from adcs_nodes.tools.run.plain import run_plain
    out, results = campaign001
    run_dir = mc.run_dir_of(str(out), 0)
    sc = load_scenario(os.path.join(run_dir, 'scenario.yaml'))
    bag = str(tmp_path / 'bag')
    assert run_plain(sc, record=bag, progress=False).exit_code == 0
    q_rec, judged_rec = [], []
    for _, _, msg in read_messages(bag, ['/adcs/attitude_target']):
        o = msg.q_ref_body
        q_rec.append((o.x, o.y, o.z, o.w))
        judged_rec.append(msg.profile != 'maneuver')
    with np.load(os.path.join(run_dir, mc.SERIES_FILE)) as s:
        t, q_target, judged = s['t_s'], s['q_orbit_target'], s['target_judged']
    assert np.array_equal(np.array(q_rec), q_target)      # a target every 0.2 s frame
    assert np.array_equal(np.array(judged_rec), judged) and not judged[t < 200.0].any()
    m = mc.bag_metrics(bag, 5.0, results[0]['period_s'], mc.GUIDANCE_TARGET)
    for key in ('status', 'capture_time_s', 'first_entry_s', 'last_exit_s', 'samples',
                'capture_reference'):
        assert m[key] == results[0][key], key
    assert m['final_angle_deg'] == pytest.approx(results[0]['final_angle_deg'], abs=1e-9)


def test_a_paper001_run_from_before_the_recorded_target_is_run_again(campaign001, tmp_path,
                                                                     capsys):
    """A run of a campaign made when the target was rebuilt from the scenario, its result
    not judged yet (no ``capture_reference``; ``series.npz`` without the target): not done,
    the reason in ``failed.json``; the resumed campaign runs it again, the same numbers."""
    out, results = campaign001
    old = tmp_path / 'old'
    shutil.copytree(out, old)
    run_dir = mc.run_dir_of(str(old), 1)
    with np.load(os.path.join(run_dir, mc.SERIES_FILE)) as s:
        series = {k: s[k] for k in s.files if k not in ('q_orbit_target', 'target_judged')}
    np.savez_compressed(os.path.join(run_dir, mc.SERIES_FILE), **series)
    worker = {k: v for k, v in results[1].items() if k != 'capture_reference'}
    mc.write_json_atomic(os.path.join(run_dir, mc.RESULT_FILE), worker)
    assert mc.load_result(run_dir) is None
    with open(os.path.join(run_dir, mc.FAILED_FILE), encoding='utf-8') as fh:
        assert 'from before the plain worker recorded the guidance target' in json.load(fh)[
            'message']
    capsys.readouterr()
    assert main([P001, '--runs', '3', '--duration', f'{DURATION:g}', '--engine', 'plain',
                 '--out', str(old)]) == 0
    assert 'executed 1 run(s)' in capsys.readouterr().out
    again = mc.load_result(run_dir)
    for key in ('status', 'capture_time_s', 'final_angle_deg', 'capture_reference'):
        assert again[key] == results[1][key], key


def test_a_paper001_campaign_from_before_is_refused_with_the_reason(campaign001, tmp_path,
                                                                    capsys):
    out, _ = campaign001
    old = tmp_path / 'old'
    shutil.copytree(out, old)
    with open(old / 'campaign.json', encoding='utf-8') as fh:
        data = json.load(fh)
    del data['capture_reference']                      # as written before this change
    data['max_rate_deg_s'] = 3.0
    with open(old / 'campaign.json', 'w', encoding='utf-8') as fh:
        json.dump(data, fh)
    code = main([P001, '--runs', '3', '--duration', f'{DURATION:g}', '--engine', 'plain',
                 '--out', str(old), '--max-rate-deg-s', '3'])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "capture_reference: 'orbit frame' in campaign.json, 'guidance target' now" in err
    assert 'measured capture to the orbit frame' in err and 'another --out' in err, err


# ---------------------------------------------------------------------- paper 000
def test_paper000_numbers_are_the_orbit_frame_ones_and_an_old_campaign_resumes(tmp_path,
                                                                               capsys):
    """The worker's numbers are those of the angle to the orbit frame (the recorded target
    is the identity: the angle to it is the angle to the orbit frame, bit for bit); a campaign
    from before (no capture_reference anywhere, no target in series.npz) resumes with nothing
    to run, same numbers."""
    out = tmp_path / 'mc'
    args = [P000, '--runs', '1', '--duration', '20', '--out', str(out), '--engine', 'plain']
    assert main(args) == 0
    run_dir = mc.run_dir_of(str(out), 0)
    with open(os.path.join(run_dir, mc.RESULT_FILE), encoding='utf-8') as fh:
        scored = json.load(fh)
    assert scored['capture_reference'] == 'orbit frame'
    with np.load(os.path.join(run_dir, mc.SERIES_FILE)) as s:
        series = {k: s[k] for k in s.files}
    expected = mc.series_metrics(series['t_s'], series['q_orbit_body'], series['w_eci'],
                                 series['w_orbit'], 5.0, scored['period_s'])
    assert {k: scored[k] for k in expected} == expected
    assert np.array_equal(series['q_orbit_target'],
                          np.tile([0.0, 0.0, 0.0, 1.0], (series['t_s'].size, 1)))
    assert series['target_judged'].all()
    to_target = angle_between_deg(series['q_orbit_target'], series['q_orbit_body'])
    assert np.array_equal(to_target, series['angle_deg'])      # the orbit frame's, bit for bit
    np.savez_compressed(os.path.join(run_dir, mc.SERIES_FILE), **{
        k: v for k, v in series.items() if k not in ('q_orbit_target', 'target_judged')})
    # as before this change: no capture_reference in campaign.json nor in result.json
    with open(out / 'campaign.json', encoding='utf-8') as fh:
        data = json.load(fh)
    assert data['capture_reference'] == 'orbit frame' and data['max_rate_deg_s'] == 3.0
    del data['capture_reference']
    with open(out / 'campaign.json', 'w', encoding='utf-8') as fh:
        json.dump(data, fh)
    old = {k: v for k, v in scored.items() if k != 'capture_reference'}
    mc.write_json_atomic(os.path.join(run_dir, mc.RESULT_FILE), old)
    capsys.readouterr()
    assert main(args) == 0
    assert 'executed 0 run(s)' in capsys.readouterr().out
    assert mc.load_result(run_dir) == scored


# ---------------------------------------------------------------------- defaults, pure
def _args(scenario, **given):
    values = {'scenario': scenario, 'runs': 1, 'jobs': 1, 'out': None, 'duration': None,
              'seed': None, 'max_rate_deg_s': None, 'capture_deg': 5.0, 'mag_bias_nT': None,
              'misalignment_deg': None, 'engine': 'plain', 'compose': False}
    return argparse.Namespace(**{**values, **given})


@pytest.mark.parametrize('name, bound, reference', [
    ('paper000_control', 3.0, 'orbit frame'), ('paper001_mpi', 0.3, 'guidance target'),
    ('paper001_mpi_two_wings', 0.3, 'guidance target'), ('paper003_slew', 3.0, 'orbit frame'),
    ('demo_mission', 3.0, 'guidance target'), ('free_tumble', 3.0, 'orbit frame')])
def test_defaults_follow_the_scenario_and_the_option_wins(name, bound, reference, tmp_path):
    path = os.path.join(ROOT, 'scenarios', f'{name}.yaml')
    cfg, _, _ = config_from_args(_args(path, out=str(tmp_path / 'c')))
    assert (cfg.max_rate_deg_s, cfg.capture_reference) == (bound, reference)
    cfg, _, _ = config_from_args(_args(path, out=str(tmp_path / 'c'), max_rate_deg_s=1.5))
    assert cfg.max_rate_deg_s == 1.5


def test_an_eci_profile_is_judged_on_the_plain_engine(tmp_path):
    """paper003_slew with its target held in the ECI frame, published every 0.5 s (5 frames):
    the worker's angle (the held ECI target converted to the orbit frame with each frame's
    truth) is the angle the graph engine reads from a bag of the same run, in the ECI frame."""
    import yaml

    from adcs_nodes.tools.run.plain import run_plain
    with open(os.path.join(ROOT, 'scenarios', 'paper003_slew.yaml'), encoding='utf-8') as fh:
        sc = yaml.safe_load(fh)
    sc['guidance'].update(frame='eci', period_s=0.5)
    path = tmp_path / 'eci.yaml'
    path.write_text(yaml.safe_dump(sc))
    out = str(tmp_path / 'c')
    assert main([str(path), '--runs', '1', '--engine', 'plain', '--out', out]) == 0
    run_dir = mc.run_dir_of(out, 0)
    res = mc.load_result(run_dir)
    assert res['capture_reference'] == 'guidance target' and res['samples'] == 801
    bag = str(tmp_path / 'bag')
    # exit 3, degraded: from this dispersed start the manager gets no estimate (the
    # measurement is what is tested here, not the capture)
    assert run_plain(load_scenario(os.path.join(run_dir, 'scenario.yaml')), record=bag,
                     progress=False).exit_code in (0, 3)
    truth = mc.read_truth(bag)
    with np.load(os.path.join(run_dir, mc.SERIES_FILE)) as s:
        angle = angle_between_deg(s['q_orbit_target'], s['q_orbit_body'])
        q_target, judged = s['q_orbit_target'], s['target_judged']
    assert judged.all() and not np.isnan(angle).any()
    assert np.abs(angle - truth['target_angle_deg']).max() < 1e-9
    # an ECI target moves in the orbit frame (the orbit rate, about 0.06 deg/s), also
    # between the guidance's frames
    moved = angle_between_deg(q_target[-1:], q_target[:1])[0]
    assert 3.0 < moved < 7.0 and not np.array_equal(q_target[1], q_target[0])
    m = mc.bag_metrics(bag, 5.0, res['period_s'], mc.GUIDANCE_TARGET)
    for key in ('status', 'capture_time_s', 'first_entry_s', 'last_exit_s', 'samples'):
        assert m[key] == res[key], key
    assert m['final_angle_deg'] == pytest.approx(res['final_angle_deg'], abs=1e-9)


def test_the_judged_samples():
    """Samples of a maneuver toward an end state are left out of the capture test."""
    t = np.arange(6.0)
    ang = np.array([90.0, 60.0, 3.0, 40.0, 2.0, 1.0])     # the 40 deg inside a maneuver
    q = np.tile([0.0, 0.0, 0.0, 1.0], (6, 1))
    w = np.zeros((6, 3))
    judged = np.array([False, False, True, False, True, True])
    m = mc.series_metrics(t, q, w, w, 5.0, None, angle_deg=ang, judged=judged)
    assert m['status'] == 'captured' and m['capture_time_s'] == 2.0
    assert m['final_angle_deg'] == 1.0
    assert mc.series_metrics(t, q, w, w, 5.0, None, angle_deg=ang)['capture_time_s'] == 4.0
    none = mc.series_metrics(t, q, w, w, 5.0, None, angle_deg=ang, judged=np.zeros(6, bool))
    assert none['status'] == 'not_captured' and none['hold_median_deg'] is None
