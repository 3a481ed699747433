"""TRIAD: deterministic attitude from two vector observations (Black 1964; Shuster & Oh 1981).

Equations (numbered here, T1-T3; paper 004 section "TRIAD", digest section 5)
-----------------------------------------------------------------------------
For each set of two vectors (body: measured; ref: model), the orthonormal triad::

    t1 = v1 / |v1|,   t2 = (v1 x v2) / |v1 x v2|,   t3 = t1 x t2                         (T1)

With ``M_body = [t1 t2 t3]_body`` and ``M_ref = [t1 t2 t3]_ref`` (columns), the attitude matrix
mapping body components to reference components is::

    R_ref_body = M_ref M_body^T,     v_ref = R_ref_body v_body                            (T2)

``v1`` is the anchor: its body direction is reproduced exactly, ``v2`` only fixes the rotation
about ``v1``; so ``v1`` should be the more accurate vector (paper 004: the Earth-sensor vertical).
The solution degrades as ``v1`` and ``v2`` become parallel::

    sin(angle(v1, v2)) = |v1 x v2| / (|v1| |v2|)  ->  0                                    (T3)
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core import attitude

MIN_SIN_ANGLE = 1e-8
"""Default smallest ``sin`` of the angle between ``v1`` and ``v2`` accepted by :func:`triad`."""


def _triad_frame(v1: np.ndarray, v2: np.ndarray, which: str, min_sin: float) -> np.ndarray:
    n1, n2 = np.linalg.norm(v1), np.linalg.norm(v2)
    if n1 == 0.0 or n2 == 0.0:
        raise ValueError(f'TRIAD {which} vectors must be non-zero, got |v1| = {n1}, |v2| = {n2}')
    t1 = v1 / n1
    c = np.cross(t1, v2 / n2)
    s = np.linalg.norm(c)
    if s < min_sin:  # (T3)
        raise ValueError(f'TRIAD {which} vectors are (nearly) parallel: sin(angle) = {s:.3g} '
                         f'< {min_sin:.3g}')
    t2 = c / s
    return np.column_stack((t1, t2, np.cross(t1, t2)))  # (T1)


def triad(v1_body: ArrayLike, v2_body: ArrayLike, v1_ref: ArrayLike, v2_ref: ArrayLike,
          min_sin_angle: float = MIN_SIN_ANGLE) -> np.ndarray:
    """``q_ref_body`` (4,), ``w >= 0`` (``v_ref = R(q) v_body``), from two directions (3,) seen
    in body and reference axes (T1, T2), ``v1`` the anchor. ``ValueError`` on non-finite or
    zero vectors, or when ``sin(angle(v1, v2))`` is below ``min_sin_angle`` in either frame."""
    vec = attitude.as_vec3
    m_body = _triad_frame(vec(v1_body, 'v1_body'), vec(v2_body, 'v2_body'), 'body',
                          min_sin_angle)
    m_ref = _triad_frame(vec(v1_ref, 'v1_ref'), vec(v2_ref, 'v2_ref'), 'reference',
                         min_sin_angle)
    return attitude.from_matrix(m_ref @ m_body.T)  # (T2)
