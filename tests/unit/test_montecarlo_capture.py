"""``adcs montecarlo``'s capture test per scenario (:mod:`adcs_nodes.tools.montecarlo.capture`):
the angle between the body and the attitude the scenario's guidance commands.

paper001_mpi: a 3-run campaign of 400 s on the plain engine (real run processes), judged
against paper 001's profile: the angle is computed here again from the run's ``series.npz``
with numpy alone (the paper's 3-1-2 Euler hold attitude written out as matrices, not through
the package), so a capture measured to the orbit frame fails. The recorded target (a bag of the
same run from the plain engine) is the rebuilt one, bit for bit. paper000_control: the numbers
are those of the angle to the orbit frame, and a campaign from before the guidance target
resumes with them; a paper001 campaign from before is refused with the reason. The default
initial-rate bound follows the scenario's paper; ``--max-rate-deg-s`` wins.
"""
import argparse
import json
import math
import os
import shutil

import numpy as np
import pytest

from adcs_nodes.tools import montecarlo as mc
from adcs_nodes.tools.montecarlo.cli import config_from_args, main
from adcs_nodes.tools.scenario import load_scenario

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


def test_the_recorded_target_is_the_rebuilt_one(campaign001, tmp_path):
    """Run 0 again on the plain engine with a bag: its recorded ``adcs/attitude_target`` is
    the target the capture test rebuilt from the scenario, bit for bit, and the bag's metrics
    (the graph engine's reading) are the plain result's."""
    from adcs_nodes.bag import read_messages
    from sim_node.engine import run_plain
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
        t = s['t_s']
    q_built, judged = mc.guidance_targets(sc, t)
    assert np.array_equal(np.array(q_rec), q_built)
    assert np.array_equal(np.array(judged_rec), judged) and not judged[t < 200.0].any()
    m = mc.bag_metrics(bag, 5.0, results[0]['period_s'], mc.GUIDANCE_TARGET)
    for key in ('status', 'capture_time_s', 'first_entry_s', 'last_exit_s', 'samples',
                'capture_reference'):
        assert m[key] == results[0][key], key
    assert m['final_angle_deg'] == pytest.approx(results[0]['final_angle_deg'], abs=1e-9)


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
    """The worker's result (angle to the orbit frame) is kept as it is, labelled; a campaign
    from before (no capture_reference anywhere) resumes with nothing to run, same numbers."""
    out = tmp_path / 'mc'
    args = [P000, '--runs', '1', '--duration', '20', '--out', str(out), '--engine', 'plain']
    assert main(args) == 0
    run_dir = mc.run_dir_of(str(out), 0)
    with open(os.path.join(run_dir, mc.RESULT_FILE), encoding='utf-8') as fh:
        scored = json.load(fh)
    assert scored['capture_reference'] == 'orbit frame'
    with np.load(os.path.join(run_dir, mc.SERIES_FILE)) as s:
        expected = mc.series_metrics(s['t_s'], s['q_orbit_body'], s['w_eci'], s['w_orbit'],
                                     5.0, scored['period_s'])
    assert {k: scored[k] for k in expected} == expected
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


def test_an_eci_profile_is_refused_on_the_plain_engine(tmp_path):
    import yaml
    with open(os.path.join(ROOT, 'scenarios', 'paper003_slew.yaml'), encoding='utf-8') as fh:
        sc = yaml.safe_load(fh)
    sc['guidance']['frame'] = 'eci'
    path = tmp_path / 'eci.yaml'
    path.write_text(yaml.safe_dump(sc))
    with pytest.raises(mc.CampaignError, match='eci frame.*--engine graph'):
        config_from_args(_args(str(path), out=str(tmp_path / 'c')))
    cfg, _, _ = config_from_args(_args(str(path), out=str(tmp_path / 'c'), engine='graph'))
    assert cfg.capture_reference == 'guidance target'


def test_the_judged_samples_and_a_recorded_target():
    """Samples of a maneuver toward an end state are left out of the capture test; a
    ``q_orbit_target`` in ``series.npz`` (the worker recording the target) is used as is."""
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


def test_a_recorded_target_in_the_series_is_used(tmp_path):
    run_dir = tmp_path / 'run'
    run_dir.mkdir()
    shutil.copy(P001, run_dir / 'scenario.yaml')
    (run_dir / 'job.json').write_text(json.dumps({'capture_deg': 5.0}))
    half = math.sqrt(0.5)
    t = np.arange(4.0)
    q_body = np.tile([half, 0.0, 0.0, half], (4, 1))          # 90 deg about x from orbit
    q_target = np.tile([half, 0.0, 0.0, half], (4, 1))
    q_target[0] = [0.0, 0.0, 0.0, 1.0]
    np.savez(run_dir / mc.SERIES_FILE, t_s=t, q_orbit_body=q_body, w_eci=np.zeros((4, 3)),
             w_orbit=np.zeros((4, 3)), q_orbit_target=q_target)
    res = mc.score_plain_result(str(run_dir), {'engine': 'plain', 'period_s': None})
    assert res['capture_reference'] == 'guidance target'
    assert res['capture_time_s'] == 1.0 and res['final_angle_deg'] == pytest.approx(0.0)
    with open(run_dir / mc.RESULT_FILE, encoding='utf-8') as fh:
        assert json.load(fh) == res
