"""A sweep means one uninterrupted sequence (src/pwsdyn/explore/_sweep.py): its dataset does
not depend on ``workers``, ``chunk_size``, the scheduler or a resume, and a run that starts in
a sticking state reports it.

Independent references:

* a ball at rest on a table vibrating as ``A sin(omega t)`` stays on it while the table's
  largest downward acceleration ``A omega^2`` is below ``g`` (the contact force
  ``m (g - A omega^2 sin(omega t))`` never vanishes): in a sweep up in ``A`` that starts
  with the ball resting, every value ``A < g / omega^2`` reports the ball stuck for the whole
  period, whatever the chunking;
* the sequential sweep (one chunk, one worker): every other setting must give its dataset to
  the integrator's tolerance.
"""

from __future__ import annotations

import numpy as np
import pytest

import pwsdyn
from pwsdyn.explore._sweep import same_attractor

G = 9.81
OMEGA = 2 * np.pi            # period T = 1 s
E = 0.8
A_LIFT = G / OMEGA ** 2      # 0.2485 m: the table's acceleration reaches g

# the guide's sweep (np.linspace(0.05, 0.4, 200), default x0: a drop from 1.5 m), thinned to
# 20 values, with 12 of them packed just below the closed-form lift-off amplitude, where the
# chunk borders of the parallel sweep used to let the ball "lift off"
VALUES = np.concatenate([np.linspace(0.05, 0.22, 6), np.linspace(0.225, 0.2475, 10),
                         np.linspace(0.26, 0.4, 4)])
KW = dict(params={"omega": OMEGA, "e": E}, transient=60, samples=12, direction="up",
          progress=False)


def _ball(chunk_size, workers, **kw):
    return pwsdyn.sweep("bouncing-ball", "A", VALUES, chunk_size=chunk_size, workers=workers,
                        **KW, **kw)


@pytest.fixture(scope="module")
def sequential():
    return _ball(len(VALUES), 1)


def _assert_same_cycles(ds, ref, atol=1e-6):
    """At every value where ``ref`` finds a period ``k``, the last ``k`` section points of
    both datasets are the same set to ``atol`` (a period-``k`` cycle is one attractor
    whichever of its points the window starts at: a run that reached it on another path may
    record it shifted by a forcing period)."""
    per = ref.period.values
    for idx in zip(*np.nonzero(per > 0)):
        k = int(per[idx])
        a = ds.section.values[idx][:int(ds.n_points.values[idx])][-k:]
        b = ref.section.values[idx][:int(ref.n_points.values[idx])][-k:]
        d = np.max(np.abs(a[:, None, :] - b[None, :, :]), axis=2)
        assert max(d.min(axis=0).max(), d.min(axis=1).max()) <= atol, (idx, a, b)


def _assert_same(ds, ref):
    """The same dataset as ``ref`` to the integrator's tolerance: the counts exactly, times
    and section points to 1e-6 (the default rtol is 1e-8; two runs on one stable orbit from
    states a transient apart agree far closer). A stuck ball's points are exact functions of
    time, so they agree too. Where the sequential sweep finds no period (chattering and
    chaos above the lift-off) a run from a state a round-off away is other points of the
    attractor: only the status and that no period is found are compared there."""
    for k in ("period", "n_points", "status"):
        np.testing.assert_array_equal(ds[k].values, ref[k].values, err_msg=k)
    periodic = ref.period.values > 0
    assert periodic.sum() >= len(VALUES) - 6
    np.testing.assert_array_equal(ds.events_per_period.values[periodic],
                                  ref.events_per_period.values[periodic])
    for k in ("stick_time", "slide_time"):
        np.testing.assert_allclose(ds[k].values[periodic], ref[k].values[periodic], atol=1e-6,
                                   rtol=0, err_msg=k)
    _assert_same_cycles(ds, ref)


def test_sequential_ball_stays_on_the_table_below_the_closed_form_lift_off(sequential):
    up = sequential.sel(direction="up")
    below = VALUES < A_LIFT
    # the whole period (T = 1 s) stuck, no event, section on the table (s = 0 at t = k T)
    np.testing.assert_allclose(up.stick_time.values[below], 1.0, atol=1e-9)
    assert np.all(up.events_per_period.values[below] == 0)
    np.testing.assert_allclose(up.section.values[below, :, 0], 0.0, atol=1e-8)
    # above it the ball leaves the table
    assert np.all(up.stick_time.values[~below] < 1.0)
    assert sequential.attrs["stitch_borders"] == 0 == sequential.attrs["stitch_values"]


@pytest.mark.parametrize("chunk_size,workers", [(1, 1), (5, 1), (5, 2), (50, 2), (1, 2)])
def test_chunked_ball_sweep_is_the_sequential_one(sequential, chunk_size, workers):
    ds = _ball(chunk_size, workers)
    up = ds.sel(direction="up")
    below = VALUES < A_LIFT
    np.testing.assert_allclose(up.stick_time.values[below], 1.0, atol=1e-9)
    _assert_same(ds, sequential)
    n_chunks = -(-len(VALUES) // chunk_size)
    assert ds.attrs["stitch_borders"] == n_chunks - 1
    assert int(ds.chunk_start.sum()) == n_chunks
    # the guesses of chunks starting below the lift-off from a drop at 1.5 m end bouncing
    # for some: those are rerun, and the record says which
    if chunk_size < len(VALUES):
        rerun = ds.chunk_rerun.values[0]
        assert ds.attrs["stitch_reruns"] == int(np.sum(rerun & ds.chunk_start.values[0]))
        assert ds.attrs["stitch_values"] == (ds.attrs["stitch_borders"]
                                             - ds.attrs["stitch_reruns"] + int(rerun.sum()))


def test_dask_cluster_and_resume_give_the_sequential_sweep(sequential, tmp_path):
    """A LocalCluster of two processes (as a user's cluster), and a store resumed after
    losing chunks (guesses and reruns alike), give the sequential dataset."""
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0") as cluster, Client(cluster) as client:
        d = _ball(5, None, client=client)
    _assert_same(d, sequential)
    store = tmp_path / "store"
    full = _ball(5, 1, store=store)
    files = sorted(store.glob("chunk-*.nc"))
    assert len(files) > 4           # 4 guesses and the reruns
    for f in files[1::2]:           # lose every other chunk, as a run killed midway
        f.unlink()
        f.with_suffix(".sha256").unlink()
    resumed = _ball(5, 1, store=store)
    import xarray as xr

    xr.testing.assert_identical(resumed, full)
    _assert_same(resumed, sequential)


def test_zoo_flow_sweep_independent_of_chunks_and_workers():
    """The impact oscillator over a range with a period-doubling and chaotic windows (few
    values, few periods): chunk sizes 1 and 5 with one and two workers give the sequential
    dataset (periodic values to 1e-6, as in ``_assert_same``)."""
    vals = np.linspace(2.3, 3.1, 10)
    kw = dict(transient=150, samples=16, direction="both", progress=False)
    ref = pwsdyn.sweep("impact-oscillator", "omega", vals, [-0.5, 0.0], chunk_size=10,
                       workers=1, **kw)
    for cs, w in ((1, 2), (5, 1)):
        ds = pwsdyn.sweep("impact-oscillator", "omega", vals, [-0.5, 0.0], chunk_size=cs,
                          workers=w, **kw)
        periodic = ref.period.values > 0
        assert periodic.sum() >= 10
        for k in ("period", "n_points", "status"):
            np.testing.assert_array_equal(ds[k].values, ref[k].values, err_msg=k)
        np.testing.assert_array_equal(ds.events_per_period.values[periodic],
                                      ref.events_per_period.values[periodic])
        _assert_same_cycles(ds, ref)


def test_zoo_map_sweep_independent_of_chunks():
    vals = np.linspace(0.01, 0.05, 9)
    kw = dict(params={"lam": 0.1}, transient=500, samples=40, direction="both",
              progress=False)
    ref = pwsdyn.sweep("sqrt-map", "mu", vals, [0.0], chunk_size=9, workers=1, **kw)
    for cs, w in ((1, 1), (5, 2)):
        ds = pwsdyn.sweep("sqrt-map", "mu", vals, [0.0], chunk_size=cs, workers=w, **kw)
        np.testing.assert_allclose(ds.section.values, ref.section.values, atol=1e-12)
        np.testing.assert_array_equal(ds.period.values, ref.period.values)


def test_ball_started_at_rest_reports_the_whole_period_stuck():
    """A ball put at rest on the table at t0 (y = s(0) = 0, v = s'(0) = A omega) with
    A omega^2 < g never leaves it: the sweep reports stick time = the whole period and no
    event, with no transient (the start itself is the only record of the sticking) and
    with one. (At a next value the table's velocity jumps with ``A``: the ball is no longer
    at rest on it, so one value only.)"""
    A = 0.1
    for transient in (0, 3):
        ds = pwsdyn.sweep("bouncing-ball", "A", [A], [0.0, A * OMEGA],
                          params={"omega": OMEGA, "e": E}, transient=transient, samples=4,
                          direction="up", workers=1, progress=False)
        np.testing.assert_allclose(ds.stick_time.values, 1.0, atol=1e-12)
        assert np.all(ds.events_per_period.values == 0)


def test_a_rerun_resumes_from_the_windows_of_an_earlier_rerun(monkeypatch):
    """A chunk rerun from a new state (the chunk before it was rerun and hands on another
    state) takes the windows of its earlier rerun from the first value that lies on their
    attractor: one value integrated, not the chunk, and the rows after it are that rerun's.
    Here the earlier rerun is the chunk's own confirmed result and the guess a window of
    another outcome (a failed status), so only the earlier rerun can be rejoined."""
    from pwsdyn.explore import _sweep as S

    seen = {}
    real_stitch = S.stitch

    def spy(tasks, *args):
        final, info = real_stitch(tasks, *args)
        seen.update(tasks=tasks, final=final)
        return final, info

    monkeypatch.setattr(S, "stitch", spy)
    _ball(5, 1)
    tasks, final = seen["tasks"], seen["final"]
    task, earlier = tasks[2], final[2]
    start = S.handed_on(final[1], np.array(task["settings"]["x0"]), 1e8)
    other = {k: np.array(v, copy=True) for k, v in earlier.items()}
    other["status"][:] = -1
    calls = []
    real_window = S.run_window
    monkeypatch.setattr(S, "run_window", lambda *a, **k: calls.append(1) or real_window(*a, **k))
    got = S.sweep_chunk({**task, "x_start": start.tolist(), "warmup": 0,
                         "values": task["values"][task["warmup"]:], "guess": other,
                         "alts": [other, earlier]})
    assert len(calls) == 1
    assert got["rerun"][0]
    for k in S._CHUNK_VARS:
        if k != "x_start":
            np.testing.assert_array_equal(got[k][1:], earlier[k][1:], err_msg=k)
    assert same_attractor(S.row(got, 0), S.row(earlier, 0), 1.0, KW["samples"], False)


def test_same_attractor_compares_windows_not_states():
    """Two windows of one period-2 cycle recorded at different phases of it are the same
    attractor; another period-2 cycle, another period, or sticking time are not."""
    pts = np.full((8, 2), np.nan)
    cyc = np.array([[0.0, 1.0], [0.5, -1.0]])
    pts[:6] = np.tile(cyc, (3, 1))
    a = dict(status=0, period=2, n_points=6, events_per_period=1.0, stick_time=0.0,
             slide_time=0.0, section=pts, phase=np.full(8, np.nan))
    shifted = pts.copy()
    shifted[:6] = np.tile(cyc[::-1], (3, 1))
    b = {**a, "section": shifted}
    assert same_attractor(a, b, 1.0, 6, False)
    assert not same_attractor({**a, "period": 0}, {**b, "period": 0}, 1.0, 6, False)
    other = {**a, "section": pts + 0.01}
    assert not same_attractor(a, other, 1.0, 6, False)
    assert not same_attractor(a, {**a, "period": 1}, 1.0, 6, False)
    assert not same_attractor(a, {**a, "stick_time": 0.5}, 1.0, 6, False)
    assert same_attractor({**a, "status": 5}, {**b, "status": 5}, 1.0, 6, False)


def test_trajectory_and_metrics_see_a_sticking_start():
    """The same start in :func:`pwsdyn.simulate`: the trajectory's discrete state is sticking
    from its first node and :func:`pwsdyn.explore.response_metrics` counts the whole window
    as stick time (closed form: the ball never leaves a table with A omega^2 < g)."""
    from pwsdyn.explore import response_metrics

    A = 0.1
    tr = pwsdyn.simulate("bouncing-ball", [0.0, A * OMEGA], (0.0, 3.0),
                         params={"A": A, "omega": OMEGA, "e": E})
    assert str(tr.state[0]) == "stick:impact" and len(tr.events) == 0
    m = response_metrics(tr, "v")
    assert m.stick_time == pytest.approx(3.0, abs=1e-12)


def test_x0_inside_a_wall_is_refused_like_simulate():
    """A sweep whose first run would start inside an impact constraint refuses ``x0`` with
    simulate's error (before, it ran the state behind the wall and reported no impacts)."""
    with pytest.raises(pwsdyn.ArgumentError, match="inside the constraint"):
        pwsdyn.sweep("impact-oscillator", "omega", [3.0, 3.1], {"x": 0.0, "v": 0.0},
                     params={"sigma": -0.5}, progress=False, workers=1)
    with pytest.raises(pwsdyn.ArgumentError, match="inside the constraint"):
        pwsdyn.scan("impact-oscillator", {"omega": [3.0, 3.1], "sigma": [0.1, -0.5]},
                    {"x": 0.0, "v": 0.0}, progress=False, workers=1)


def test_a_wall_moved_onto_the_carried_state_pushes_it():
    """Swept down in the gap ``sigma``, the wall (``x <= sigma``) passes the carried state,
    which is then put on it (``readmit``). Below ``sigma = 0`` the spring's rest position
    ``x = 0`` lies beyond the wall, so every admissible motion keeps hitting it: at least one
    impact per period at every such value, and the final states admissible."""
    sig = np.linspace(0.3, -0.5, 9)
    ds = pwsdyn.sweep("impact-oscillator", "sigma", sig, {"x": 0.0, "v": 0.0},
                      params={"omega": 3.0}, direction="down", progress=False, workers=1,
                      transient=50, samples=20)
    ev = ds.events_per_period.sel(direction="down").values
    assert np.all(ds.status.values == 0)
    assert np.all(ev[ds.sigma.values < -0.05] >= 1.0), ev
    x_end = ds.x_final.sel(direction="down", state="x").values
    assert np.all(x_end <= ds.sigma.values + 1e-8), x_end


@pytest.mark.parametrize("model", ["sqrt-map", "impact-oscillator"])
@pytest.mark.parametrize("section", [np.array([]), np.array(["stroboscopic"]), 3, None])
def test_a_section_that_is_not_a_string_is_refused(model, section):
    """Found by the slow fuzzer: an empty array as ``section`` of a map's sweep raised numpy's
    ValueError (the comparison with 'stroboscopic' was element by element)."""
    with pytest.raises(pwsdyn.ArgumentError, match="section"):
        pwsdyn.sweep(model, list(pwsdyn.load_model(model).parameters)[0], [0.1, 0.2],
                     section=section, progress=False, workers=1)
