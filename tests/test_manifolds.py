"""Saddle periodic points of maps and their one-dimensional manifolds (issue 25).

Checked against closed forms derived here (the border-collision normal form, whose manifolds are
polylines whose corners are the images, or explicit preimages, of one border crossing; the fixed
points and multipliers of the square-root map) and against invariance: the image of a point of
a manifold lies on the manifold, on every example, next to borders included.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import pwsdyn
from pwsdyn.manifolds import (Manifold, ManifoldError, PeriodicPoint, find_periodic_point,
                              manifold)


# ======================================================================================
# models and their maps written out by hand (the independent side of every check)
# ======================================================================================
#
# The border-collision normal form in the plane (Nusse & Yorke 1992; di Bernardo et al. 2008,
# ch. 3): x -> A_L x + mu e1 for x1 <= 0, A_R x + mu e1 (+ J e1) for x1 > 0, with
# A = [[tau, 1], [-delta, 0]] (trace tau, determinant delta). J = 0: continuous, J != 0: the
# map jumps at the border.

def bcnf(tL, dL, tR, dR, mu, J=0.0):
    model = {"name": "bcnf", "kind": "map", "states": ["x", "y"],
             "parameters": {"tL": tL, "dL": dL, "tR": tR, "dR": dR, "mu": mu, "J": J},
             "pieces": [{"name": "L", "condition": "x <= 0",
                         "map": {"x": "tL*x + y + mu", "y": "-dL*x"}},
                        {"name": "R", "map": {"x": "tR*x + y + mu + J", "y": "-dR*x"}}]}
    AL = np.array([[tL, 1.0], [-dL, 0.0]])
    AR = np.array([[tR, 1.0], [-dR, 0.0]])

    def F(v):
        v = np.asarray(v, dtype=float)
        return AL @ v + [mu, 0.0] if v[0] <= 0 else AR @ v + [mu + J, 0.0]

    def F_inverse(w):
        """The explicit inverse of the continuous invertible map (dL, dR > 0): the preimage
        through L if it lies in L, else through R."""
        z = np.linalg.solve(AL, np.asarray(w) - [mu, 0.0])
        if z[0] <= 0:
            return z
        return np.linalg.solve(AR, np.asarray(w) - [mu + J, 0.0])

    return model, F, F_inverse, AL, AR


# Saddle in L with multipliers (5 +- sqrt(17)) / 4 = 2.2808, 0.2192 at (-mu, mu/2) (x1 = mu /
# (1 - tL + dL) = -mu); R a stable focus (trace -0.5, determinant 0.3).
SADDLE = (2.5, 0.5, -0.5, 0.3, 1.0)

# A square-root map in the plane: the border-collision form whose impacting side (x > 0) has
# -gamma sqrt(x) in place of the linear term, the form of Nordmark's normal form of a grazing
# impact (Nordmark 1991); continuous at x = 0, with an unbounded derivative there.
NORDMARK = {"name": "nordmark2", "kind": "map", "states": ["x", "y"],
            "parameters": {"tau": 2.5, "delta": 0.5, "gamma": 1.0, "mu": 0.1},
            "pieces": [{"name": "no_impact", "condition": "x <= 0",
                        "map": {"x": "tau*x + y + mu", "y": "-delta*x"}},
                       {"name": "impact",
                        "map": {"x": "-gamma*sqrt(x) + y + mu", "y": "-delta*x"}}]}


def nordmark_F(v):
    x, y = v
    if x <= 0:
        return np.array([2.5 * x + y + 0.1, -0.5 * x])
    return np.array([-np.sqrt(x) + y + 0.1, -0.5 * x])


def polyline_distance(points, poly):
    """Distance of each point to a polyline (vertices ``poly``), written out independently of
    :meth:`Manifold.distance`."""
    A, B = poly[:-1], poly[1:]
    AB = B - A
    out = []
    for x in np.atleast_2d(points):
        t = np.clip(((x - A) * AB).sum(1) / (AB * AB).sum(1), 0.0, 1.0)
        out.append(np.linalg.norm(A + t[:, None] * AB - x, axis=1).min())
    return np.array(out)


def arclength_positions(branch):
    """Per point of a branch (a list of pieces), the arclength from the saddle along it (jumps
    not counted)."""
    out, total = [], 0.0
    for piece in branch:
        steps = np.linalg.norm(np.diff(piece, axis=0), axis=1)
        out.append(total + np.concatenate([[0.0], np.cumsum(steps)]))
        total = out[-1][-1]
    return out


def invariance_defect(m: Manifold, F, fraction: float = 1.0, near_nodes: bool = False):
    """The largest distance from the manifold of the image (unstable: ``F``; stable: ``F``
    too, which maps the stable manifold into itself) of its points, over the points within
    ``fraction`` of each branch's arclength (an unstable branch's last points map beyond what
    was grown); ``near_nodes``: only the points within three of a node (kinks, piece ends)."""
    worst, count = 0.0, 0
    for branch, nodes in zip(m.branches, m.nodes):
        pos = arclength_positions(branch)
        total = pos[-1][-1]
        for piece, s, nd in zip(branch, pos, nodes):
            keep = s <= fraction * total
            if near_nodes:
                idx = np.flatnonzero(nd)
                close = np.zeros(len(piece), bool)
                for i in idx:
                    close[max(0, i - 3):i + 4] = True
                keep &= close
            if not keep.any():
                continue
            images = np.array([F(x) for x in piece[keep]])
            worst = max(worst, float(m.distance(images).max()))
            count += int(keep.sum())
    return worst, count


# ======================================================================================
# periodic points
# ======================================================================================

def test_the_square_root_maps_fixed_point_and_multiplier_in_closed_form():
    # x = mu - sqrt(x) on the impacting side: sqrt(x) = (-1 + sqrt(1 + 4 mu)) / 2; the
    # multiplier is -1 / (2 sqrt(x))
    mu = 0.2
    pt = find_periodic_point("sqrt-map", [0.1], params={"mu": mu, "lam": 0.3})
    r = (-1 + np.sqrt(1 + 4 * mu)) / 2
    assert pt.converged and pt.period == 1 and pt.pieces == ("impact",)
    assert abs(pt.x[0] - r * r) < 1e-14
    assert abs(pt.multipliers[0] - (-1 / (2 * r))) < 1e-12
    assert not pt.stable and not pt.saddle     # 1-D: one multiplier, outside


def test_the_bcnf_fixed_point_and_a_period_two_cycle_in_closed_form():
    model, F, _, AL, AR = bcnf(*SADDLE)
    tL, dL, _, _, mu = SADDLE
    pt = find_periodic_point(model, [-0.5, 0.0])
    assert np.allclose(pt.x, [mu / (1 - tL + dL), -dL * mu / (1 - tL + dL)], atol=1e-14)
    lam = np.sort(np.roots([1, -tL, dL]).real)[::-1]
    assert np.allclose(pt.multipliers.real, lam, atol=1e-12) and pt.saddle
    # an LR cycle: x1 = A_R (A_L x1 + b) + b, x1 in L, A_L x1 + b in R (b = mu e1)
    model2, F2, _, AL2, AR2 = bcnf(-1.5, 0.3, 1.5, 0.5, -1.0)
    b = np.array([-1.0, 0.0])
    x1 = np.linalg.solve(np.eye(2) - AR2 @ AL2, AR2 @ b + b)
    assert x1[0] <= 0 and (AL2 @ x1 + b)[0] > 0
    cyc = find_periodic_point(model2, x1 + 0.05, period=2)
    assert cyc.pieces == ("L", "R")
    assert np.allclose(cyc.x, x1, atol=1e-13)
    assert np.allclose(np.sort_complex(cyc.multipliers),
                       np.sort_complex(np.linalg.eigvals(AR2 @ AL2)), atol=1e-12)
    assert np.allclose(cyc.cycle[1], F2(x1), atol=1e-13)
    # a period-2 saddle (multipliers -3 and -0.05): its manifolds are invariant under F^2
    for kind in ("unstable", "stable"):
        m = manifold(model2, cyc, kind, arclength=2.0, tol=1e-9)
        worst, n = invariance_defect(m, lambda v: F2(F2(v)), 0.1 if kind == "unstable"
                                     else 1.0)
        assert n > 20 and worst < 1e-10


def test_newton_failure_is_reported_with_the_last_iterate():
    # the square-root map's smooth side has no fixed point for lam = 1, mu != 0
    with pytest.raises(ManifoldError) as e:
        find_periodic_point("sqrt-map", [-1.0], params={"mu": -0.2, "lam": 1.0}, max_iter=5)
    assert isinstance(e.value.result, PeriodicPoint) and not e.value.result.converged


# ======================================================================================
# manifolds of the border-collision normal form, in closed form
# ======================================================================================

@pytest.fixture(scope="module")
def saddle_case():
    model, F, Finv, AL, AR = bcnf(*SADDLE)
    pt = find_periodic_point(model, [-1.0, 0.5])
    return model, F, Finv, AL, AR, pt


def reference_polyline(start, f, coord, levels):
    """``start`` (a local manifold: a segment in one piece) and its images under ``f``, each
    image of a polyline taken vertex by vertex after the points where it crosses ``x[coord] =
    0`` (where the piece of ``f`` changes) are added as vertices: ``f`` is affine on each
    side, so the image of such a polyline is exactly the polyline of the images."""
    poly = [np.asarray(v, dtype=float) for v in start]
    for _ in range(levels):
        split = [poly[0]]
        for a, b in zip(poly[:-1], poly[1:]):
            if a[coord] * b[coord] < 0:
                t = a[coord] / (a[coord] - b[coord])
                split.append(a + t * (b - a))
            split.append(b)
        poly = [f(v) for v in split]
    return np.array(poly)


def turn(poly):
    """``|a x b|`` of the chords before and after each interior vertex: zero where the polyline
    goes straight on."""
    a, b = poly[1:-1] - poly[:-2], poly[2:] - poly[1:-1]
    return np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])


def test_bcnf_unstable_manifold_matches_its_closed_form(saddle_case):
    # W^u leaves p = (-1, 1/2) along the unstable eigenvector E = (1, lam - tL) of A_L. Its
    # local part [p, c], c the first point of the line on the border x1 = 0, is in L, where F
    # is affine: W^u is the union of F^k([p, c]); F maps a segment within one piece onto a
    # segment, so each F^k([p, c]) is a polyline whose corners are images of its preimage's
    # border crossings (reference_polyline). The branch away from the border stays in L: the
    # ray p - s E.
    model, F, _, AL, _, pt = saddle_case
    m = manifold(model, pt, arclength=5.0, tol=1e-9)
    lam = m.multiplier
    E = np.array([1.0, lam - SADDLE[0]])
    E /= np.linalg.norm(E)
    p = pt.x
    c = p + (-p[0] / E[0]) * E
    ref = reference_polyline([p, c], F, 0, 40)
    toward = 0 if np.dot(m.eigenvector, E) > 0 else 1
    branch = np.concatenate(m.branches[toward])
    # every computed point on the reference polyline, every corner of the reference within
    # the computed branch on it: 1e-10, the bound; the map is affine on each piece,
    # so only rounding and the bisection of the border (to a few ulp) remain
    assert polyline_distance(branch, ref).max() < 1e-10
    corners = ref[1:-1][turn(ref) > 1e-9]
    assert len(corners) >= 8
    assert polyline_distance(corners, branch).max() < 1e-10
    # the corners are nodes (exact images), not interpolated points
    node_pts = branch[np.concatenate(m.nodes[toward])]
    assert max(min(np.linalg.norm(node_pts - v, axis=1)) for v in corners[:8]) < 1e-10
    # the ray
    other = np.concatenate(m.branches[1 - toward])
    rel = other - p
    assert np.abs(rel[:, 0] * E[1] - rel[:, 1] * E[0]).max() < 1e-12
    assert (rel @ E).max() < 1e-12
    assert m.arclengths[1 - toward] >= 5.0 and m.status[1 - toward] == "arclength"
    # the branch into R spirals onto the stable focus of R: it stops growing there
    focus = np.linalg.solve(np.eye(2) - np.array([[-0.5, 1], [-0.3, 0]]), [1.0, 0.0])
    assert m.status[toward] == "stalled"
    assert np.linalg.norm(branch[-1] - focus) < 1e-6


def test_bcnf_stable_manifold_matches_its_closed_form(saddle_case):
    # W^s leaves p along the stable eigenvector Es of A_L; its local part [p, c] up to the
    # border is in L. W^s is the union of F^-k([p, c]), with the explicit inverse (the map is
    # invertible: dL, dR > 0, and continuous). F^-1 is affine on each side of the image of the
    # border, F({x1 = 0}) = {x2 = 0}, so the preimage of a polyline is the polyline of the
    # preimages of its vertices and of its crossings of x2 = 0.
    model, F, Finv, AL, AR, pt = saddle_case
    m = manifold(model, pt, "stable", arclength=12.0, tol=1e-9)
    p = pt.x
    Es = np.array([1.0, m.multiplier - SADDLE[0]])
    Es /= np.linalg.norm(Es)
    direction = 1.0 if Es[0] > 0 else -1.0          # towards the border x1 = 0
    c = p + (-p[0] / Es[0]) * Es
    ref = reference_polyline([p, c], Finv, 1, 8)
    toward = 0 if np.dot(m.eigenvector, direction * Es) > 0 else 1
    branch = np.concatenate(m.branches[toward])
    ref_len = np.linalg.norm(np.diff(ref, axis=0), axis=1).sum()
    inside = np.concatenate(arclength_positions(m.branches[toward])) <= min(ref_len, 12.0)
    assert inside.sum() > 50
    assert polyline_distance(branch[inside], ref).max() < 1e-10
    corners = ref[1:-1][turn(ref) > 1e-9]
    within = corners[polyline_distance(corners, branch) < 1e-6]
    assert len(within) >= 2
    assert polyline_distance(within, branch).max() < 1e-10
    # the other branch stays in L: a straight segment of the line
    other = np.concatenate(m.branches[1 - toward]) - p
    assert np.abs(other[:, 0] * Es[1] - other[:, 1] * Es[0]).max() < 1e-12


@pytest.mark.parametrize("kind", ["unstable", "stable"])
def test_bcnf_manifolds_are_invariant(saddle_case, kind):
    model, F, _, _, _, pt = saddle_case
    m = manifold(model, pt, kind, arclength=4.0, tol=1e-9)
    worst, n = invariance_defect(m, F, 0.3 if kind == "unstable" else 1.0)
    assert n > 100 and worst < 1e-10           # piecewise-linear: straight segments are exact
    worst, n = invariance_defect(m, F, 0.3 if kind == "unstable" else 1.0, near_nodes=True)
    assert n > 5 and worst < 1e-10


@pytest.mark.parametrize("kind", ["unstable", "stable"])
def test_a_jump_of_the_map_cuts_the_manifold_into_pieces(kind):
    # J = 0.3: the map jumps by 0.3 in x1 across the border; no segment of the manifold may
    # join the two sides' images
    model, F, _, _, _ = bcnf(*SADDLE, J=0.3)
    pt = find_periodic_point(model, [-1.0, 0.5])
    m = manifold(model, pt, kind, arclength=4.0, tol=1e-9)
    assert len(m.pieces) >= 3
    worst, n = invariance_defect(m, F, 0.2 if kind == "unstable" else 1.0)
    assert n > 100 and worst < 1e-10
    worst, n = invariance_defect(m, F, 0.2 if kind == "unstable" else 1.0, near_nodes=True)
    assert n > 5 and worst < 1e-10
    # the piece ends are the one-sided images of the border: the gap between consecutive
    # pieces of a branch is the jump's size (0.3 in x1, times the map's stretching), never
    # bridged by a segment; and no segment is longer than max_step
    for branch in m.branches:
        for a, b in zip(branch[:-1], branch[1:]):
            assert np.linalg.norm(a[-1] - b[0]) > 1e-3
        for piece in branch:
            if len(piece) > 1:
                steps = np.linalg.norm(np.diff(piece, axis=0), axis=1)
                assert steps.max() <= m.options["max_step"] * (1 + 1e-12)


def test_a_flip_saddles_branches_map_onto_each_other():
    # multipliers -2.28 and -0.22: F swaps the branches (each is grown with F^2); F of a point
    # of one branch lies on the other
    model, F, _, _, _ = bcnf(-2.5, 0.5, 1.2, 0.3, -1.0)
    pt = find_periodic_point(model, [-0.25, 0.125])
    assert pt.multipliers[0].real < -1
    for kind in ("unstable", "stable"):
        m = manifold(model, pt, kind, arclength=3.0, tol=1e-9)
        worst, n = invariance_defect(m, F, 0.15 if kind == "unstable" else 1.0)
        assert n > 50 and worst < 1e-10


# ======================================================================================
# the square-root map in the plane
# ======================================================================================

@pytest.mark.parametrize("kind", ["unstable", "stable"])
def test_square_root_map_manifolds_are_invariant_next_to_the_border(kind):
    pt = find_periodic_point(NORDMARK, [-0.1, 0.05])
    tol = 1e-7
    m = manifold(NORDMARK, pt, kind, arclength=3.0, tol=tol)
    assert m.unresolved == 0
    # the map is continuous: a kink, not a cut, where the branch crosses x = 0
    assert len(m.pieces) == 2
    # tolerance: each chord deviates from the curve by about d alpha / 8 <= tol (the density
    # criterion); a point's image is compared with chords too, so a few tol
    frac = 0.3 if kind == "unstable" else 1.0
    worst, n = invariance_defect(m, nordmark_F, frac)
    assert n > 100 and worst < 5 * tol
    worst, n = invariance_defect(m, nordmark_F, frac, near_nodes=True)
    assert n > 5 and worst < 5 * tol
    if kind == "unstable":
        # the fold: the image of the segment across x = 0 leaves the kink with a square-root
        # (unbounded) stretching; the points next to the kink are refined far below max_step
        steps = [np.linalg.norm(np.diff(p, axis=0), axis=1) for br in m.branches for p in br]
        assert min(s.min() for s in steps) < 1e-3 * m.options["max_step"]


# ======================================================================================
# the result
# ======================================================================================

def test_the_manifold_round_trips_through_netcdf_and_plots(saddle_case, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import xarray as xr

    model, *_, pt = saddle_case
    m = pwsdyn.manifold(model, pt, arclength=2.0)
    assert isinstance(m, Manifold) and "Manifold('bcnf'" in repr(m)
    path = m.save(tmp_path / "w.nc")
    with xr.open_dataset(path) as ds:
        ds.load()
    assert ds.attrs["pwsdyn_type"] == "manifold" and ds.attrs["manifold_kind"] == "unstable"
    assert ds.attrs["model"] == "bcnf" and "pwsdyn_version" in ds.attrs
    assert "date_created" in ds.attrs
    assert json.loads(ds.attrs["branch_status"]) == list(m.status)
    X = ds["x"].values
    assert np.array_equal(X, np.concatenate(m.pieces))
    for k, piece in enumerate(m.pieces):
        assert np.array_equal(X[ds["piece"].values == k], piece)
    assert np.allclose(ds["multiplier_real"].values, m.multipliers.real)
    ax = m.plot()
    assert len(ax.lines) == len(m.pieces) + 1
    with pytest.raises(pwsdyn.OutputExistsError):
        m.save(path)


def test_arguments_are_checked(saddle_case):
    model, *_, pt = saddle_case
    with pytest.raises(pwsdyn.ArgumentError):
        manifold(model, pt, "sideways")
    with pytest.raises(pwsdyn.ArgumentError):
        manifold(model, pt, section="stroboscopic")
    with pytest.raises(pwsdyn.ArgumentError):
        manifold(model, pt, arclength=-1.0)
    # the stable focus of R has no one-dimensional manifold
    focus = np.linalg.solve(np.eye(2) - np.array([[-0.5, 1], [-0.3, 0]]), [1.0, 0.0])
    with pytest.raises(ManifoldError, match="exactly one unstable"):
        manifold(model, focus)
    # a state is refined to the periodic point first
    m = manifold(model, pt.x + 1e-3, arclength=0.5)
    assert np.allclose(m.saddle, pt.x, atol=1e-14)


# ======================================================================================
# a forced flow: the impact oscillator's stroboscopic map
# ======================================================================================

def test_the_impact_oscillators_saddle_orbit_has_invariant_manifolds_on_its_section():
    # omega = 2.8: the period-1 impacting orbit is past its period doubling, a flip saddle
    # (multipliers about -2.96 and -0.22). Its points' images are computed here with
    # pwsdyn.simulate over one forcing period (Trajectories, not the compiled layer the
    # manifold uses), at tighter tolerances than the manifold's runs.
    orbit = pwsdyn.find_periodic_orbit("impact-oscillator", [-0.29, -0.58],
                                       params={"omega": 2.8})
    assert orbit.multipliers[0].real < -1 < orbit.multipliers[1].real < 0
    tol = 1e-6

    def F(x, k=1):
        traj = pwsdyn.simulate("impact-oscillator", x, (orbit.t0, orbit.t0 + k * orbit.period),
                               params={"omega": 2.8}, rtol=1e-12, atol=1e-13)
        return traj.x[-1]

    m = pwsdyn.manifold("impact-oscillator", orbit, arclength=0.6, tol=tol)
    assert m.section == "stroboscopic" and m.status == ("arclength", "arclength")
    assert np.allclose(m.saddle, orbit.x0) and m.multiplier < -1
    # F swaps the branches; the first third of each maps into the part grown
    for branch in m.branches:
        piece = branch[0]
        pos = arclength_positions([piece])[0]
        sample = piece[pos <= 0.2][::7]
        images = np.array([F(x) for x in sample])
        # tolerance: the density criterion's tol (d alpha / 8 per chord) and the integration
        # error of the manifold's runs (rtol 1e-10), a few times over
        assert m.distance(images).max() < 5 * tol
    # the stable manifold: each point is a Newton preimage under F^2 of a point of the branch
    s = pwsdyn.manifold("impact-oscillator", orbit, "stable", arclength=0.3, tol=tol)
    for branch in s.branches:
        sample = branch[0][1::9]
        images = np.array([F(x, 2) for x in sample])
        assert s.distance(images).max() < 5 * tol


def _segments_cross(P0, P1, Q0, Q1):
    """Whether segment ``P0[i] P1[i]`` crosses segment ``Q0[j] Q1[j]`` (2-D), for all ``i, j``:
    an ``(m, k)`` boolean array (proper crossings, by the signs of the orientations)."""
    def orient(a, b, c):
        return ((b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
                - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0]))
    A, B = P0[:, None, :], P1[:, None, :]
    C, D = Q0[None, :, :], Q1[None, :, :]
    return ((np.sign(orient(A, B, C)) * np.sign(orient(A, B, D)) < 0)
            & (np.sign(orient(C, D, A)) * np.sign(orient(C, D, B)) < 0))


@pytest.mark.slow   # ~10-25 s: among the long checks, run by CI
def test_a_basin_boundary_of_the_impact_oscillator_is_the_saddles_stable_manifold():
    # omega = 3.05: a period-2 saddle orbit with three impacts per orbit and multipliers about
    # 4513 and 5.8e-5, between two period-2 attractors. Its strongly contracting stable
    # direction makes the preimage map expand 17000-fold and its third impact is close to
    # grazing: plain Newton fails already for the first preimage (the fundamental domain is
    # shortened) and again along the branch (Newton with a line search from the branch's
    # prediction, and shorter steps, take over there).
    P = {"omega": 3.05}
    orbit = pwsdyn.find_periodic_orbit("impact-oscillator", [-0.26717145, -0.51828814],
                                       params=P, periods=2)
    mult = np.sort(np.abs(orbit.multipliers))
    assert orbit.converged and 4e3 < mult[1] < 5e3 and 5e-5 < mult[0] < 7e-5
    p = np.asarray(orbit.x0)
    ws = pwsdyn.manifold("impact-oscillator", orbit, "stable", arclength=2e-3, tol=1e-7)
    assert ws.status == ("arclength", "arclength")
    # a 30 x 30 grid of half-width 3e-4 around the saddle, each start run 300 + 16 periods
    w, n = 3e-4, 30
    xs, vs = p[0] + np.linspace(-w, w, n), p[1] + np.linspace(-w, w, n)
    ds = pwsdyn.basins("impact-oscillator", {"x": xs, "v": vs}, params=P, transient=300,
                       samples=16, max_period=4, workers=1, progress=False)
    L = ds["label"].values                       # over (x, v)
    assert set(np.unique(L)) == {0, 1}
    assert list(ds["attractor_period"].values) == [2, 2]
    # every grid edge (neighbouring starts) the manifold crosses joins two basins, and every
    # edge joining two basins is crossed by it: the grid's boundary is the stable manifold
    X, Vv = np.meshgrid(xs, vs, indexing="ij")
    G = np.stack([X, Vv], axis=-1)
    edges = [(G[:-1, :].reshape(-1, 2), G[1:, :].reshape(-1, 2),
              L[:-1, :].ravel() != L[1:, :].ravel()),
             (G[:, :-1].reshape(-1, 2), G[:, 1:].reshape(-1, 2),
              L[:, :-1].ravel() != L[:, 1:].ravel())]
    crossings = 0
    for E0, E1, differ in edges:
        crossed = np.zeros(len(E0), dtype=bool)
        for piece in ws.pieces:
            crossed |= _segments_cross(E0, E1, piece[:-1], piece[1:]).any(axis=1)
        assert np.array_equal(crossed, differ)
        crossings += int(crossed.sum())
    assert crossings >= n                          # the manifold runs across the whole grid
    # points 1e-6 on either side of the manifold, along its normal, at ten points inside the
    # grid, run by simulation (not by basins) to the two attractors. Tolerance: the polyline
    # is within tol = 1e-7 of the manifold (plus the integration's 1e-10), ten times less
    # than the offset.
    T = 2 * np.pi / P["omega"]
    attractors = ds["attractor_points"].values   # (attractor, cycle point, state)

    def attractor_of(x):
        traj = pwsdyn.simulate("impact-oscillator", x, (0.0, 320 * T), params=P)
        last = np.asarray(traj(np.array([319 * T])))[0]
        dist = [min(np.abs(last - a[k]).max() for k in range(2)) for a in attractors]
        assert min(dist) < 1e-4
        return int(np.argmin(dist))

    branch = np.vstack(ws.pieces)
    inside = branch[np.all(np.abs(branch - p) < 0.9 * w, axis=1)]
    for i in np.linspace(1, len(inside) - 2, 10).astype(int):
        t = inside[i + 1] - inside[i - 1]
        nrm = np.array([-t[1], t[0]]) / np.linalg.norm(t)
        sides = {attractor_of(inside[i] + s * 1e-6 * nrm) for s in (1.0, -1.0)}
        assert sides == {0, 1}
