"""Campaign definition and the dispersion of each run (see the package docstring)."""
from __future__ import annotations

import copy
import hashlib
import json
from dataclasses import dataclass
from typing import Any, Dict, List, Optional

import numpy as np

#: Keys of ``campaign.json`` that must match for a restart to resume the campaign (one without
#: ``capture_reference`` measured to the orbit frame).
IDENTITY_KEYS = ('scenario_sha256', 'seed', 'duration_s', 'max_rate_deg_s', 'capture_deg',
                 'mag_bias_nT', 'misalignment_deg', 'auto_detumble', 'bdot_gain', 'engine',
                 'capture_reference')
#: Default bound of each initial rate component [deg/s] by the first 3 characters of the
#: scenario's ``paper:`` key: paper 000's "up to 3 deg/s"; 0.3 deg/s for paper 001, an
#: ASSUMPTION (its wheels would saturate at 3 deg/s): ``docs/montecarlo.md``.
MAX_RATE_BY_PAPER_DEG_S = {'000': 3.0, '001': 0.3}
#: Default bound for a scenario of another paper or of none [deg/s] (paper 000's).
DEFAULT_MAX_RATE_DEG_S = 3.0
ENGINES = ('graph', 'plain')
#: Automatic sequence written by ``--auto-detumble`` (``manager.auto``; the scenario schema's
#: defaults): B-dot until ``|omega_body_eci_body|`` < 0.5 deg/s for 10 frames, then magnetic;
#: back to B-dot above 1 deg/s.
AUTO_DETUMBLE = {'detumble': 'bdot', 'acquire': 'magnetic', 'rate_enter_deg_s': 0.5,
                 'rate_exit_deg_s': 1.0, 'confirm_frames': 10, 'exit_confirm_frames': 1,
                 'rate_frame': 'eci'}


class CampaignError(ValueError):
    """Bad campaign arguments, or a restart whose arguments differ from ``campaign.json``."""


@dataclass(frozen=True)
class CampaignConfig:
    """What defines a campaign (its identity, :data:`IDENTITY_KEYS`) and its number of runs.

    Attributes
    ----------
    scenario_path, scenario_sha256 : str
        The base scenario YAML (absolute path) and the hash of its validated dict.
    runs, seed : int
        Runs ``0 .. runs - 1``; run ``i`` draws from ``default_rng([seed, i])``.
    duration_s : float
        Simulated duration of every run [s].
    max_rate_deg_s, capture_deg : float
        Bound of each initial rate component [deg/s] (:func:`default_max_rate_deg_s`);
        capture threshold on the angle between the body and the guidance target [deg].
    mag_bias_nT, misalignment_deg : float or None
        Bound of each magnetometer bias component [nT] and misalignment rotation-vector
        component [deg]; None: the scenario's (not dispersed).
    auto_detumble : bool
        Each run gets the automatic sequence :data:`AUTO_DETUMBLE` (``manager.auto``).
    bdot_gain : float or None
        B-dot gain of the detumble [A m^2 s/T]; None: the scenario's.
    engine : str
        ``'graph'`` (the ROS graph, a bag per run) or ``'plain'`` (the FrameLoop).
    compose : bool
        Each graph composed in one process (not part of the identity).
    capture_reference : str
        ``'orbit frame'`` or ``'guidance target'``
        (:func:`~adcs_nodes.tools.campaigns.capture.capture_reference`): a campaign measured
        to one is not resumed as one measured to the other.
    """

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
    """Dispersed values of one run (:func:`draw_dispersion`).

    Attributes
    ----------
    index, seed : int
        Run index in the campaign; the run's scenario seed.
    q_orbit_body_xyzw : list of float, shape (4,)
        Initial attitude, body -> orbit, scalar last, ``w >= 0``.
    omega_body_eci_body_deg_s : list of float, shape (3,)
        Initial rate of body w.r.t. ECI, body axes [deg/s].
    mag_bias_T, mag_misalignment_deg : list of float, shape (3,), or None
        Magnetometer bias, sensor axes [T], and misalignment, body -> sensor rotation vector
        [deg] (None: the scenario's).
    """

    index: int
    seed: int
    q_orbit_body_xyzw: List[float]
    omega_body_eci_body_deg_s: List[float]
    mag_bias_T: Optional[List[float]]
    mag_misalignment_deg: Optional[List[float]]


def default_max_rate_deg_s(scenario: Dict[str, Any]) -> float:
    """Default bound of each initial rate component [deg/s] of a campaign of ``scenario``
    (:data:`MAX_RATE_BY_PAPER_DEG_S`, else :data:`DEFAULT_MAX_RATE_DEG_S`)."""
    paper = str(scenario.get('paper') or '')[:3]
    return MAX_RATE_BY_PAPER_DEG_S.get(paper, DEFAULT_MAX_RATE_DEG_S)


def scenario_hash(scenario: Dict[str, Any]) -> str:
    """SHA-256 of a validated scenario dict (``_path`` and other private keys excluded)."""
    clean = {k: v for k, v in scenario.items() if not k.startswith('_')}
    return hashlib.sha256(json.dumps(clean, sort_keys=True).encode()).hexdigest()


def draw_dispersion(cfg: CampaignConfig, index: int) -> Dispersion:
    """The dispersion of run ``index``, deterministic in ``cfg.seed`` and ``index``: attitude
    uniform on SO(3), rate components uniform in ``+-max_rate_deg_s``, magnetometer bias and
    misalignment uniform per axis, the run's scenario seed (``docs/montecarlo.md``)."""
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
    """Deep copy of the validated scenario ``base`` with the run's dispersion written in: the
    initial attitude and rate (replacing ``initial``'s alternative keys), the magnetometer
    errors when dispersed, with ``cfg.auto_detumble`` the manager's :data:`AUTO_DETUMBLE`
    (and ``cfg.bdot_gain``)."""
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
