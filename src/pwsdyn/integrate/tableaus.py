"""Butcher tableaus of the embedded Runge-Kutta pairs, with dense output in power form.

The coefficients are the published ones of Dormand & Prince (1980) for RK5(4) and of Hairer,
Norsett & Wanner (Solving ODEs I, 2nd ed., section II.10) for DOP853; we take the numbers from
SciPy, which ships them, rather than retyping 200 constants.

Every method is reduced to the same data the compiled kernel reads:

* ``A`` (s_ext x s_ext), ``C`` (s_ext): stages, including the extra stages some methods need
  for dense output (DOP853: 3 extra);
* ``B`` (s): the propagating weights; the stage ``s`` is the FSAL stage ``f(t+h, y_new)``;
* ``E`` (2, s+1): error weights; RK45 uses row 0, DOP853 combines both rows (see the kernel);
* ``P`` (s_ext, deg): dense output in power form,
  ``y(t + theta h) = y + h * sum_k (K^T P)[:, k] theta^(k+1)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.polynomial import polynomial as npoly
from scipy.integrate._ivp import dop853_coefficients as _d853
from scipy.integrate._ivp.rk import RK45 as _RK45


@dataclass(frozen=True)
class Tableau:
    name: str
    code: int          # method code read by the kernel
    order: int
    n_stages: int      # s (FSAL stage index)
    A: np.ndarray
    C: np.ndarray
    B: np.ndarray
    E: np.ndarray
    P: np.ndarray      # (s_ext, deg) power-form dense output

    @property
    def n_ext(self) -> int:
        return self.A.shape[0]


def _rk45() -> Tableau:
    s = _RK45.n_stages  # 6
    A = np.zeros((s + 1, s + 1))
    A[:s, : s - 1] = _RK45.A
    A[s, :s] = _RK45.B  # FSAL stage
    C = np.append(_RK45.C, 1.0)
    E = np.zeros((2, s + 1))
    E[0] = _RK45.E
    return Tableau("RK45", 0, 5, s, A, C, np.array(_RK45.B, float), E,
                   np.array(_RK45.P, float))


def _dop853() -> Tableau:
    s = _d853.N_STAGES  # 12
    s_ext = _d853.N_STAGES_EXTENDED  # 16
    A = np.zeros((s_ext, s_ext))
    A[:, :] = _d853.A[:s_ext, :s_ext]
    A[s, :s] = _d853.B  # stage 12 is the FSAL stage f(t+h, y_new)
    C = np.array(_d853.C[:s_ext], float)
    E = np.zeros((2, s + 1))
    E[0] = _d853.E5
    E[1] = _d853.E3
    # Dense output of DOP853 (Hairer et al., II.10): with x = theta and
    #   F0 = y1 - y0, F1 = h f0 - F0, F2 = 2 F0 - h (f1 + f0), F3.. = h D K,
    #   y(x) = y0 + x (F0 + (1-x) (F1 + x (F2 + (1-x) (F3 + x (F4 + (1-x) (F5 + x F6)))))).
    # Each F_i is linear in the stages K (y1 - y0 = h B K), so the whole interpolant is
    # y0 + h * sum_j K_j q_j(x) with polynomials q_j; we expand them into power form once.
    deg = _d853.INTERPOLATOR_POWER  # 7
    # basis polynomial multiplying F_i in the nested form
    x = np.array([0.0, 1.0])
    omx = np.array([1.0, -1.0])
    basis = []
    poly = x.copy()
    for i in range(deg):
        basis.append(poly.copy())
        poly = npoly.polymul(poly, omx if i % 2 == 0 else x)
    # F_i in terms of stage weights w (F_i = h * sum_j w_ij K_j)
    W = np.zeros((deg, s_ext))
    Bfull = np.zeros(s_ext)
    Bfull[:s] = _d853.B
    f0 = np.zeros(s_ext); f0[0] = 1.0
    f1 = np.zeros(s_ext); f1[s] = 1.0
    W[0] = Bfull
    W[1] = f0 - Bfull
    W[2] = 2 * Bfull - (f1 + f0)
    W[3:] = _d853.D[:, :s_ext]
    P = np.zeros((s_ext, deg))
    for i in range(deg):
        coeffs = np.zeros(deg + 1)
        coeffs[: len(basis[i])] = basis[i]
        # coeffs[0] is 0 (every basis polynomial has the factor x)
        P += np.outer(W[i], coeffs[1:])
    return Tableau("DOP853", 1, 8, s, A, C, np.array(_d853.B, float), E, P)


RK45 = _rk45()
DOP853 = _dop853()
METHODS = {"RK45": RK45, "DOPRI5": RK45, "DOP853": DOP853}
