"""The steppers: the embedded Runge-Kutta pairs (error norm, dense output) and the exact
propagation of affine modes (matrix exponential, Taylor-summed steps), behind one interface.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...model.codegen import W_AFFINE, W_F
from .._codes import REGULAR
from ._base import _EXACT_TERMS, _hot, _hot_inline
from .fields import _rhs

# --------------------------------------------------------------------------------------
# Runge-Kutta step and dense output
# --------------------------------------------------------------------------------------

@_hot_inline
def _error_norm(K, E, method, s, y, ynew, h, i0, i1, rtol, atol):
    """Scaled RMS error of the components ``y[i0:i1]``.

    The kernel takes the state (``0:n``) and, with variational equations, ``Phi`` (``n:nY``)
    separately and accepts a step only when both meet the tolerances: on a sliding surface,
    for example, the state moves trivially while ``Phi`` contracts at the stabilising rate,
    and a step chosen for the state alone misses that."""
    m = i1 - i0
    if method == 0:
        acc = 0.0
        for i in range(i0, i1):
            e = 0.0
            for j in range(s + 1):
                e += E[0, j] * K[j, i]
            sc = atol + rtol * max(abs(y[i]), abs(ynew[i]))
            acc += (h * e / sc) ** 2
        return np.sqrt(acc / m)
    # DOP853 (Hairer et al. II.10): combined 5th and 3rd order estimates
    e5 = 0.0
    e3 = 0.0
    for i in range(i0, i1):
        a5 = 0.0
        a3 = 0.0
        for j in range(s + 1):
            a5 += E[0, j] * K[j, i]
            a3 += E[1, j] * K[j, i]
        sc = atol + rtol * max(abs(y[i]), abs(ynew[i]))
        e5 += (a5 / sc) ** 2
        e3 += (a3 / sc) ** 2
    if e5 == 0.0 and e3 == 0.0:
        return 0.0
    return abs(h) * e5 / np.sqrt((e5 + 0.01 * e3) * m)


@_hot
def _dense_coeffs(K, P, h, nY, s_ext, deg, out):
    """out[i, k] = h * sum_j K[j, i] P[j, k]  (power form, theta^(k+1))."""
    for i in range(nY):
        for k in range(deg):
            acc = 0.0
            for j in range(s_ext):
                pj = P[j, k]
                if pj != 0.0:
                    acc += K[j, i] * pj
            out[i, k] = h * acc


@_hot
def _take_samples(t, h, y, Q, nY, n, deg, s0, sdt, k, t_end, samp, n_samp, xs, max_samp):
    """Record the states at the sample times ``s0 + k sdt`` in ``(t, t + h]`` (and not past
    ``t_end``) from the step's dense output into ``samp`` (allocated for all of them), at most
    ``max_samp`` in all. Returns ``(n_samp, k)``."""
    ts = s0 + k * sdt
    # bounded: the kernel admits only finite s0, t, h, t_end and 0 < sdt < inf, so ts grows
    # with k; the cap bounds a tiny sdt (the kernel's set-up already refuses more samples
    # than it, so it is only a backstop and never drops a sample of a run it accepted)
    while ts <= t + h and ts <= t_end and n_samp < max_samp:
        _dense_eval(y, Q, (ts - t) / h if h > 0.0 else 1.0, nY, deg, xs)
        samp[n_samp, 0] = ts
        for i in range(n):
            samp[n_samp, 1 + i] = xs[i]
        n_samp += 1
        k += 1
        ts = s0 + k * sdt
    return n_samp, k


@_hot
def _exact_step(M, sc, wt, md, nz, n, t, y, h, z, v, Q, ynew):
    """One exact step of affine mode ``md``: ``z(t + h) = exp(h M) z(t)`` for the augmented
    state ``z = (x, 1, cos(w_j t), sin(w_j t), ...)`` (:mod:`pwsdyn.model.affine`); ``M``,
    ``sc``, ``wt`` are the per-mode tables of :func:`_affine_setup` (indexed here, not sliced
    by the caller: an array view costs two atomic reference-count updates per step).

    The exponential is summed as its Taylor series ``sum_k (h M)^k z / k!`` (dense products: a
    compressed-row product skipping the zeros of ``M`` measured slower at these sizes). The
    caller keeps ``||h D^-1 M D||_inf <= 1`` (``D`` the balancing scales of the mode, ``wt``
    their inverses, powers of two: see :func:`_affine_setup`), so in the balanced coordinates
    the terms fall faster than ``1/k!`` and the sum is exact to rounding after at most
    ``_EXACT_TERMS`` terms; it stops once a term is below 1e-18 of ``z`` (both measured in
    those coordinates). The terms are also the dense output: ``x(t + theta h) = x + sum_k
    Q[:, k-1] theta^k`` is the same series at ``theta h``, so events are located on the exact
    flow too. Columns of ``Q`` past the last term are zeroed."""
    _augment(M, sc, md, nz, n, t, y, z)
    zmax = 0.0
    for i in range(nz):
        zmax = max(zmax, abs(z[i]) * wt[md, i])
    for i in range(n):
        ynew[i] = y[i]
    ncol = Q.shape[1]
    if nz == 5 and n == 2:
        # two states and one forcing frequency (the impact oscillator, the ball on a table,
        # a forced friction oscillator): the same series with the same sums in the same
        # order, its terms in registers (``_exact_terms5``)
        k = _exact_terms5(M, wt, md, h, z, Q, ynew, zmax, ncol)
    else:
        k = _exact_terms(M, wt, md, nz, n, h, z, v, Q, ynew, zmax, ncol)
    for kk in range(k - 1, ncol):
        for i in range(n):
            Q[i, kk] = 0.0


@_hot_inline
def _exact_terms(M, wt, md, nz, n, h, z, v, Q, ynew, zmax, ncol):
    """The Taylor terms of ``_exact_step`` from ``z`` (any size): into ``Q`` and summed
    into ``ynew``. Returns one past the number of terms."""
    k = 1
    while k <= ncol:
        # v = (h / k) M z, then z = v (z holds the previous term)
        c = h / k
        big = 0.0
        for i in range(nz):
            acc = 0.0
            for m in range(nz):
                acc += M[md, i, m] * z[m]
            v[i] = c * acc
            big = max(big, abs(v[i]) * wt[md, i])
        for i in range(nz):
            z[i] = v[i]
        for i in range(n):
            Q[i, k - 1] = v[i]
            ynew[i] += v[i]
        k += 1
        if big <= 1e-18 * zmax or k > _EXACT_TERMS:
            break
    return k


@_hot_inline
def _exact_terms5(M, wt, md, h, z, Q, ynew, zmax, ncol):
    """``_exact_terms`` for ``nz = 5``, ``n = 2``, written out on scalars: the loop over
    arrays stores each term and reloads ``z`` and ``M`` after every store (the compiler cannot
    tell that the arrays do not alias), measured 2x the cost of this version, which forms
    each sum in the same order (``0.0 + M_i0 z_0 + ... + M_i4 z_4``, left to right) and so
    gives the same terms bit for bit. Leaves the last term in ``z``."""
    z0 = z[0]
    z1 = z[1]
    z2 = z[2]
    z3 = z[3]
    z4 = z[4]
    m00, m01, m02, m03, m04 = M[md, 0, 0], M[md, 0, 1], M[md, 0, 2], M[md, 0, 3], M[md, 0, 4]
    m10, m11, m12, m13, m14 = M[md, 1, 0], M[md, 1, 1], M[md, 1, 2], M[md, 1, 3], M[md, 1, 4]
    m20, m21, m22, m23, m24 = M[md, 2, 0], M[md, 2, 1], M[md, 2, 2], M[md, 2, 3], M[md, 2, 4]
    m30, m31, m32, m33, m34 = M[md, 3, 0], M[md, 3, 1], M[md, 3, 2], M[md, 3, 3], M[md, 3, 4]
    m40, m41, m42, m43, m44 = M[md, 4, 0], M[md, 4, 1], M[md, 4, 2], M[md, 4, 3], M[md, 4, 4]
    w0, w1, w2, w3, w4 = wt[md, 0], wt[md, 1], wt[md, 2], wt[md, 3], wt[md, 4]
    y0 = ynew[0]
    y1 = ynew[1]
    k = 1
    while k <= ncol:
        c = h / k
        # (the sums start at 0.0 as in _exact_terms: 0.0 + (-0.0) is +0.0)
        a0 = 0.0 + m00 * z0
        a0 = a0 + m01 * z1
        a0 = a0 + m02 * z2
        a0 = a0 + m03 * z3
        a0 = a0 + m04 * z4
        a1 = 0.0 + m10 * z0
        a1 = a1 + m11 * z1
        a1 = a1 + m12 * z2
        a1 = a1 + m13 * z3
        a1 = a1 + m14 * z4
        a2 = 0.0 + m20 * z0
        a2 = a2 + m21 * z1
        a2 = a2 + m22 * z2
        a2 = a2 + m23 * z3
        a2 = a2 + m24 * z4
        a3 = 0.0 + m30 * z0
        a3 = a3 + m31 * z1
        a3 = a3 + m32 * z2
        a3 = a3 + m33 * z3
        a3 = a3 + m34 * z4
        a4 = 0.0 + m40 * z0
        a4 = a4 + m41 * z1
        a4 = a4 + m42 * z2
        a4 = a4 + m43 * z3
        a4 = a4 + m44 * z4
        z0 = c * a0
        z1 = c * a1
        z2 = c * a2
        z3 = c * a3
        z4 = c * a4
        big = max(0.0, abs(z0) * w0)
        big = max(big, abs(z1) * w1)
        big = max(big, abs(z2) * w2)
        big = max(big, abs(z3) * w3)
        big = max(big, abs(z4) * w4)
        Q[0, k - 1] = z0
        Q[1, k - 1] = z1
        y0 += z0
        y1 += z1
        k += 1
        if big <= 1e-18 * zmax or k > _EXACT_TERMS:
            break
    ynew[0] = y0
    ynew[1] = y1
    z[0] = z0
    z[1] = z1
    z[2] = z2
    z[3] = z3
    z[4] = z4
    return k


@_hot
def _exact_propagator(M, wt, md, nz, h, Pm, T1, T2):
    """``Pm = exp(h M)`` summed as its Taylor series (``||h D^-1 M D||_inf <= 1``, as in
    :func:`_exact_step`; the stop test on the balanced entries ``T_ic d_c / d_i``): steps of
    the same length then cost one matrix-vector product."""
    for i in range(nz):
        for c in range(nz):
            T1[i, c] = 1.0 if i == c else 0.0
            Pm[md, i, c] = T1[i, c]
    for k in range(1, _EXACT_TERMS + 1):
        big = 0.0
        for i in range(nz):
            for c in range(nz):
                acc = 0.0
                for m in range(nz):
                    acc += T1[i, m] * M[md, m, c]
                T2[i, c] = acc * h / k
                big = max(big, abs(T2[i, c]) * wt[md, i] / wt[md, c])
        for i in range(nz):
            for c in range(nz):
                T1[i, c] = T2[i, c]
                Pm[md, i, c] += T2[i, c]
        if big <= 1e-18:
            break


@_hot_inline
def _exact_apply(M, sc, Pm, md, nz, n, t, y, z, ynew):
    """``x(t + h)`` from a cached propagator ``Pm[md] = exp(h M)`` (see :func:`_exact_step`)."""
    _augment(M, sc, md, nz, n, t, y, z)
    for i in range(n):
        acc = 0.0
        for m in range(nz):
            acc += Pm[md, i, m] * z[m]
        ynew[i] = acc


@_hot
def _balance(M, nz, w, B):
    """Balancing of ``M`` by a diagonal similarity of powers of two (Parlett & Reinsch 1969,
    as LAPACK's ``gebal`` without permutations): ``B = D^-1 M D`` with row and column norms
    (off the diagonal) made comparable. Writes ``w = 1 / diag(D)`` (exact: powers of two) and
    returns ``||B||_inf``. Rows or columns that are zero off the diagonal (the constant of the
    augmented state) keep their scale.

    The exponential's Taylor terms in the balanced coordinates are those of ``M`` scaled by
    powers of two, so only the step bound and the stop tests use ``D``: a stiff spring
    ``[[0, 1], [-k, -c]]`` has ``||M|| ~ k`` but ``||B|| ~ sqrt(k)``, its frequency."""
    for i in range(nz):
        w[i] = 1.0
        for c in range(nz):
            B[i, c] = M[i, c]
    for sweep in range(64):
        done = True
        for i in range(nz):
            c = 0.0
            r = 0.0
            for j in range(nz):
                if j != i:
                    c += abs(B[j, i])
                    r += abs(B[i, j])
            if c == 0.0 or r == 0.0 or not (np.isfinite(c) and np.isfinite(r)):
                continue
            g = r / 2.0
            f = 1.0
            tot = c + r
            while c < g and f < 2.0 ** 500:
                f *= 2.0
                c *= 4.0
            g = r * 2.0
            while c > g and f > 2.0 ** -500:
                f /= 2.0
                c /= 4.0
            if (c + r) / f < 0.95 * tot:
                done = False
                # column i times f, row i divided by f: D_ii *= f
                w[i] /= f
                for j in range(nz):
                    B[i, j] /= f
                    B[j, i] *= f
        if done:
            break
    nrm = 0.0
    for i in range(nz):
        row = 0.0
        for c in range(nz):
            row += abs(B[i, c])
        nrm = max(nrm, row)
    return nrm


@njit(cache=True)
def _affine_setup(ev, t0, x0, p, n, nm, enabled):
    """The exact propagation data of a run: ``(nz, ok, M, hmax, scale, weight)``.

    ``nz`` is the size of the augmented state (0: exact propagation off, or no mode is
    affine); per mode ``ok`` (affine with a finite matrix), its augmented matrix ``M`` with the
    constant and forcing columns divided by ``scale``, the largest exact step ``hmax`` with
    ``||hmax D^-1 M D||_inf <= 1`` and the inverse balancing scales ``weight = 1 / diag(D)``
    (:func:`_balance`; the identity where balancing does not lower the norm)."""
    nz = 0
    if enabled:
        abuf = np.zeros(1)
        ev(W_AFFINE, -1, t0, x0, p, abuf)
        nz = int(abuf[0])
    aff_ok = np.zeros(nm, dtype=np.int64)
    aff_M = np.zeros((nm, max(nz, 1), max(nz, 1)))
    aff_h = np.zeros(nm)
    aff_s = np.ones((nm, max(nz, 1)))
    aff_w = np.ones((nm, max(nz, 1)))
    if nz > 0:
        abuf = np.zeros(1 + nz * nz)
        B = np.zeros((nz, nz))
        wb = np.ones(nz)
        for m in range(nm):
            ev(W_AFFINE, m, t0, x0, p, abuf)
            if abuf[0] == 0.0:
                continue
            for i in range(nz):
                for c in range(nz):
                    aff_M[m, i, c] = abuf[1 + i * nz + c]
            # scale the constant and each (cos, sin) pair of z by the largest coefficient
            # multiplying it (z = (x, s_0, s_1 cos, s_1 sin, ...), those columns of M divided
            # by s): the step bound ||h M|| <= 1 then reflects the dynamics, not the units of
            # b or of the forcing amplitude (a ball in flight: b = -g)
            for c in range(n, nz):
                aff_s[m, c] = 1.0
            for c in range(n, nz):
                if c > n and (c - n) % 2 == 0:
                    continue  # the sin column shares the scale of its cos column
                big = 0.0
                for i in range(n):
                    big = max(big, abs(aff_M[m, i, c]))
                    if c > n:
                        big = max(big, abs(aff_M[m, i, c + 1]))
                if big > 1.0 and np.isfinite(big):
                    aff_s[m, c] = big
                    if c > n:
                        aff_s[m, c + 1] = big
            for c in range(n, nz):
                for i in range(n):
                    aff_M[m, i, c] /= aff_s[m, c]
            nrm = 0.0
            for i in range(nz):
                row = 0.0
                for c in range(nz):
                    row += abs(aff_M[m, i, c])
                nrm = max(nrm, row)
            if not np.isfinite(nrm):
                continue
            # balanced: the step bound of a stiff spring is its frequency, not its stiffness
            nb = _balance(aff_M[m], nz, wb, B)
            if nb < nrm:
                nrm = nb
                for i in range(nz):
                    aff_w[m, i] = wb[i]
            aff_ok[m] = 1
            aff_h[m] = 1.0 / nrm if nrm > 0.0 else np.inf
    return nz, aff_ok, aff_M, aff_h, aff_s, aff_w


@_hot_inline
def _augment(M, sc, md, nz, n, t, y, z):
    """The augmented state ``z = (x, s_0, s_1 cos(w_1 t), s_1 sin(w_1 t), ...)``, the
    frequencies read off the rotation blocks ``(0, -w_j; w_j, 0)`` of ``M`` and the scales
    ``s`` from ``sc`` (``M``'s columns are divided by them: see the kernel's set-up)."""
    for i in range(n):
        z[i] = y[i]
    z[n] = sc[md, n]
    for j in range((nz - n - 1) // 2):
        om = M[md, n + 2 + 2 * j, n + 1 + 2 * j]
        z[n + 1 + 2 * j] = sc[md, n + 1 + 2 * j] * np.cos(om * t)
        z[n + 2 + 2 * j] = sc[md, n + 2 + 2 * j] * np.sin(om * t)


@_hot
def _dense_eval(y0, Q, theta, nY, deg, out):
    """``out = y0 + sum_k Q[:, k] theta^(k+1)`` by Horner's rule.

    For two components (the impact oscillator, the ball on a table) the two Horner chains
    are summed side by side in scalars: each is a chain of dependent multiply-adds, and two
    run in parallel where one after the other they wait on each other (each component's sums
    are the same, in the same order, as in the general loop)."""
    if nY == 2:
        a0 = 0.0
        a1 = 0.0
        for k in range(deg - 1, -1, -1):
            a0 = (a0 + Q[0, k]) * theta
            a1 = (a1 + Q[1, k]) * theta
        out[0] = y0[0] + a0
        out[1] = y0[1] + a1
        return
    for i in range(nY):
        acc = 0.0
        for k in range(deg - 1, -1, -1):
            acc = (acc + Q[i, k]) * theta
        out[i] = y0[i] + acc


# --------------------------------------------------------------------------------------
# steppers: one step from (t, y) of length h, Runge-Kutta or exact, behind one interface
# --------------------------------------------------------------------------------------
# The Runge-Kutta step itself is written out in the stepping loop of run_kernel (its cost is
# that of a few multiply-adds and field calls, and any call costs a visible fraction of it);
# the exact stepper (inlined by LLVM: ``_hot_inline``), the dense output and the landing step
# are functions with the same arguments. Each is a plain call of a ``_hot`` function with at
# most 30 arguments: longer calls are made by Python as ``f(*args)``, for which numba builds a
# tuple of the arrays (a reference-count update per array: measured 1.7x the cost of an RK45
# step), and numba's inlining assigns each array argument to a new variable (the same
# updates). The work vectors
# of the vector fields travel as one tuple ``wk = (w1, w2, gx, hdx, jac, xt, ft)`` and the
# affine tables as ``aff = (M, sc, wt, z, v)``, both built once per run.

@_hot_inline
def _exact_stepper(mode, t, y, h, ynew, Q, aff, aff_P, aff_ph, aff_full, nz, T1, T2):
    """One exact step of affine mode ``mode`` (see "Exact propagation" in the module
    docstring), with the outputs of the Runge-Kutta step of run_kernel except its FSAL stage:
    the new state into ``ynew``. The field at the step's end is not evaluated: nothing on the
    exact path reads it (see ``K`` in run_kernel). The error is zero (the step is limited only by
    the convergence of the Taylor sum, the largest step and the events). A full step
    (``h == aff_full``) is one product with the propagator made once per mode and length; a
    shorter one sums the Taylor series of the vector, whose terms are the dense output in
    ``Q``. Returns ``(err, finite, dense_made, nfev)``."""
    aff_M, aff_s, aff_w, zv, zv1 = aff
    n = y.shape[0]   # (exact steps carry no variational equations)
    q_made = False
    if h == aff_full:
        if h != aff_ph[mode]:
            _exact_propagator(aff_M, aff_w, mode, nz, h, aff_P, T1, T2)
            aff_ph[mode] = h
        _exact_apply(aff_M, aff_s, aff_P, mode, nz, n, t, y, zv, ynew)
    else:
        _exact_step(aff_M, aff_s, aff_w, mode, nz, n, t, y, h, zv, zv1, Q, ynew)
        q_made = True
    # (an affine field with a finite matrix is finite wherever the state is)
    finite = True
    for i in range(n):
        if not np.isfinite(ynew[i]):
            finite = False
    return (0.0 if finite else np.inf), finite, q_made, 0


@_hot
def _step_stages(ev, p, exact, dkind, didx, mode, nm, t, y, h, h_full, K, A, C, s_fsal, Q, ytmp,
                 etab, stab, slide_c, wk):
    """Stages 1..s_fsal of the step of length ``h`` from ``(t, y)`` (``K[0] = f(t, y)`` is
    given), its end state into ``ytmp``: the step retaken to an event at ``t + h`` inside the
    accepted step of length ``h_full`` (the landing step: the event state comes from the
    integrator, not from an interpolant), or a step rebuilt from its node. On an exact step the
    dense output ``Q`` of the full step is the exact flow: the landing is its evaluation and
    the FSAL stage ``K[s_fsal]`` its field. Returns the number of function evaluations."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    nY = y.shape[0]
    n = w1.shape[0]
    if exact:
        _dense_eval(y, Q, h / h_full, nY, Q.shape[1], ytmp)
        ev(W_F, mode, t + h, ytmp, p, K[s_fsal])
        return 1
    nvar = 1 if nY > n else 0
    for st in range(1, s_fsal + 1):
        for i in range(nY):
            acc = 0.0
            for m in range(st):
                a = A[st, m]
                if a != 0.0:
                    acc += a * K[m, i]
            ytmp[i] = y[i] + h * acc
        if dkind == REGULAR and nvar == 0:
            ev(W_F, mode, t + C[st] * h, ytmp, p, K[st])
        else:
            _rhs(ev, p, dkind, didx, mode, nm, t + C[st] * h, ytmp, n, nvar, K[st], etab, stab,
                 slide_c, w1, w2, gx, hdx, jac, xt, ft)
    return s_fsal


@_hot_inline
def _step_dense(ev, p, exact, dkind, didx, mode, nm, t, y, h, h_full, K, A, C, s_fsal, P, Q, ytmp,
                etab, stab, slide_c, wk, nz, aff):
    """The dense output ``Q`` (power form) of the step of length ``h`` just taken from
    ``(t, y)`` with stages ``K``: for the Runge-Kutta pair the extra stages of the tableau
    (DOP853: 3) and the interpolant's coefficients; for an exact step the Taylor terms of the
    exact flow, made once for the full step (``h == h_full``) and rescaled to a landing step
    inside it (term k by ``(h / h_full)^k``). Made only where it is needed (stored steps,
    samples, event search). Returns the number of function evaluations."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    nY = y.shape[0]
    n = w1.shape[0]
    if exact:
        if h == h_full:
            aff_M, aff_s, aff_w, zv, zv1 = aff
            # (the end state of the series goes to the scratch ytmp: the step's is in ynew)
            _exact_step(aff_M, aff_s, aff_w, mode, nz, n, t, y, h, zv, zv1, Q, ytmp)
        else:
            ratio = h / h_full
            scale = 1.0
            for k in range(Q.shape[1]):
                scale *= ratio
                for i in range(n):
                    Q[i, k] *= scale
        return 0
    nvar = 1 if nY > n else 0
    s_ext = A.shape[0]
    for st in range(s_fsal + 1, s_ext):
        for i in range(nY):
            acc = 0.0
            for m in range(st):
                acc += A[st, m] * K[m, i]
            ytmp[i] = y[i] + h * acc
        _rhs(ev, p, dkind, didx, mode, nm, t + C[st] * h, ytmp, n, nvar, K[st], etab, stab,
             slide_c, w1, w2, gx, hdx, jac, xt, ft)
    _dense_coeffs(K, P, h, nY, s_ext, P.shape[1], Q)
    # columns beyond the method's degree are used by exact steps only
    for k in range(P.shape[1], Q.shape[1]):
        for i in range(nY):
            Q[i, k] = 0.0
    return s_ext - s_fsal - 1
