"""How a branch ends, as a :class:`pwsdyn.Status` member, and a branch's points as columns.

* every way the engine ends a branch sets ``stop_status`` (a member of
  :data:`pwsdyn.errors.BRANCH_ENDS`) with the ``stop_reason`` text it has always written; each
  end that a normal form reaches in a few points is reached here (one-dimensional equilibria,
  ``x' = p - x^2`` and friends, whose branches are known in closed form), the others are
  checked through the words of their text (:meth:`Status.of_branch_stop`, what a file written
  before the status was kept decodes with);
* the status travels through a branch file, and a file without it is read by its words;
* a :class:`~pwsdyn.continuation.Branch` stores columns: its points are views whose
  attributes equal those of the engine's :class:`~pwsdyn.continuation.Point` objects exactly
  (bit for bit), its arrays equal those rebuilt point by point, and a branch built by
  appending one point at a time equals one built at once.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

import pwsdyn
from pwsdyn import Status
from pwsdyn.continuation import (Branch, Continuation, ContinuationError, ContinuationSettings,
                                 EquilibriumProblem, Point, load_branch)
from pwsdyn.continuation.branch import BranchPoint
from pwsdyn.errors import BRANCH_ENDS
from pwsdyn.io import save_dataset

POINT_ATTRS = ("lam", "ds", "iterations", "arclength", "special", "signature_index")


def _flow(name, fields, params):
    return {"name": name, "states": list(fields), "parameters": params,
            "modes": {"m": dict(fields)}}


FOLD = _flow("fold", {"x": "p - x**2"}, {"p": 1.0})


def _fold_branch(**kw):
    kw.setdefault("span", (-1, 2))
    kw.setdefault("ds", -0.05)
    return pwsdyn.continue_equilibrium(FOLD, [1.0], "p", **kw)


# ======================================================================================
# stop reasons as Status members
# ======================================================================================

def test_branch_ends_are_distinct_members_with_messages():
    assert len(set(BRANCH_ENDS)) == len(BRANCH_ENDS) == 9
    assert all(int(s) <= -20 for s in BRANCH_ENDS)
    for s in BRANCH_ENDS:
        assert s.message.strip() and Status.from_meaning(s.meaning) is s
    # an end the settings asked for is not a failure; a point the corrector cannot pass is
    assert not Status.MAX_POINTS.failed and not Status.SPAN_END.failed
    assert Status.STEP_BELOW_DS_MIN.failed and Status.START_FAILED.failed


def test_max_points():
    br = _fold_branch(max_points=5)
    assert len(br) == 5
    assert br.stop_status is Status.MAX_POINTS and "max_points = 5" in br.stop_reason


def test_max_arclength():
    br = _fold_branch(max_arclength=0.2, ds_max=0.05)
    assert br.stop_status is Status.MAX_ARCLENGTH and "max_arclength" in br.stop_reason
    assert br.points[-1].arclength >= 0.2


def test_end_of_span():
    # x' = p - x: x = p, up to p = 1 exactly
    br = pwsdyn.continue_equilibrium(_flow("line", {"x": "p - x"}, {"p": 0.0}), [0.0], "p",
                                     span=(-1, 1), ds=0.1)
    assert br.stop_status is Status.SPAN_END and "end of span" in br.stop_reason
    assert br.values[-1] == pytest.approx(1.0) and br.points[-1].special == "EP"


def test_step_below_ds_min():
    # x' = sqrt(p) - x has no equilibria for p < 0 (NaN field): the corrector cannot pass p = 0
    br = pwsdyn.continue_equilibrium(_flow("sqrtp", {"x": "sqrt(p) - x"}, {"p": 1.0}), [1.0],
                                     "p", span=(-1, 2), ds=-0.05)
    assert br.stop_status is Status.STEP_BELOW_DS_MIN and "ds_min" in br.stop_reason


def test_stop_at_a_special_point():
    prob = EquilibriumProblem(FOLD, "p")
    cont = Continuation(prob, [1.0], 1.0, ContinuationSettings(ds=-0.05, span=(-1, 2),
                                                              stop_at=("LP",)))
    cont.run()
    assert cont.stop_status is Status.STOP_AT_SPECIAL_POINT
    assert cont.stop_reason.startswith("LP located at p = ")
    assert cont.points[-1].special == "LP" and cont.stop_point is cont.points[-1]


def test_start_failure_carries_its_status():
    with pytest.raises(ContinuationError, match="not a solution") as info:
        pwsdyn.continue_equilibrium(_flow("noeq", {"x": "1 + x**2"}, {"p": 0.0}), [0.0], "p")
    assert info.value.status is Status.START_FAILED


@pytest.mark.parametrize("text, member", [
    ("max_points = 200 reached", Status.MAX_POINTS),
    ("max_arclength = 3.0 reached", Status.MAX_ARCLENGTH),
    ("the step fell below ds_min = 1e-07 at p = 0.001 (corrector: singular): a singular or "
     "nonsmooth point of the branch", Status.STEP_BELOW_DS_MIN),
    ("the parameter reached the end of span (2, 4.6)", Status.SPAN_END),
    ("the branch left the finite numbers", Status.BRANCH_NONFINITE),
    ("GR located at sigma = 0.27", Status.STOP_AT_SPECIAL_POINT),
    ("omega left span2 (2, 3)", Status.SPAN2_LEFT),
    ("GR located at sigma = 0.27; the orbit past the graze could not be followed: x",
     Status.SWITCH_FAILED),
    ("GR located at sigma = 0.27; the span ends at the graze", Status.SWITCH_FAILED),
    ("", None), ("no points", None)])
def test_a_stop_text_names_its_member(text, member):
    assert Status.of_branch_stop(text) is member


def test_the_status_travels_through_a_file(tmp_path):
    br = _fold_branch(max_points=7)
    back = load_branch(br.save(tmp_path / "b.nc"))
    assert back.stop_status is Status.MAX_POINTS and back.stop_reason == br.stop_reason
    assert br.to_dataset().attrs["stop_status"] == "max_points"
    # a file written before the status was kept: read from the words of the text
    ds = br.to_dataset()
    # a file of then had no content hash either (it covers the status)
    del ds.attrs["stop_status"], ds.attrs["content_sha256"]
    old = tmp_path / "old.nc"
    save_dataset(ds, old)       # the library's writer (its engine), as a file of then was
    with pytest.warns(UserWarning, match="no content hash"):
        assert load_branch(old).stop_status is Status.MAX_POINTS


# ======================================================================================
# the branch as columns
# ======================================================================================

@pytest.fixture(scope="module")
def engine_points():
    """The engine's Point objects of a fold branch, through the fold (LP) to the span's end."""
    prob = EquilibriumProblem(FOLD, "p")
    cont = Continuation(prob, [1.0], 1.0, ContinuationSettings(ds=-0.05, span=(-1, 2)))
    return prob, cont.run()


def _same(a, b):
    for name in POINT_ATTRS:
        assert getattr(a, name) == getattr(b, name), name
        assert type(getattr(a, name)) is type(getattr(b, name)), name
    for name in ("u", "tangent", "X"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.data is b.data and a.tests is b.tests


def test_views_equal_the_engine_points(engine_points):
    prob, pts = engine_points
    br = Branch(prob, pts)
    assert len(br) == len(pts) and len(br.points) == len(pts)
    for p, v in zip(pts, br.points):
        assert isinstance(v, BranchPoint)
        _same(p, v)
    _same(pts[-1], br.points[-1])
    assert [v.lam for v in br.points[2:5]] == [p.lam for p in pts[2:5]]
    # the columns equal the arrays rebuilt point by point
    assert np.array_equal(br.values, [p.lam for p in pts])
    assert np.array_equal(br.stable, [bool(p.data["stable"]) for p in pts])
    assert np.array_equal(br.admissible, [bool(p.data["admissible"]) for p in pts])
    assert [(s.kind, s.index, s.value) for s in br.special_points] == \
        [(p.special, i, p.lam) for i, p in enumerate(pts) if p.special]
    assert np.array(br.points, dtype=object).shape == (len(pts),)
    with pytest.raises(IndexError):
        br.points[len(pts)]


def test_appending_equals_building_at_once(engine_points):
    prob, pts = engine_points
    whole = Branch(prob, pts)
    grown = Branch(prob, [])
    for p in pts:
        grown.append(p)
    assert len(grown) == len(whole)
    for a, b in zip(grown.points, whole.points):
        _same(a, b)
    assert whole.to_dataset().equals(grown.to_dataset())


def test_views_write_through_and_copies_detach(engine_points):
    prob, pts = engine_points
    br = Branch(prob, pts)
    p = copy.copy(br.points[3])
    assert isinstance(p, Point)
    _same(p, br.points[3])
    p.data = {**p.data, "stable": not p.data["stable"]}
    assert br.stable[3] == bool(pts[3].data["stable"])       # the copy is detached
    br.points[3] = p
    assert br.stable[3] == p.data["stable"] and br.points[3].data is p.data
    br.points[4].special = "XX"
    assert br.points[4].special == "XX" and pts[4].special != "XX"
    # a new list of points makes new columns: a shallow copy of the branch keeps its own
    other = copy.copy(br)
    other.points = list(br.points)
    other.points[0] = pts[1]
    assert br.points[0].lam == pts[0].lam and other.points[0].lam == pts[1].lam


def test_file_round_trip_of_the_columns(engine_points, tmp_path):
    prob, pts = engine_points
    br = Branch(prob, pts, model=prob.model, stop_reason="max_points = 9 reached")
    back = load_branch(br.save(tmp_path / "cols.nc"))
    assert len(back) == len(br)
    for a, b in zip(br.points, back.points):
        for name in POINT_ATTRS:
            assert getattr(a, name) == getattr(b, name), name
        assert np.array_equal(a.u, b.u) and np.array_equal(a.tangent, b.tangent)
        assert a.tests == b.tests
    assert back.to_dataset().equals(br.to_dataset())      # values and coordinates, not attrs
