"""Butcher tableaus of the embedded Runge-Kutta pairs, with dense output in power form.

The coefficients are data of this module, entered from the publications:

* RK5(4), "DOPRI5": J. R. Dormand & P. J. Prince, "A family of embedded Runge-Kutta
  formulae", J. Comput. Appl. Math. 6 (1980) 19-26, table 2 (all coefficients rational), with
  the continuous extension of order 4 of L. F. Shampine, "Some practical Runge-Kutta
  formulas", Math. Comp. 46 (1986) 135-150 (the one-free-parameter interpolant used by
  dopri5 and ode45).
* DOP853: E. Hairer, S. P. Norsett & G. Wanner, *Solving Ordinary Differential Equations I*,
  2nd ed., Springer 1993, section II.10 (the method of Dormand & Prince of order 8 with error
  estimators of orders 5 and 3) and its dense output of order 7 with three extra stages, as
  published with the code ``dop853`` (30-digit decimals; the rational ones are entered as
  rationals).

Every method is reduced to the same data the compiled kernel reads:

* ``A`` (s_ext x s_ext), ``C`` (s_ext): stages, including the extra stages some methods need
  for dense output (DOP853: 3 extra);
* ``B`` (s): the propagating weights; the stage ``s`` is the FSAL stage ``f(t+h, y_new)``;
* ``E`` (2, s+1): error weights; RK45 uses row 0, DOP853 combines both rows (see the kernel);
* ``P`` (s_ext, deg): dense output in power form,
  ``y(t + theta h) = y + h * sum_k (K^T P)[:, k] theta^(k+1)``.

A new method is one more function here returning a :class:`Tableau` and its entry in
:data:`~pwsdyn.integrate.tableaus.METHODS`; the kernel reads only these arrays (its error norm
distinguishes the single estimate of ``code`` 0 from the combined 5th/3rd-order estimate of
``code`` 1).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction as F

import numpy as np
from numpy.polynomial import polynomial as npoly


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
    dense_order: int = 0   # order of the continuous extension (for the tests and docs)

    @property
    def n_ext(self) -> int:
        return self.A.shape[0]


def _num(v) -> float:
    """A coefficient as a double: rationals are rounded once (``float(Fraction)`` is correctly
    rounded), decimals are parsed from their published digits."""
    return float(v)


def _rows(rows: dict, size: int) -> np.ndarray:
    """A strictly lower-triangular matrix from ``{i: {j: value}}`` (sparse rows as published)."""
    out = np.zeros((size, size))
    for i, row in rows.items():
        for j, v in row.items():
            out[i, j] = _num(v)
    return out


# --------------------------------------------------------------------------------------
# Dormand & Prince RK5(4)7M, with Shampine's dense output
# --------------------------------------------------------------------------------------

_DP5_C = [F(0), F(1, 5), F(3, 10), F(4, 5), F(8, 9), F(1), F(1)]
_DP5_A = {
    1: {0: F(1, 5)},
    2: {0: F(3, 40), 1: F(9, 40)},
    3: {0: F(44, 45), 1: F(-56, 15), 2: F(32, 9)},
    4: {0: F(19372, 6561), 1: F(-25360, 2187), 2: F(64448, 6561), 3: F(-212, 729)},
    5: {0: F(9017, 3168), 1: F(-355, 33), 2: F(46732, 5247), 3: F(49, 176),
        4: F(-5103, 18656)},
}
# 5th-order weights (propagated: local extrapolation); the 7th stage is f(t+h, y_new) (FSAL)
_DP5_B = [F(35, 384), F(0), F(500, 1113), F(125, 192), F(-2187, 6784), F(11, 84)]
# 4th-order embedded weights of the same stages plus the FSAL stage
_DP5_BHAT = [F(5179, 57600), F(0), F(7571, 16695), F(393, 640), F(-92097, 339200),
             F(187, 2100), F(1, 40)]
# Shampine's interpolant (order 4) in power form: y(t + theta h) = y + h sum_j K_j
# sum_k P[j, k] theta^(k+1), one row per stage (the FSAL stage included)
_DP5_P = [
    [F(1), F(-8048581381, 2820520608), F(8663915743, 2820520608),
     F(-12715105075, 11282082432)],
    [F(0), F(0), F(0), F(0)],
    [F(0), F(131558114200, 32700410799), F(-68118460800, 10900136933),
     F(87487479700, 32700410799)],
    [F(0), F(-1754552775, 470086768), F(14199869525, 1410260304),
     F(-10690763975, 1880347072)],
    [F(0), F(127303824393, 49829197408), F(-318862633887, 49829197408),
     F(701980252875, 199316789632)],
    [F(0), F(-282668133, 205662961), F(2019193451, 616988883), F(-1453857185, 822651844)],
    [F(0), F(40617522, 29380423), F(-110615467, 29380423), F(69997945, 29380423)],
]


def _rk45() -> Tableau:
    s = 6
    A = _rows(_DP5_A, s + 1)
    B = np.array([_num(b) for b in _DP5_B])
    A[s, :s] = B  # FSAL stage
    C = np.array([_num(c) for c in _DP5_C])
    E = np.zeros((2, s + 1))
    # error estimate y4 - y5 (the kernel takes its norm; only the magnitude matters)
    E[0] = [_num(bhat - b) for b, bhat in zip(_DP5_B + [F(0)], _DP5_BHAT)]
    P = np.array([[_num(v) for v in row] for row in _DP5_P])
    return Tableau("RK45", 0, 5, s, A, C, B, E, P, dense_order=4)


# --------------------------------------------------------------------------------------
# DOP853 (Hairer, Norsett & Wanner, II.10), dense output of order 7
# --------------------------------------------------------------------------------------

# Nodes; c2..c5 involve sqrt(6) (published decimals), the others are rational.
_D8_C = ["0", "0.526001519587677318785587544488e-01", "0.789002279381515978178381316732e-01",
         "0.118350341907227396726757197510", "0.281649658092772603273242802490",
         F(1, 3), F(1, 4), F(4, 13), F(127, 195), F(3, 5), F(6, 7), F(1), F(1),
         F(1, 10), F(1, 5), F(7, 9)]
# Stage matrix by rows, including the FSAL row 12 (= the weights b) and the extra stages
# 13-15 of the dense output.
_D8_A = {
    1: {0: "5.26001519587677318785587544488e-2"},
    2: {0: "1.97250569845378994544595329183e-2", 1: "5.91751709536136983633785987549e-2"},
    3: {0: "2.95875854768068491816892993775e-2", 2: "8.87627564304205475450678981324e-2"},
    4: {0: "2.41365134159266685502369798665e-1", 2: "-8.84549479328286085344864962717e-1",
        3: "9.24834003261792003115737966543e-1"},
    5: {0: F(1, 27), 3: "1.70828608729473871279604482173e-1",
        4: "1.25467687566822425016691814123e-1"},
    6: {0: F(19, 512), 3: "1.70252211019544039314978060272e-1",
        4: "6.02165389804559606850219397283e-2", 5: F(-9, 512)},
    7: {0: "3.70920001185047927108779319836e-2", 3: "1.70383925712239993810214054705e-1",
        4: "1.07262030446373284651809199168e-1", 5: "-1.53194377486244017527936158236e-2",
        6: "8.27378916381402288758473766002e-3"},
    8: {0: "6.24110958716075717114429577812e-1", 3: "-3.36089262944694129406857109825",
        4: "-8.68219346841726006818189891453e-1", 5: "2.75920996994467083049415600797e1",
        6: "2.01540675504778934086186788979e1", 7: "-4.34898841810699588477366255144e1"},
    9: {0: "4.77662536438264365890433908527e-1", 3: "-2.48811461997166764192642586468",
        4: "-5.90290826836842996371446475743e-1", 5: "2.12300514481811942347288949897e1",
        6: "1.52792336328824235832596922938e1", 7: "-3.32882109689848629194453265587e1",
        8: "-2.03312017085086261358222928593e-2"},
    10: {0: "-9.3714243008598732571704021658e-1", 3: "5.18637242884406370830023853209",
         4: "1.09143734899672957818500254654", 5: "-8.14978701074692612513997267357",
         6: "-1.85200656599969598641566180701e1", 7: "2.27394870993505042818970056734e1",
         8: "2.49360555267965238987089396762", 9: "-3.0467644718982195003823669022"},
    11: {0: "2.27331014751653820792359768449", 3: "-1.05344954667372501984066689879e1",
         4: "-2.00087205822486249909675718444", 5: "-1.79589318631187989172765950534e1",
         6: "2.79488845294199600508499808837e1", 7: "-2.85899827713502369474065508674",
         8: "-8.87285693353062954433549289258", 9: "1.23605671757943030647266201528e1",
         10: "6.43392746015763530355970484046e-1"},
    12: {0: "5.42937341165687622380535766363e-2", 5: "4.45031289275240888144113950566",
         6: "1.89151789931450038304281599044", 7: "-5.8012039600105847814672114227",
         8: "3.1116436695781989440891606237e-1", 9: "-1.52160949662516078556178806805e-1",
         10: "2.01365400804030348374776537501e-1", 11: "4.47106157277725905176885569043e-2"},
    13: {0: "5.61675022830479523392909219681e-2", 6: "2.53500210216624811088794765333e-1",
         7: "-2.46239037470802489917441475441e-1", 8: "-1.24191423263816360469010140626e-1",
         9: "1.5329179827876569731206322685e-1", 10: "8.20105229563468988491666602057e-3",
         11: "7.56789766054569976138603589584e-3", 12: F(-4149, 500000)},
    14: {0: "3.18346481635021405060768473261e-2", 5: "2.83009096723667755288322961402e-2",
         6: "5.35419883074385676223797384372e-2", 7: "-5.49237485713909884646569340306e-2",
         10: "-1.08347328697249322858509316994e-4", 11: "3.82571090835658412954920192323e-4",
         12: "-3.40465008687404560802977114492e-4", 13: "1.41312443674632500278074618366e-1"},
    15: {0: "-4.28896301583791923408573538692e-1", 5: "-4.69762141536116384314449447206",
         6: "7.68342119606259904184240953878", 7: "4.06898981839711007970213554331",
         8: "3.56727187455281109270669543021e-1", 12: "-1.39902416515901462129418009734e-3",
         13: "2.9475147891527723389556272149", 14: "-9.15095847217987001081870187138"},
}
# 3rd-order estimator: b - bhh, with bhh = (31/127 at stage 0, bhh2 at 8, 3/136 at 11)
_D8_BHH = {0: F(31, 127), 8: "0.733846688281611857341361741547", 11: F(3, 136)}
# 5th-order estimator weights (difference of the 8th-order and a 5th-order solution)
_D8_E5 = {0: "0.1312004499419488073250102996e-1", 5: "-0.1225156446376204440720569753e+1",
          6: "-0.4957589496572501915214079952", 7: "0.1664377182454986536961530415e+1",
          8: "-0.3503288487499736816886487290", 9: "0.3341791187130174790297318841",
          10: "0.8192320648511571246570742613e-1", 11: "-0.2235530786388629525884427845e-1"}
# Dense output: the stage weights of the terms F3..F6 of the nested interpolant (below)
_D8_D = [
    {0: "-0.84289382761090128651353491142e+1", 5: "0.56671495351937776962531783590",
     6: "-0.30689499459498916912797304727e+1", 7: "0.23846676565120698287728149680e+1",
     8: "0.21170345824450282767155149946e+1", 9: "-0.87139158377797299206789907490",
     10: "0.22404374302607882758541771650e+1", 11: "0.63157877876946881815570249290",
     12: "-0.88990336451333310820698117400e-1", 13: "0.18148505520854727256656404962e+2",
     14: "-0.91946323924783554000451984436e+1", 15: "-0.44360363875948939664310572000e+1"},
    {0: "0.10427508642579134603413151009e+2", 5: "0.24228349177525818288430175319e+3",
     6: "0.16520045171727028198505394887e+3", 7: "-0.37454675472269020279518312152e+3",
     8: "-0.22113666853125306036270938578e+2", 9: "0.77334326684722638389603898808e+1",
     10: "-0.30674084731089398182061213626e+2", 11: "-0.93321305264302278729567221706e+1",
     12: "0.15697238121770843886131091075e+2", 13: "-0.31139403219565177677282850411e+2",
     14: "-0.93529243588444783865713862664e+1", 15: "0.35816841486394083752465898540e+2"},
    {0: "0.19985053242002433820987653617e+2", 5: "-0.38703730874935176555105901742e+3",
     6: "-0.18917813819516756882830838328e+3", 7: "0.52780815920542364900561016686e+3",
     8: "-0.11573902539959630126141871134e+2", 9: "0.68812326946963000169666922661e+1",
     10: "-0.10006050966910838403183860980e+1", 11: "0.77771377980534432092869265740",
     12: "-0.27782057523535084065932004339e+1", 13: "-0.60196695231264120758267380846e+2",
     14: "0.84320405506677161018159903784e+2", 15: "0.11992291136182789328035130030e+2"},
    {0: "-0.25693933462703749003312586129e+2", 5: "-0.15418974869023643374053993627e+3",
     6: "-0.23152937917604549567536039109e+3", 7: "0.35763911791061412378285349910e+3",
     8: "0.93405324183624310003907691704e+2", 9: "-0.37458323136451633156875139351e+2",
     10: "0.10409964950896230045147246184e+3", 11: "0.29840293426660503123344363579e+2",
     12: "-0.43533456590011143754432175058e+2", 13: "0.96324553959188282948394950600e+2",
     14: "-0.39177261675615439165231486172e+2", 15: "-0.14972683625798562581422125276e+3"},
]


def _dop853() -> Tableau:
    s, s_ext, deg = 12, 16, 7
    A = _rows(_D8_A, s_ext)
    C = np.array([_num(c) for c in _D8_C])
    B = A[s, :s].copy()  # row 12 is the FSAL stage f(t+h, y_new): its entries are b
    E = np.zeros((2, s + 1))
    for j, v in _D8_E5.items():
        E[0, j] = _num(v)
    E[1, :s] = B
    for j, v in _D8_BHH.items():
        E[1, j] -= _num(v)
    # Dense output (Hairer et al., II.10): with x = theta and
    #   F0 = y1 - y0, F1 = h f0 - F0, F2 = 2 F0 - h (f1 + f0), F3.. = h D K,
    #   y(x) = y0 + x (F0 + (1-x) (F1 + x (F2 + (1-x) (F3 + x (F4 + (1-x) (F5 + x F6)))))).
    # Each F_i is linear in the stages K (y1 - y0 = h B K), so the whole interpolant is
    # y0 + h * sum_j K_j q_j(x) with polynomials q_j, expanded into power form once.
    # The polynomial multiplying F_i in the nested form: x, x(1-x), x^2(1-x), x^2(1-x)^2, ...
    x = np.array([0.0, 1.0])
    omx = np.array([1.0, -1.0])
    basis = []
    poly = x.copy()
    for i in range(deg):
        basis.append(poly.copy())
        poly = npoly.polymul(poly, omx if i % 2 == 0 else x)
    # F_i = h * sum_j W[i, j] K_j
    W = np.zeros((deg, s_ext))
    Bfull = np.zeros(s_ext)
    Bfull[:s] = B
    f0 = np.zeros(s_ext)
    f0[0] = 1.0
    f1 = np.zeros(s_ext)
    f1[s] = 1.0
    W[0] = Bfull
    W[1] = f0 - Bfull
    W[2] = 2 * Bfull - (f1 + f0)
    for i, row in enumerate(_D8_D):
        for j, v in row.items():
            W[3 + i, j] = _num(v)
    P = np.zeros((s_ext, deg))
    for i in range(deg):
        coeffs = np.zeros(deg + 1)
        coeffs[: len(basis[i])] = basis[i]
        # coeffs[0] is 0 (every basis polynomial has the factor x)
        P += np.outer(W[i], coeffs[1:])
    return Tableau("DOP853", 1, 8, s, A, C, B, E, P, dense_order=7)


RK45 = _rk45()
DOP853 = _dop853()
#: The tableaus by name, for the ``method`` option of :func:`~pwsdyn.simulate`.
METHODS = {"RK45": RK45, "DOPRI5": RK45, "DOP853": DOP853}
