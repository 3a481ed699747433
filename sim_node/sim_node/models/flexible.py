"""Rigid hub + flexible solar wings + reaction wheels (paper 001's simulated spacecraft).

Tan Tian-le, "State transition control of satellite attitude" (seed paper 001, Sec. 6; digest
``papers/mpi-state-transition-control.md`` section 2.2). The paper gives only numbers: two
symmetric wings along +-X_b, the first five modes 0.16, 0.85, 0.96, 2.10, 2.55 Hz and the
rotational coupling ``C_a`` (3 x 5) of one wing, eq. (32). The equations are the standard
hybrid-coordinate form (ASSUMPTION: not written in the paper)::

    I_b w_dot + F eta_ddot + w x (I_b w + F eta_dot + A h_w) = -A tau_w + T_ext         (H1)
    eta_ddot + 2 zeta Lambda eta_dot + Lambda^2 eta + F^T w_dot = 0                      (H2)
    dh_w/dt = tau_w                                                                        (H3)
    dq_eci_body/dt = 1/2 q_eci_body (x) [w, 0]                                             (H4)

``w = omega_body_eci_body``; ``I_b`` the whole spacecraft's inertia with the rotors locked
(paper (30)); ``F`` (3, m) the coupling of all modes; ``Lambda = 2 pi diag(f)``; ``A`` (3, n) the
wheel spin axes; ``h_w`` (n,) the wheels' axial momenta; ``T_ext`` external torques (gravity
gradient (D1), disturbances), body axes. (H1)-(H2) are solved together every evaluation::

    [[I_b, F], [F^T, E_m]] [w_dot; eta_ddot]
        = [T_ext - A tau_w - w x (I_b w + F eta_dot + A h_w);
           -2 zeta Lambda eta_dot - Lambda^2 eta]

Without damping, external torque and wheel torque the energy
``1/2 [w; eta_dot]^T M [w; eta_dot] + 1/2 eta^T Lambda^2 eta`` and the inertial angular momentum
``R(q) (I_b w + F eta_dot + A h_w)`` are conserved. ``sim_node.models.dynamics`` integrates
them (compiled); ``tests/unit/reference_dynamics.py`` is an independent numpy implementation.

Assumptions
-----------
* ASSUMPTION: modal damping ``zeta = 0.005`` for every mode (the paper gives none; typical
  for solar arrays, digest section 6).
* ASSUMPTION: the second wing is the first turned half a turn about z_b,
  ``C_a2 = diag(-1, -1, 1) C_a`` (digest Option P, the default ``wings='two'``); ``'one'`` uses
  ``C_a`` alone (digest Option R, with which the digest reproduces the paper's rate accuracy).
* RK4 damps an undamped oscillator by ``1 - (w h)^6 / 144`` per step: take substeps of at
  most 0.01 s for the 2.55 Hz mode (< 1e-6 per step).
"""
from __future__ import annotations

import numpy as np

#: Paper 001's first five modal frequencies [Hz] (Sec. 6).
PAPER001_FREQUENCIES_HZ = (0.16, 0.85, 0.96, 2.10, 2.55)
#: Rotational coupling of one wing, eq. (32): rows body x, y, z; columns modes [kg^1/2 m].
PAPER001_COUPLING_ONE_WING = np.array([[0.48, 11.58, 0.28, -1.85, -0.14],
                                       [0.17, -24.28, 0.10, -0.67, -0.05],
                                       [25.34, 0.0, 7.51, 0.0, -3.02]])
#: True inertia, eq. (30) [kg m^2], body axes.
PAPER001_INERTIA = np.array([[1200.0, -800.0, -10.0], [-800.0, 2500.0, -25.0],
                             [-10.0, -25.0, 2800.0]])
#: ASSUMPTION: modal damping ratio of every mode (not in the paper).
DEFAULT_DAMPING = 0.005


def paper001_modes(wings: str = 'two') -> tuple[np.ndarray, np.ndarray]:
    """Coupling ``F`` (3, m) and frequencies (m,) [Hz] of paper 001's ``wings``: 'two' (m = 10,
    the -X wing ``diag(-1, -1, 1) C_a``, ASSUMPTION) or 'one' (``C_a``, m = 5)."""
    ca = PAPER001_COUPLING_ONE_WING
    f = np.array(PAPER001_FREQUENCIES_HZ)
    if wings == 'one':
        return ca.copy(), f
    if wings == 'two':
        return np.hstack([ca, np.diag([-1.0, -1.0, 1.0]) @ ca]), np.concatenate([f, f])
    raise ValueError(f"wings must be 'one' or 'two', got {wings!r}")
