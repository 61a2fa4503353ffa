"""Results print as what they are: statuses by name, signatures as their event sequence, and a
short ``repr`` with an HTML summary (``_repr_html_``, what a notebook shows) for trajectories,
periodic orbits, branches and the other results users get.

Each summary is checked for its content (the numbers of the result it shows, computed here
from the result's own attributes), for escaping (a model whose name is HTML shows as text),
and for not failing on an empty or failed result. The snippet checker of the documentation
(``tests/_snippets.py``) is checked on lines of known output.
"""

from __future__ import annotations

import html
import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

import pwsdyn
from pwsdyn import Status
from pwsdyn.integrate.trajectory import Trajectory
from pwsdyn.orbits import Signature

sys.path.insert(0, str(Path(__file__).parent))
from _snippets import bare_values, check_printed, line_matches, stated_lines  # noqa: E402

#: A model whose name is HTML (names of states, modes and events are identifiers; a model's
#: name and a result's message are free text): a summary must show it as text.
HTML_BALL = {
    "name": "<b>ball</b>", "states": ["y", "v"], "parameters": {"g": 9.81, "e": 0.5},
    "modes": {"flight": {"y": "v", "v": "-g"}},
    "events": [{"name": "impact", "kind": "impact", "surface": "y", "direction": -1,
                "reset": {"v": "-e*v"}}],
}


def _no_raw_markup(page: str, *texts: str):
    """None of ``texts`` appears unescaped in ``page``; each appears escaped."""
    for text in texts:
        assert text not in page
        assert html.escape(text) in page


# ---- Status -------------------------------------------------------------------------------

def test_status_prints_by_name_and_stays_an_int():
    s = Status.SUCCESS
    assert repr(s) == "Status.SUCCESS" and str(s) == "SUCCESS"
    assert f"{s}" == "SUCCESS" and f"{Status.MAX_STEPS:>10}" == " MAX_STEPS"
    assert repr([Status.DIVERGED]) == "[Status.DIVERGED]"
    # the value is still the int the kernel and the files use
    assert s == 0 and int(Status.DIVERGED) == -1 and Status.MAX_STEPS + 1 == 3
    assert f"{Status.DIVERGED:d}" == "-1" and f"{Status.ZENO:03d}" == "007"
    assert "%d" % Status.NONFINITE == "5"
    assert json.dumps({"status": Status.NONFINITE}) == '{"status": 5}'
    assert np.array([Status.SUCCESS, Status.DIVERGED]).tolist() == [0, -1]
    for member in Status:
        assert eval(repr(member), {"Status": Status}) is member
        assert Status[str(member)] is member


# ---- Signature ----------------------------------------------------------------------------

def test_signature_prints_as_its_event_sequence_and_its_repr_makes_it_again():
    sig = Signature([("impact", "impact", "free", "stick:impact"),
                     ("release", "impact", "stick:impact", "free")])
    assert str(sig) == "(free) impact:impact (stick:impact) release:impact (free)"
    assert repr(sig) == "Signature('(free) impact:impact (stick:impact) release:impact (free)')"
    assert eval(repr(sig), {"Signature": Signature}) == sig
    assert Signature.parse(str(sig)) == sig and Signature(str(sig)) == sig
    assert repr(Signature()) == "Signature()" and str(Signature()) == "()"
    assert eval(repr(Signature()), {"Signature": Signature}) == Signature()
    assert repr([Signature(), sig[:1]]) == (
        "[Signature(), Signature('(free) impact:impact (stick:impact)')]")
    with pytest.raises(ValueError, match="kind:name"):
        Signature("(free) impact (free)")


# ---- Trajectory ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def html_run():
    model = pwsdyn.load_model(HTML_BALL)
    return pwsdyn.simulate(model, {"y": 1.0, "v": 0.0}, (0, 1.2))


def test_trajectory_repr_and_html_show_the_run(html_run):
    traj = html_run
    n_imp = sum(1 for e in traj.events if e.kind == "impact")
    assert n_imp >= 2
    text = repr(traj)
    assert text.startswith("Trajectory(model='<b>ball</b>'")
    assert f"nodes={len(traj.t)}" in text and f"impact={n_imp}" in text
    assert "status=SUCCESS" in text and f"{traj.t_final:.6g}" in text
    page = traj._repr_html_()
    assert page.startswith("<table>") and page.endswith("</table>")
    _no_raw_markup(page, "<b>ball</b>")
    assert f"impact {n_imp}" in page and "SUCCESS" in page
    assert f"y={traj.x_final[0]:.6g}" in page


def test_trajectory_summaries_of_an_empty_and_a_failed_run(html_run):
    failed = pwsdyn.simulate(html_run.model, {"y": 1.0, "v": 0.0}, (0, 1.2), max_steps=3,
                             throw=False)
    assert failed.status is Status.MAX_STEPS
    assert "status=MAX_STEPS" in repr(failed)
    assert "MAX_STEPS: " + html.escape(failed.message) in failed._repr_html_()
    empty = Trajectory(t=np.zeros(0), x=np.zeros((0, 2)), state=[], events=[],
                       status=Status.NONFINITE, message="x < 0 & y > 1", stats={},
                       model=html_run.model, params={}, options={}, t0=0.0, t_end=1.0)
    assert "nodes=0" in repr(empty) and "events: none" in repr(empty)
    page = empty._repr_html_()
    _no_raw_markup(page, "<b>ball</b>", "x < 0 & y > 1")
    assert "NONFINITE: x &lt; 0" in page


# ---- PeriodicOrbit, Branch, special points ------------------------------------------------

@pytest.fixture(scope="module")
def branch():
    params = {"eps": 0.1, "sigma": -0.5, "omega": 2.8}
    traj = pwsdyn.simulate("impact-oscillator", {"x": -1.0, "v": 0.0}, (0, 100),
                           params=params)
    orbit = pwsdyn.PeriodicOrbit.from_trajectory(traj)
    return orbit, pwsdyn.continue_orbit("impact-oscillator", orbit, "omega", span=(2.6, 3.0))


def test_periodic_orbit_repr_and_html(branch):
    orbit, _ = branch
    mods = np.abs(orbit.multipliers)
    text = repr(orbit)
    assert text.startswith("PeriodicOrbit(model='impact-oscillator'")
    assert f"period={orbit.period:.10g}" in text
    assert "|multipliers|=[" + ", ".join(f"{m:.4g}" for m in mods) + "]" in text
    assert ("stable" if orbit.stable else "unstable") in text
    assert "NOT" not in text
    page = orbit._repr_html_()
    assert html.escape(str(orbit.signature)) in page and f"{orbit.period:.12g}" in page
    assert "(1 forcing period(s))" in page


def test_periodic_orbit_summaries_when_nothing_was_found(branch):
    orbit, _ = branch
    failed = type(orbit)(model=orbit.model, params={}, t0=0.0, x0=np.array([np.nan, np.nan]),
                         state0="free", period=np.nan, events=[], trajectory=None,
                         monodromy=None, multipliers=None, stable=None, history=[],
                         converged=False, autonomous=True)
    text = repr(failed)
    assert "period=nan" in text and "|multipliers|=?" in text and "NOT converged" in text
    page = failed._repr_html_()
    assert "no events" in page and "0 Newton step(s)" in page


def test_branch_and_special_point_summaries(branch):
    _, br = branch
    lam = br.values
    text = repr(br)
    assert text.startswith("Branch(orbit of 'impact-oscillator' in omega: "
                           f"{len(br)} points, omega in [{lam.min():.6g}, {lam.max():.6g}]")
    page = br._repr_html_()
    assert f"{int(br.stable.sum())} of {len(br)} points" in page
    for sp in br.special_points:
        assert f"{sp.kind}</th>" in page and f"{sp.value:.10g} (point {sp.index})" in page
    empty = type(br)(br.problem, [], stop_reason="no points")
    assert "0 points, omega in []" in repr(empty) and "no points" in empty._repr_html_()


# ---- the snippet checker --------------------------------------------------------------------

def test_the_snippet_convention_on_known_lines():
    code = ("x = 1\nprint(x)  # -> 2.24399\nprint('a # -> b')  # -> SUCCESS\n"
            "print(y)  # -> [0. 0. -2.3787]  # a remark\n")
    assert stated_lines(code) == ["2.24399", "SUCCESS", "[0. 0. -2.3787]"]
    assert line_matches("2.24399", "2.243994752564")
    assert not line_matches("2.2439", "2.243994752564")          # rounded, not truncated
    assert line_matches("[0. 0. -2.3787]", "[ 0.        0.       -2.378654]")
    assert line_matches("[PD at omega = 4.31998, ...]", "[PD at omega = 4.319977, EP at 4.6]")
    assert not line_matches("x0 = 1.5", "x1 = 1.5") and not line_matches("loss", "persistence")
    assert check_printed(code, "2.243995\nSUCCESS\n[0 0 -2.37871]\n") == []
    assert len(check_printed(code, "2.243995\nSUCCESS\n")) == 1       # a line missing
    assert check_printed(code, "2.25\nSUCCESS\n[0 0 -2.37871]\n")[0].startswith("line 1")
    assert re.search("4 printed", check_printed("print(1)  # -> 1\n", "1\n2\n3\n4\n")[0])
    # a value left in a comment is found; a call with an effect, or a printed value, is not
    assert bare_values("orbit.multipliers, orbit.stable   # [...], True\n"
                       "traj.events[:3]  # impacts\ntraj.save('a.nc')  # writes\n"
                       "print(orbit.stable)  # -> True\n") == [
        "orbit.multipliers, orbit.stable   # [...], True", "traj.events[:3]  # impacts"]


# ---- the grazing and Lyapunov results -------------------------------------------------------

def test_discontinuity_map_summary():
    from pwsdyn.grazing import DiscontinuityMap

    names = ("x", "v", "t")
    dmap = DiscontinuityMap(x_star=np.array([0.1, 0.0, 1.0]), a_star=1.14523,
                            beta=np.array([0.0, 0.0, -2.37871]), P=0.5 * np.eye(3),
                            h_x=np.array([0.0, 0.0, -1.0]), names=names, event="<stop>")
    seq = dmap.persistence(6)
    assert np.all(seq > 0) and dmap.scenario == "persistence"
    assert repr(dmap) == ("DiscontinuityMap(event='<stop>', a_star=1.14523, "
                          "beta=[x=0, v=0, t=-2.37871], scenario='persistence')")
    page = dmap._repr_html_()
    _no_raw_markup(page, "<stop>")
    assert ", ".join(f"{v:.4g}" for v in seq) in page
    broken = DiscontinuityMap(x_star=np.zeros(3), a_star=np.nan, beta=np.zeros(2),
                              P=np.eye(3), h_x=np.zeros(3), names=names, event="stop")
    assert "scenario='?'" in repr(broken) and "?" in broken._repr_html_()


def test_lyapunov_spectrum_summary():
    from pwsdyn.explore import LyapunovSpectrum

    lyap = LyapunovSpectrum(exponents=np.array([0.0123456, -np.inf]), time=80.0,
                            convergence=np.zeros((0, 2)), events={"impact": 7},
                            status=int(Status.DIVERGED), span=100.0, contact_episodes=2,
                            contact_time=20.0)
    assert repr(lyap) == ("LyapunovSpectrum(model='?', exponents=[0.0123456, -inf], time=80, "
                          "status=DIVERGED)")
    page = lyap._repr_html_()
    assert "80 of 100" in page and "impact 7" in page and "2 episode(s), 20 sticking" in page
    assert html.escape(Status.DIVERGED.message) in page
