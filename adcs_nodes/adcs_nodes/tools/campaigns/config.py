"""Campaign definition, the dispersion of each run, the engine it runs on."""
from __future__ import annotations

import copy
import hashlib
import json
import os
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

#: Keys of ``campaign.json`` that must match for a restart to resume the campaign.
IDENTITY_KEYS = ('scenario_sha256', 'seed', 'duration_s', 'max_rate_deg_s', 'capture_deg',
                 'mag_bias_nT', 'misalignment_deg', 'auto_detumble', 'bdot_gain', 'engine',
                 'capture_reference')
#: Default bound of each initial rate component [deg/s] by the scenario's ``paper:``: paper
#: 000's "up to 3 deg/s"; 0.3 for paper 001 (ASSUMPTION: ``docs/montecarlo.md``).
MAX_RATE_BY_PAPER_DEG_S = {'000': 3.0, '001': 0.3}
#: Default bound for a scenario of another paper or of none [deg/s] (paper 000's).
DEFAULT_MAX_RATE_DEG_S = 3.0
ENGINES = ('graph', 'plain')
#: ``manager.auto`` of ``--auto-detumble``: B-dot below 0.5 deg/s, then magnetic.
AUTO_DETUMBLE = {'detumble': 'bdot', 'acquire': 'magnetic', 'rate_enter_deg_s': 0.5,
                 'rate_exit_deg_s': 1.0, 'confirm_frames': 10, 'exit_confirm_frames': 1,
                 'rate_frame': 'eci'}


class CampaignError(ValueError):
    """Bad campaign arguments, or a restart whose arguments differ from ``campaign.json``."""


@dataclass(frozen=True)
class CampaignConfig:
    """A campaign: its identity (:data:`IDENTITY_KEYS`; run ``i`` draws from
    ``default_rng([seed, i])``; bounds [deg/s], [nT], [deg]) and its number of runs."""

    scenario_path: str
    scenario_sha256: str
    runs: int
    seed: int
    duration_s: float
    max_rate_deg_s: float = 3.0
    capture_deg: float = 5.0
    mag_bias_nT: Optional[float] = None
    misalignment_deg: Optional[float] = None
    auto_detumble: bool = False
    bdot_gain: Optional[float] = None
    engine: str = 'graph'
    compose: bool = False
    capture_reference: str = 'orbit frame'

    def identity(self) -> Dict[str, Any]:
        """The values a restart must repeat (see :data:`IDENTITY_KEYS`)."""
        return {k: getattr(self, k) for k in IDENTITY_KEYS}


@dataclass(frozen=True)
class Dispersion:
    """Dispersed values of run ``index``: rate [deg/s], bias [T], misalignment [deg]."""

    index: int
    seed: int
    q_orbit_body_xyzw: List[float]
    omega_body_eci_body_deg_s: List[float]
    mag_bias_T: Optional[List[float]]
    mag_misalignment_deg: Optional[List[float]]


def default_max_rate_deg_s(scenario: Dict[str, Any]) -> float:
    """Default bound of each initial rate component [deg/s] of a campaign of ``scenario``."""
    paper = str(scenario.get('paper') or '')[:3]
    return MAX_RATE_BY_PAPER_DEG_S.get(paper, DEFAULT_MAX_RATE_DEG_S)


def scenario_hash(scenario: Dict[str, Any]) -> str:
    """SHA-256 of a validated scenario dict (``_path`` and other private keys excluded)."""
    clean = {k: v for k, v in scenario.items() if not k.startswith('_')}
    return hashlib.sha256(json.dumps(clean, sort_keys=True).encode()).hexdigest()


def draw_dispersion(cfg: CampaignConfig, index: int) -> Dispersion:
    """The dispersion of run ``index``: attitude uniform on SO(3), the rest per axis."""
    rng = np.random.default_rng([cfg.seed, index])
    q = rng.standard_normal(4)
    q /= np.linalg.norm(q)
    if q[3] < 0.0:
        q = -q
    rate = rng.uniform(-cfg.max_rate_deg_s, cfg.max_rate_deg_s, 3)
    # drawn even when not applied (unit bounds), so the later draws never depend on it
    bias = rng.uniform(-1.0, 1.0, 3) * (cfg.mag_bias_nT or 0.0) * 1e-9
    mis = rng.uniform(-1.0, 1.0, 3) * (cfg.misalignment_deg or 0.0)
    seed = int(rng.integers(0, 2**31 - 1))
    return Dispersion(index, seed, q.tolist(), rate.tolist(),
                      None if cfg.mag_bias_nT is None else bias.tolist(),
                      None if cfg.misalignment_deg is None else mis.tolist())


def apply_dispersion(base: Dict[str, Any], disp: Dispersion, duration_s: float,
                     cfg: Optional[CampaignConfig] = None) -> Dict[str, Any]:
    """Deep copy of the validated ``base`` with the run's dispersion (and ``cfg``) in."""
    sc = copy.deepcopy({k: v for k, v in base.items() if not k.startswith('_')})
    sc['seed'] = disp.seed
    sc['duration_s'] = float(duration_s)
    init = sc.setdefault('initial', {})
    init.pop('q_orbit_body_wxyz', None)
    init.pop('omega_body_orbit_body_deg_s', None)
    init['q_orbit_body_xyzw'] = list(disp.q_orbit_body_xyzw)
    init['omega_body_eci_body_deg_s'] = list(disp.omega_body_eci_body_deg_s)
    mag = sc.get('sensors', {}).get('magnetometer')
    if mag is not None:
        if disp.mag_bias_T is not None:
            mag['bias_T'] = list(disp.mag_bias_T)
        if disp.mag_misalignment_deg is not None:
            mag['misalignment_deg'] = list(disp.mag_misalignment_deg)
    if cfg is not None and cfg.auto_detumble:
        man = sc.setdefault('manager', {})
        man['auto'] = dict(AUTO_DETUMBLE)
        man['initial'] = ''
        if cfg.bdot_gain is not None and 'bdot' in sc.get('controllers', {}):
            sc['controllers']['bdot']['gain_Am2s_per_T'] = float(cfg.bdot_gain)
    return sc


# ---------------------------------------------------------------------- engine (--engine)
def plain_engine_problem(sc: Dict[str, Any]) -> Optional[str]:
    """Why the plain engine cannot run the validated ``sc``; None when it can."""
    external = sorted(k for k, cfg in (sc.get('sensors') or {}).items() if cfg.get('external'))
    if external:
        return f'external sensors ({", ".join(external)}) need their drivers: a graph'
    return None


def recorded_engine(out: str) -> Optional[str]:
    """The engine in ``out/campaign.json`` (default ``'graph'``), or None (no campaign)."""
    path = os.path.join(out, 'campaign.json')
    if not os.path.isfile(path):
        return None
    try:
        with open(path, encoding='utf-8') as fh:
            data = json.load(fh)
    except (OSError, ValueError):
        return None   # unreadable: the identity check reports it
    engine = data.get('engine', 'graph') if isinstance(data, dict) else None
    return engine if engine in ENGINES else None


def resolve_engine(requested: Optional[str], sc: Dict[str, Any],
                   out: str) -> Tuple[str, str]:
    """``(engine, reason)`` of a campaign of ``sc`` in ``out`` for ``--engine`` ``requested``."""
    if requested in ENGINES:
        return requested, '--engine'
    if requested not in (None, 'auto'):
        raise ValueError(f'--engine must be auto, {" or ".join(ENGINES)}, got {requested!r}')
    old = recorded_engine(out)
    if old is not None:
        return old, 'auto: the engine of the campaign being resumed'
    problem = plain_engine_problem(sc)
    if problem is None:
        return 'plain', 'auto: the plain engine runs this scenario'
    return 'graph', f'auto: {problem}'
