"""``summary.md`` and ``capture_vs_rate.png`` of a campaign."""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from adcs_nodes.tools.analyse.papers.series import orbit_period_s  # noqa: F401 (re-exported)
from adcs_nodes.tools.campaigns.capture import ORBIT_FRAME
from adcs_nodes.tools.campaigns.config import AUTO_DETUMBLE, CampaignConfig


def _rate_of(result: Dict[str, Any]) -> float:
    return float(np.linalg.norm(result['dispersion']['omega_body_eci_body_deg_s']))


def rate_bins(cfg: CampaignConfig, n_runs: int) -> np.ndarray:
    """Edges of the initial-rate bins [deg/s]: 0 .. sqrt(3) max_rate, 2 to 6 bins."""
    count = int(min(6, max(2, n_runs // 5)))
    return np.linspace(0.0, math.sqrt(3.0) * cfg.max_rate_deg_s, count + 1)


def _bin_table(cfg: CampaignConfig, done: Sequence[Dict[str, Any]]) -> List[tuple]:
    edges = rate_bins(cfg, len(done))
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        last = hi == edges[-1]
        inside = [r for r in done if lo <= _rate_of(r) < hi or (last and _rate_of(r) >= hi)]
        ok = sum(1 for r in inside if r['status'] == 'captured')
        in_time = sum(1 for r in inside if r.get('captured_in_time'))
        rows.append((lo, hi, len(inside), ok, in_time))
    return rows


def summary_markdown(cfg: CampaignConfig, results: Sequence[Dict[str, Any]],
                     base: Dict[str, Any]) -> str:
    """``summary.md``: campaign definition, success rate, capture-time statistics, bins."""
    done = [r for r in results if r.get('status') in ('captured', 'not_captured')]
    captured = [r for r in done if r['status'] == 'captured']
    period = orbit_period_s(base)
    if 'magnetometer' in (base.get('sensors') or {}):
        bias = (', the scenario\'s magnetometer bias' if cfg.mag_bias_nT is None
                else f', magnetometer bias +-{cfg.mag_bias_nT:g} nT per axis')
        mis = (', the scenario\'s misalignment' if cfg.misalignment_deg is None
               else f', misalignment +-{cfg.misalignment_deg:g} deg per axis')
    else:                        # no magnetometer: its errors are drawn, not applied
        bias, mis = '', ''
    mode = (f'automatic B-dot detumble first (below {AUTO_DETUMBLE["rate_enter_deg_s"]} deg/s, '
            f'then the magnetic law; B-dot gain '
            f'{"of the scenario" if cfg.bdot_gain is None else f"{cfg.bdot_gain:g} A m^2 s/T"})'
            if cfg.auto_detumble else 'the scenario\'s controller from t = 0')
    lines = [f'# Monte Carlo campaign: {base.get("name", "?")}', '',
             f'Scenario `{cfg.scenario_path}`, seed {cfg.seed}, {cfg.runs} runs of '
             f'{cfg.duration_s:g} s ({cfg.engine} engine); initial rate components uniform in '
             f'+-{cfg.max_rate_deg_s:g} deg/s, attitude uniform on SO(3){bias}{mis}; '
             f'{mode}. Captured: the angle between the body and the {_reference_text(cfg)} '
             f'enters {cfg.capture_deg:g} deg and then stays below {2 * cfg.capture_deg:g} deg '
             'to the end of the run (:mod:`adcs_nodes.tools.analyse.metrics`). Hold: the '
             'angle from 4 '
             'orbits to the end.', '',
             '| quantity | value |', '|---|---|',
             f'| runs completed | {len(done)} of {cfg.runs} |',
             f'| runs failed | {sum(1 for r in results if r.get("status") == "error")} |',
             f'| success rate (captured / completed) | {_rate_text(len(captured), len(done))} |']
    in_time = [r for r in done if r.get('captured_in_time')]
    lines.append(f'| captured within 4 orbits (target >= 95 %) | '
                 f'{_rate_text(len(in_time), len(done))} |')
    lines += _capture_stats(captured, period)
    lines += _hold_stats(done)
    missed = sum(int(r.get('missed_frames') or 0) for r in done)
    lines += [f'| missed lockstep frames (all runs) | {missed} |', '',
              '## Success rate against initial rate', '',
              '| initial rate \\|omega0\\| [deg/s] | runs | captured | success rate | within 4 '
              'orbits |', '|---|---|---|---|---|']
    for lo, hi, n, ok, in_time in _bin_table(cfg, done):
        lines.append(f'| {lo:.2f} - {hi:.2f} | {n} | {ok} | {_rate_text(ok, n)} | '
                     f'{_rate_text(in_time, n)} |')
    lines += ['', 'Table: `campaign.csv`; plot: `capture_vs_rate.png`.', '']
    return '\n'.join(lines)


def _reference_text(cfg: CampaignConfig) -> str:
    """What the capture angle is measured to (:mod:`.capture`)."""
    if cfg.capture_reference == ORBIT_FRAME:
        return 'orbit frame (the scenario\'s guidance holds it)'
    return ('guidance target (`adcs/attitude_target`, the attitude the controllers track; '
            'samples of a maneuver toward a segment\'s end state are not judged)')


def _hold_stats(done: Sequence[Dict[str, Any]]) -> List[str]:
    """Distribution over the runs of each run's hold median and RMS [deg]."""
    med = np.array([r['hold_median_deg'] for r in done
                    if isinstance(r.get('hold_median_deg'), (int, float))])
    rms = np.array([r['hold_rms_deg'] for r in done
                    if isinstance(r.get('hold_rms_deg'), (int, float))])
    if med.size == 0:
        return ['| hold accuracy | no run reached 4 orbits |']
    ok = int(np.sum(med <= 1.5))
    return [f'| hold median per run: median / 90th percentile / max [deg] (target: median '
            f'<= 1.5) | {np.median(med):.2f} / {np.percentile(med, 90):.2f} / '
            f'{med.max():.2f} |',
            f'| hold RMS per run: median / 90th percentile / max [deg] | '
            f'{np.median(rms):.2f} / {np.percentile(rms, 90):.2f} / {rms.max():.2f} |',
            f'| runs with a hold median <= 1.5 deg | {_rate_text(ok, med.size)} |']


def _rate_text(ok: int, n: int) -> str:
    return f'{ok}/{n} = {100.0 * ok / n:.1f} %' if n else 'n/a'


def _capture_stats(captured: Sequence[Dict[str, Any]], period: Optional[float]) -> List[str]:
    if not captured:
        return ['| capture time | no run captured |']
    times = np.array([r['capture_time_s'] for r in captured])
    finals = np.array([r['final_angle_deg'] for r in captured])
    out = []
    for name, value in (('min', times.min()), ('median', np.median(times)),
                        ('mean', times.mean()), ('90th percentile', np.percentile(times, 90)),
                        ('max', times.max())):
        orbits = f' ({value / period:.2f} orbits)' if period else ''
        out.append(f'| capture time, {name} [s] | {value:.0f}{orbits} |')
    out.append(f'| final angle of captured runs, median / max [deg] | '
               f'{np.median(finals):.2f} / {finals.max():.2f} |')
    return out


def plot_capture_vs_rate(path: str, cfg: CampaignConfig,
                         results: Sequence[Dict[str, Any]],
                         base: Optional[Dict[str, Any]] = None) -> None:
    """Capture time against initial rate magnitude, and success rate per rate bin (PNG)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    done = [r for r in results if r.get('status') in ('captured', 'not_captured')]
    period = orbit_period_s(base) if base else None
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 7), sharex=True)
    cap = [r for r in done if r['status'] == 'captured']
    held = [r for r in cap if isinstance(r.get('hold_median_deg'), (int, float))
            and r['hold_median_deg'] <= 1.5]
    loose = [r for r in cap if r not in held]
    ax1.plot([_rate_of(r) for r in held], [r['capture_time_s'] for r in held], 'o',
             label='captured, hold median <= 1.5 deg')
    if loose:
        ax1.plot([_rate_of(r) for r in loose], [r['capture_time_s'] for r in loose], 's',
                 mfc='none', label='captured, hold median > 1.5 deg (or no hold)')
    miss = [r for r in done if r['status'] == 'not_captured']
    if miss:
        ax1.plot([_rate_of(r) for r in miss], [cfg.duration_s] * len(miss), 'rx',
                 label='not captured (plotted at the run end)')
    ax1.set_ylim(bottom=0.0)
    if cfg.duration_s > 4 * (period or math.inf):
        ax1.axhline(4 * period, color='k', ls='--', lw=0.8, label='4 orbits')
    ax1.set_ylabel('capture time [s]')
    ax1.set_title(f'capture (enters {cfg.capture_deg:g} deg, stays within '
                  f'{2 * cfg.capture_deg:g} deg), {len(done)} runs')
    ax1.legend(loc='best')
    ax1.grid(True)
    bins = _bin_table(cfg, done)
    centres = [(lo + hi) / 2 for lo, hi, _, _, _ in bins]
    width = (bins[0][1] - bins[0][0]) * 0.9
    ax2.bar(centres, [100.0 * ok / n if n else 0.0 for _, _, n, ok, _ in bins], width=width,
            color='lightsteelblue', label='captured')
    ax2.bar(centres, [100.0 * t / n if n else 0.0 for _, _, n, _, t in bins],
            width=width * 0.5, color='tab:blue', label='captured within 4 orbits')
    ax2.legend(loc='lower right', fontsize=8)
    for x, (_, _, n, _, _) in zip(centres, bins):
        ax2.annotate(f'n={n}', (x, 2), ha='center', fontsize=8)
    ax2.set_ylim(0, 105)
    ax2.set_xlabel('initial rate |omega_body_eci_body| [deg/s]')
    ax2.set_ylabel('success rate [%]')
    ax2.grid(True)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
