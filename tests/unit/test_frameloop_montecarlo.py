"""``adcs montecarlo`` without processes: the run metrics, the dispersions and their
application to the scenario (pure functions), the summary and plot, and a campaign's
dispersed runs on the FrameLoop (the plain engine: no ROS, no process), each reaching its
run's initial state, sensor models and seed.

The pure-function tests were in ``tests/integration/test_montecarlo.py``, unchanged. The
FrameLoop test is that file's ``test_three_runs_in_parallel_and_every_dispersion_reached_its_run``
without the campaign's processes and bags: the truth is read from the FrameLoop's own first
``sim/state`` and the sensor models it built. The campaign command itself (processes,
parallel runs, resume, refusal, Dask, Ctrl-C) is ``tests/graph/test_montecarlo.py``.
"""
import dataclasses
import math
import os

import numpy as np
import pytest

from adcs_nodes.tools import campaigns as mc
from adcs_nodes.scenario import load_scenario
from frameloop_run import SCENARIOS, q, run, v

SCENARIO = os.path.join(SCENARIOS, 'paper000_control.yaml')
DURATION = 60.0


def quat_close(a, b, tol):
    return min(np.abs(a - b).max(), np.abs(a + b).max()) < tol


# ---------------------------------------------------------------------- pure functions
def test_run_metrics_use_the_paper_definitions():
    # angle about z: 50, 4, 6, 3, 2 deg at t = 0..4 s; capture = entering 5 deg and staying
    # below 10 (t = 1 s), the last exit from 5 deg is later (t = 3 s)
    ang = np.radians([50.0, 4.0, 6.0, 3.0, 2.0])
    q = np.stack([np.zeros(5), np.zeros(5), np.sin(ang / 2), np.cos(ang / 2)], axis=1)
    w = np.zeros((5, 3))
    w[:, 2] = 0.01
    m = mc.series_metrics(np.arange(5.0), q, w, w, 5.0, None)
    assert m['status'] == 'captured' and m['capture_time_s'] == 1.0
    assert m['last_exit_s'] == 3.0 and m['final_angle_deg'] == pytest.approx(2.0)
    assert m['max_rate_deg_s'] == pytest.approx(math.degrees(0.01))
    assert m['bag_initial']['q_orbit_body_xyzw'] == list(q[0])
    q[-1] = [0.0, 0.0, math.sin(0.1), math.cos(0.1)]          # 11.5 deg at the end
    assert mc.series_metrics(np.arange(5.0), q, w, w, 5.0, None)['status'] == 'not_captured'


def test_dispersions_are_deterministic_bounded_and_uniform_on_so3():
    cfg = mc.CampaignConfig('x.yaml', 'h', runs=4000, seed=7, duration_s=10.0,
                            mag_bias_nT=120.0, misalignment_deg=1.0)
    assert mc.draw_dispersion(cfg, 3) == mc.draw_dispersion(cfg, 3)
    assert mc.draw_dispersion(cfg, 3) != mc.draw_dispersion(cfg, 4)
    draws = [mc.draw_dispersion(cfg, i) for i in range(cfg.runs)]
    q = np.array([d.q_orbit_body_xyzw for d in draws])
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0) and np.all(q[:, 3] >= 0.0)
    # uniform on S^3: w has density (2/pi) sqrt(1 - w^2), so E|w| = 4 / (3 pi)
    assert abs(np.abs(q[:, 3]).mean() - 4.0 / (3.0 * math.pi)) < 0.02
    assert np.abs(q[:, :3].mean(axis=0)).max() < 0.03
    w = np.array([d.omega_body_eci_body_deg_s for d in draws])
    assert np.abs(w).max() <= 3.0 and np.abs(w).max() > 2.9
    assert np.abs(np.array([d.mag_bias_T for d in draws])).max() <= 120e-9
    assert np.abs(np.array([d.mag_misalignment_deg for d in draws])).max() <= 1.0
    assert len({d.seed for d in draws}) == cfg.runs
    # without sensor dispersion the same attitude, rate and seed are drawn, errors are None
    keep = mc.CampaignConfig('x.yaml', 'h', runs=1, seed=7, duration_s=10.0)
    a, b = mc.draw_dispersion(keep, 3), mc.draw_dispersion(cfg, 3)
    assert a.mag_bias_T is None and a.mag_misalignment_deg is None
    assert (a.q_orbit_body_xyzw, a.omega_body_eci_body_deg_s, a.seed) == \
        (b.q_orbit_body_xyzw, b.omega_body_eci_body_deg_s, b.seed)


def test_apply_dispersion_replaces_the_initial_state_and_sensor_errors():
    from adcs_nodes.scenario import load_scenario
    base = load_scenario(SCENARIO)
    cfg = mc.CampaignConfig(SCENARIO, 'h', runs=1, seed=1, duration_s=DURATION,
                            mag_bias_nT=120.0, misalignment_deg=1.0)
    disp = mc.draw_dispersion(cfg, 0)
    sc = mc.apply_dispersion(base, disp, DURATION, cfg)
    assert 'q_orbit_body_wxyz' not in sc['initial'] and '_path' not in sc
    assert sc['initial']['q_orbit_body_xyzw'] == disp.q_orbit_body_xyzw
    assert sc['sensors']['magnetometer']['bias_T'] == disp.mag_bias_T
    assert sc['seed'] == disp.seed and sc['duration_s'] == DURATION
    assert 'auto' not in sc.get('manager', {})
    assert base['initial']['q_orbit_body_wxyz'] == [0.36, 0.48, -0.48, 0.64]  # base untouched
    # default: the scenario's sensor errors; --auto-detumble: B-dot first, with its gain
    keep = mc.CampaignConfig(SCENARIO, 'h', runs=1, seed=1, duration_s=DURATION,
                             auto_detumble=True, bdot_gain=1e8)
    sc = mc.apply_dispersion(base, mc.draw_dispersion(keep, 0), DURATION, keep)
    assert sc['sensors']['magnetometer']['bias_T'] == base['sensors']['magnetometer']['bias_T']
    assert sc['manager']['auto'] == mc.AUTO_DETUMBLE and sc['manager']['initial'] == ''
    assert sc['controllers']['bdot']['gain_Am2s_per_T'] == 1e8


def test_summary_and_plot_from_synthetic_results(tmp_path):
    cfg = mc.CampaignConfig(SCENARIO, 'h', runs=4, seed=1, duration_s=40000.0)
    results = []
    for i, (status, t_cap, in_time, hold) in enumerate([
            ('captured', 300.0, True, 1.0), ('captured', 30000.0, False, 2.0),
            ('not_captured', None, False, 90.0), ('error', None, None, None)]):
        results.append({'index': i, 'status': status, 'capture_time_s': t_cap,
                        'captured_in_time': in_time, 'hold_median_deg': hold,
                        'hold_rms_deg': hold, 'final_angle_deg': 1.0 if t_cap else 90.0,
                        'missed_frames': 0,
                        'dispersion': dataclasses.asdict(mc.draw_dispersion(cfg, i))})
    base = {'name': 'x', 'orbit': {'type': 'circular', 'altitude_km': 690.0}}
    text = mc.summary_markdown(cfg, results, base)
    assert '| runs completed | 3 of 4 |' in text
    assert '2/3 = 66.7 %' in text
    assert '| captured within 4 orbits (target >= 95 %) | 1/3 = 33.3 % |' in text
    assert '| capture time, median [s] | 15150 (2.56 orbits) |' in text
    assert '| hold median per run: median / 90th percentile / max [deg] (target: median ' \
        '<= 1.5) | 2.00 / 72.40 / 90.00 |' in text
    assert '| runs with a hold median <= 1.5 deg | 1/3 = 33.3 % |' in text
    png = tmp_path / 'plot.png'
    mc.plot_capture_vs_rate(str(png), cfg, results, base)
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


# ---------------------------------------------------------------------- the runs on the FrameLoop
def test_three_dispersed_runs_each_start_from_their_dispersion():
    """As a 3-run campaign of 60 s with magnetometer dispersion (``--mag-bias-nT 120
    --misalignment-deg 1``, the campaign's default seed, the scenario's 21) prepares them."""
    base = load_scenario(SCENARIO)
    cfg = mc.CampaignConfig(SCENARIO, 'h', runs=3, seed=21, duration_s=DURATION,
                            mag_bias_nT=120.0, misalignment_deg=1.0)
    disps = []
    for i in range(3):
        disp = mc.draw_dispersion(cfg, i)
        disps.append(disp)
        out, loop = run(mc.apply_dispersion(base, disp, DURATION, cfg))
        first = out['sim/state'][0]
        assert quat_close(q(first.q_orbit_body), np.array(disp.q_orbit_body_xyzw), 1e-9), i
        assert np.abs(np.degrees(v(first.omega_body_eci_body))
                      - disp.omega_body_eci_body_deg_s).max() < 1e-9, i
        # sensor errors and seed: what the run's magnetometer model and random streams use
        mags = [comp.model for topic, _, comp in loop.sensors
                if topic == 'sensors/magnetometer']
        assert len(mags) == 1
        assert np.abs(mags[0].bias_T - np.array(disp.mag_bias_T)).max() < 1e-18
        assert np.abs(np.degrees(mags[0].misalignment_rad)
                      - np.array(disp.mag_misalignment_deg)).max() < 1e-12
        assert loop.seed == disp.seed
        # the run ran to its end and has a status
        states = out['sim/state']
        t = np.array([(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec) for m in states])
        t = (t - t[0]) / 1e9
        m = mc.series_metrics(t, np.array([q(s.q_orbit_body) for s in states]),
                              np.array([v(s.omega_body_eci_body) for s in states]),
                              np.array([v(s.omega_body_orbit_body) for s in states]),
                              cfg.capture_deg, None)
        assert m['status'] in ('captured', 'not_captured') and t[-1] == DURATION
    # the runs differ from each other
    for a in range(3):
        for b in range(a + 1, 3):
            assert not quat_close(np.array(disps[a].q_orbit_body_xyzw),
                                  np.array(disps[b].q_orbit_body_xyzw), 1e-3)
            assert np.abs(np.array(disps[a].omega_body_eci_body_deg_s)
                          - disps[b].omega_body_eci_body_deg_s).max() > 1e-3
    assert len({d.seed for d in disps}) == 3


# ---------------------------------------------------------------------- an interrupt's race
class _RacingBackend:
    """Run 0 writes its result files, then Ctrl-C arrives before its result is delivered
    (the race a clean-clone run met once: the table said 'pending' for a finished run)."""

    def __init__(self, out):
        self.out = out
        self.jobs = []

    def submit(self, job):
        self.jobs.append(job)

    def results(self):
        run_dir = self.jobs[0]['run_dir']
        np.savez_compressed(os.path.join(run_dir, mc.SERIES_FILE), t_s=np.zeros(1))
        mc.write_json_atomic(os.path.join(run_dir, mc.RESULT_FILE),
                             {'index': 0, 'status': 'captured', 'capture_time_s': 5.0,
                              'final_angle_deg': 1.0})
        raise KeyboardInterrupt
        yield  # a generator, as the backends' results()

    def drain(self, timeout_s):
        return iter(())

    def close(self):
        pass


def test_an_interrupt_keeps_a_finished_run_that_was_not_delivered_yet(tmp_path, monkeypatch):
    from adcs_nodes.tools.campaigns import campaign as campaign_mod
    base = load_scenario(SCENARIO)
    cfg = mc.CampaignConfig(SCENARIO, 'h', runs=2, seed=1, duration_s=DURATION)
    out = str(tmp_path / 'c')
    monkeypatch.setattr(campaign_mod, 'LocalBackend', lambda jobs: _RacingBackend(out))
    c = campaign_mod.Campaign(cfg, base, out, log=lambda text: None)
    assert c.run(jobs=1) == 130
    rows = {r['index']: r for r in c._sorted_rows()}
    assert rows[0]['status'] == 'captured' and c.executed == 1
    assert rows[1]['status'] == 'pending'
    with open(os.path.join(out, 'campaign.csv'), encoding='utf-8') as fh:
        assert 'captured' in fh.read()
