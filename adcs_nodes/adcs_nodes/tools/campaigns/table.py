"""``campaign.csv``: one row per run, floats in full precision."""
from __future__ import annotations

import csv
import io
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from adcs_nodes.tools.campaigns.files import write_text_atomic

_VEC = ('x', 'y', 'z')
_QUAT = ('x', 'y', 'z', 'w')
#: Columns of ``campaign.csv``.
CSV_COLUMNS: List[str] = (
    ['index', 'seed', 'status']
    + [f'disp_q_orbit_body_{c}' for c in _QUAT]
    + [f'disp_omega_body_eci_body_{c}_deg_s' for c in _VEC]
    + ['disp_rate_deg_s']
    + [f'disp_mag_bias_{c}_T' for c in _VEC]
    + [f'disp_mag_misalignment_{c}_deg' for c in _VEC]
    + ['capture_reference', 'capture_time_s', 'captured_in_time', 'last_exit_s',
       'hold_rms_deg', 'hold_median_deg', 'hold_p95_deg', 'final_angle_deg', 'final_rate_deg_s',
       'max_rate_deg_s']
    + [f'bag_q_orbit_body_{c}' for c in _QUAT]
    + [f'bag_omega_body_eci_body_{c}_deg_s' for c in _VEC]
    + ['engine', 'sim_time_s', 'wall_time_s', 'missed_frames', 'host', 'supervisor_pid',
       'message'])


def table_row(result: Dict[str, Any]) -> Dict[str, Any]:
    """One ``campaign.csv`` row (:data:`CSV_COLUMNS`) from a run's result dict."""
    disp = result.get('dispersion') or {}
    init = result.get('bag_initial') or {}
    row: Dict[str, Any] = {'index': result['index'], 'seed': disp.get('seed', ''),
                           'status': result.get('status', '')}
    _put(row, 'disp_q_orbit_body_{}', _QUAT, disp.get('q_orbit_body_xyzw'))
    omega = disp.get('omega_body_eci_body_deg_s')
    _put(row, 'disp_omega_body_eci_body_{}_deg_s', _VEC, omega)
    row['disp_rate_deg_s'] = repr(float(np.linalg.norm(omega))) if omega else ''
    _put(row, 'disp_mag_bias_{}_T', _VEC, disp.get('mag_bias_T'))
    _put(row, 'disp_mag_misalignment_{}_deg', _VEC, disp.get('mag_misalignment_deg'))
    _put(row, 'bag_q_orbit_body_{}', _QUAT, init.get('q_orbit_body_xyzw'))
    _put(row, 'bag_omega_body_eci_body_{}_deg_s', _VEC, init.get('omega_body_eci_body_deg_s'))
    for key in (k for k in CSV_COLUMNS if k not in row):      # the result's own values
        value = result.get(key)
        row[key] = '' if value is None else (repr(value) if isinstance(value, float)
                                             else value)
    return row


def _put(row: Dict[str, Any], pattern: str, names: Sequence[str],
         values: Optional[Sequence[float]]) -> None:
    for j, name in enumerate(names):
        row[pattern.format(name)] = repr(float(values[j])) if values else ''


def write_table(path: str, results: Sequence[Dict[str, Any]]) -> None:
    """Write ``campaign.csv`` atomically; floats in full precision (``repr``)."""
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=CSV_COLUMNS)
    writer.writeheader()
    writer.writerows(table_row(result) for result in results)
    write_text_atomic(path, text.getvalue())


def read_table(path: str) -> List[Dict[str, str]]:
    """Rows of a ``campaign.csv`` as dicts of strings."""
    with open(path, encoding='utf-8', newline='') as fh:
        return list(csv.DictReader(fh))
