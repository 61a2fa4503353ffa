"""Model files and dicts are untrusted input: they may be refused, never run code.

Regression tests for what fuzzing found: a model name that ran code through a ``coding:``
declaration in the generated module, a cache that imported whatever was planted in it, names
that broke the generated code, and expressions that crashed the compiler or took minutes.
"""

from __future__ import annotations

import dataclasses
import json
import os
import stat
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import pwsdyn
from pwsdyn.errors import ExpressionError, ModelError
from pwsdyn.model import cache as model_cache
from pwsdyn.model import codegen


def _payload(sentinel: Path) -> str:
    """Python that, if it ever runs, leaves a file behind."""
    return f"open({str(sentinel)!r}, 'w').write('ran')"


def _injecting_names(sentinel: Path) -> list[str]:
    code = _payload(sentinel)
    return [
        # the defect: a coding declaration on line 1 of the generated module, the rest of
        # the name decoded by unicode_escape into a new line of code
        f"a # coding: unicode_escape \n{code}#",
        f"x\n# -*- coding: unicode_escape -*-\n{code}\n",
        f"# coding=utf-7\n+AAo-{code}",
        f"\r{code}",
        f"name'); {code}; ('",
        f'name"""\n{code}\n"""',
    ]


@pytest.fixture
def private_cache(tmp_path, monkeypatch):
    d = tmp_path / "cache"
    monkeypatch.setenv("PWSDYN_CACHE_DIR", str(d))
    return d / "models"


def _unique_model(name="probe", **extra):
    """A small model never compiled before (a fresh parameter name gives a new hash)."""
    k = f"k_{uuid.uuid4().hex[:10]}"
    spec = {"name": name, "states": ["x", "v"], "parameters": {k: 2.0},
            "modes": {"m": {"x": "v", "v": f"-{k}*x"}}}
    spec.update(extra)
    return spec


# ======================================================================================
# 1. no user text reaches generated code
# ======================================================================================

def test_coding_declaration_in_a_name_is_refused_from_every_source(tmp_path, private_cache):
    """Names with line breaks or control characters are refused at load (TOML file, dict,
    map model); printable ones that look like code are accepted and stay text."""
    sentinel = tmp_path / "SENTINEL"
    for name in _injecting_names(sentinel):
        printable = name.isprintable()
        toml = tmp_path / "evil.toml"
        toml.write_text(f"name = {json.dumps(name)}\nstates = ['x']\n[modes.m]\nx = '-x'\n")
        sources = [_unique_model(name), toml,
                   {"name": name, "kind": "map", "states": ["x"],
                    "pieces": [{"name": "p", "map": {"x": "x/2"}}]}]
        for source in sources:
            if printable:
                m = pwsdyn.load_model(source)
                assert m.name == name
                if getattr(m, "is_map", False):
                    pwsdyn.model.iterate(m, [0.5], 3)
                else:
                    pwsdyn.simulate(m, np.ones(m.n_states), (0.0, 0.1))
                continue
            with pytest.raises(ModelError) as exc:
                pwsdyn.load_model(source)
            assert "`name`" in str(exc.value) and "non-printable" in str(exc.value)
            if isinstance(source, Path):
                assert str(toml) in str(exc.value)
    assert not sentinel.exists()


def test_a_model_built_around_the_loader_still_writes_no_name_into_code(tmp_path,
                                                                         private_cache):
    """A Model whose name was replaced after loading (no validation on that path) compiles,
    and the generated source holds neither the name nor anything it could smuggle in."""
    sentinel = tmp_path / "SENTINEL"
    base = pwsdyn.load_model(_unique_model())
    for name in _injecting_names(sentinel):
        evil = dataclasses.replace(base, name=name)
        evil.__dict__.pop("digest", None)
        evil.__dict__.pop("hash", None)
        cm = pwsdyn.compile_model(evil)
        src = cm.source_path.read_text()
        assert name not in src and "coding" not in src.splitlines()[0]
        assert src.isascii()
        traj = pwsdyn.simulate(evil, {"x": 1.0, "v": 0.0}, (0.0, 1.0))
        assert traj.status == pwsdyn.Status.SUCCESS
    assert not sentinel.exists()


def test_saved_trajectory_with_an_injecting_model_name_is_refused(tmp_path, private_cache):
    sentinel = tmp_path / "SENTINEL"
    spec = _unique_model()
    traj = pwsdyn.simulate(spec, {"x": 1.0, "v": 0.0}, (0.0, 1.0))
    good = tmp_path / "good.nc"
    traj.save(good)
    ds = xr.load_dataset(good, engine="h5netcdf")
    stored = json.loads(ds.attrs["model_spec"])
    stored["name"] = _injecting_names(sentinel)[0]
    ds.attrs["model_spec"] = json.dumps(stored)
    ds.attrs["model"] = stored["name"]
    bad = tmp_path / "bad.nc"
    ds.to_netcdf(bad, engine="h5netcdf")
    with pytest.raises(pwsdyn.PwsdynError):
        back = pwsdyn.io.load_trajectory(bad)
        pwsdyn.simulate(back.model, {"x": 1.0, "v": 0.0}, (0.0, 1.0))
    assert not sentinel.exists()


@pytest.mark.parametrize("states, field", [
    (["x\n"], "states"),                      # '$' matched before a final newline
    (["x", "u_switch"], "states"),            # the switching variable of Utkin's family
    (["x" * 65], "states"),                   # longer than the limit
    (["x", "t"], "states"),
    (["x", "if"], None),                      # a Python keyword is fine: it is prefixed
])
def test_state_names_are_full_identifiers(states, field, private_cache):
    spec = {"name": "names", "states": states,
            "modes": {"m": {s: "0" for s in states}}}
    if field is None:
        m = pwsdyn.load_model(spec)
        cm = pwsdyn.compile_model(m)
        out = np.zeros(len(states) ** 2)
        cm.evaluate(codegen.W_F, 0, 0.0, np.ones(len(states)), np.zeros(1), out)
        return
    with pytest.raises(ModelError, match=f"field `{field}`"):
        pwsdyn.load_model(spec)


@pytest.mark.parametrize("where", ["parameters", "definitions", "modes", "events", "switches"])
def test_other_names_are_full_identifiers(where):
    bad = "k\n"
    spec = {"name": "names", "states": ["x"], "parameters": {"k": 1.0},
            "modes": {"m": {"x": "-k*x"}, "n": {"x": "k"}}}
    if where == "parameters":
        spec["parameters"] = {bad: 1.0}
        spec["modes"] = {"m": {"x": "-x"}}
    elif where == "definitions":
        spec["definitions"] = {bad: "x"}
    elif where == "modes":
        spec["modes"][bad] = {"x": "0"}
    elif where == "events":
        spec["events"] = [{"name": bad, "surface": "x"}]
    else:
        spec["switches"] = [{"name": bad, "surface": "x", "above": "m", "below": "n"}]
    with pytest.raises(ModelError):
        pwsdyn.load_model(spec)


@pytest.mark.parametrize("name", ["\x1b[2J\x1b[31mred", "bidi \u202eevil", "tab\there",
                                  "a" * 129, "", "   "])
def test_model_names_are_printable_text_of_bounded_length(name):
    with pytest.raises(ModelError, match="`name`"):
        pwsdyn.load_model(_unique_model(name))


def test_model_names_may_be_ordinary_text(private_cache):
    m = pwsdyn.load_model(_unique_model("Budd & Dux impact oscillator (ω = 2.5), run #3"))
    assert m.name.startswith("Budd & Dux")


# ======================================================================================
# 2. the cache cannot be planted
# ======================================================================================

def _module_path(model) -> Path:
    return model_cache.cache_dir() / f"m_{model.digest}_v{codegen._CODEGEN_VERSION}.py"


def _plant(path: Path, sentinel: Path, header: str | None = None) -> None:
    body = textwrap.dedent(f"""\
        {_payload(sentinel)}
        def evaluate(*args):
            pass
        """)
    first = header if header is not None else f"# planted for {path.stem}"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(first + "\n" + body)


def test_a_planted_module_under_the_model_name_is_regenerated_not_run(tmp_path, private_cache):
    sentinel = tmp_path / "SENTINEL"
    m = pwsdyn.load_model("bouncing-ball")
    m = dataclasses.replace(m, parameters={**m.parameters, f"z_{uuid.uuid4().hex[:8]}": 0.0})
    path = _module_path(m)
    _plant(path, sentinel)
    cm = pwsdyn.compile_model(m)
    assert not sentinel.exists()
    assert cm.source_path == path and "planted" not in path.read_text()
    traj = pwsdyn.simulate(m, {"y": 1.0, "v": 0.0}, (0.0, 0.3))
    np.testing.assert_allclose(traj.x_final[0], 1.0 - 9.81 / 2 * 0.3**2, rtol=1e-9)


def test_a_planted_module_with_a_forged_header_is_refused_when_others_can_write(
        tmp_path, private_cache):
    """Someone who can write into the cache can forge a consistent header; a cache directory
    that others can write to is therefore not used at all."""
    sentinel = tmp_path / "SENTINEL"
    m = pwsdyn.load_model(_unique_model())
    path = _module_path(m)
    body = f"{_payload(sentinel)}\ndef evaluate(*args):\n    pass\n"
    path.write_text(model_cache.header("model", codegen._CODEGEN_VERSION, m.digest, body)
                    + "\n" + body)
    os.chmod(path.parent, 0o777)
    model_cache._WARNED.clear()
    with pytest.warns(model_cache.CacheWarning, match="writable by group or others"):
        cm = pwsdyn.compile_model(m)
    assert not sentinel.exists()
    assert cm.source_path.parent != path.parent
    assert stat.S_IMODE(os.stat(cm.source_path.parent).st_mode) == 0o700


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="changing a file's owner needs root")
def test_a_module_owned_by_another_user_is_not_imported(tmp_path, private_cache):
    sentinel = tmp_path / "SENTINEL"
    m = pwsdyn.load_model(_unique_model())
    path = _module_path(m)
    body = f"{_payload(sentinel)}\ndef evaluate(*args):\n    pass\n"
    path.write_text(model_cache.header("model", codegen._CODEGEN_VERSION, m.digest, body)
                    + "\n" + body)
    os.chown(path, 65534, 65534)
    pwsdyn.compile_model(m)
    assert not sentinel.exists()
    assert os.stat(path).st_uid == os.getuid()


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="changing a directory's owner needs root")
def test_a_cache_directory_owned_by_another_user_is_not_used(tmp_path, private_cache):
    private_cache.mkdir(parents=True, mode=0o700)
    os.chown(private_cache, 65534, 65534)
    model_cache._WARNED.clear()
    with pytest.warns(model_cache.CacheWarning, match="owned by user id 65534"):
        cm = pwsdyn.compile_model(pwsdyn.load_model(_unique_model()))
    assert cm.source_path.parent != private_cache


def test_new_cache_directories_are_private(private_cache):
    pwsdyn.compile_model(pwsdyn.load_model(_unique_model()))
    assert stat.S_IMODE(os.stat(private_cache).st_mode) == 0o700


def test_an_unusable_cache_falls_back_to_a_private_directory(tmp_path, monkeypatch):
    blocker = tmp_path / "not-a-dir"
    blocker.write_text("")
    monkeypatch.setenv("PWSDYN_CACHE_DIR", str(blocker / "cache"))
    model_cache._WARNED.clear()
    with pytest.warns(model_cache.CacheWarning, match="cannot create it"):
        traj = pwsdyn.simulate(_unique_model(), {"x": 1.0, "v": 0.0}, (0.0, 1.0))
    assert traj.status == pwsdyn.Status.SUCCESS


def test_a_module_that_fails_to_compile_is_removed_and_a_retry_fails_the_same_way(
        private_cache):
    """Before, the half-imported module stayed in sys.modules and a retry in the same process
    said "module has no attribute 'evaluate'"."""
    digest = uuid.uuid4().hex * 2
    body = "import numba\n\n@numba.njit\ndef evaluate(x):\n    return x + 'a'\n"

    def warm_up(fn):
        fn(1.0)

    for _ in range(2):
        with pytest.raises(ModelError, match="could not be compiled"):
            model_cache.load_module("model", "test", digest, lambda: body, model_name="bad",
                                    attribute="evaluate", warm_up=warm_up)
        assert not list(model_cache.cache_dir().glob(f"m_{digest}*"))
        assert not any(digest in k for k in sys.modules)


def test_a_truncated_module_is_regenerated(private_cache):
    m = pwsdyn.load_model(_unique_model())
    cm = pwsdyn.compile_model(m)
    text = cm.source_path.read_text()
    cm.source_path.write_text(text[: len(text) // 2])
    codegen._COMPILED.clear()
    for k in [k for k in sys.modules if m.digest in k]:
        del sys.modules[k]
    again = pwsdyn.compile_model(m)
    assert again.source_path.read_text() == text


def test_generated_source_is_ascii_with_a_fixed_header(private_cache):
    for name in ("bouncing-ball", "quarter-car", "stick-slip-oscillator"):
        src = codegen.generate_source(pwsdyn.load_model(name))
        first, second = src.splitlines()[:2]
        assert src.isascii()
        assert first.startswith("# pwsdyn model codegen v") and name not in first
        assert "coding" not in second


# ======================================================================================
# 3. expressions: finite and real, or refused naming the field
# ======================================================================================

@pytest.mark.parametrize("text", [
    "sqrt(-1)", "log(-1)*x", "10**1000", "(9**999)**5", "((9**999)**999)**999", "sin(inf)",
    "Max(sqrt(-1), x)", "inf - inf", "0/0", "x/0", "log(0)", "1e308*10", "10**300*10**300",
    "x + inf", "9" * 400, "2**-2000",
])
def test_non_finite_complex_and_huge_constants_are_refused_naming_the_field(text):
    spec = {"name": "nf", "states": ["x"], "modes": {"m": {"x": text}}}
    with pytest.raises(ExpressionError, match="modes.m.x"):
        pwsdyn.load_model(spec)


def test_a_complex_derivative_is_refused_for_flows_and_maps(private_cache):
    """A negative number to a symbolic power is finite where the power is an integer, but its
    derivative has log(-a) = log(a) + I pi: complex at every point. Flows and maps are refused
    at code generation, naming the field (a map once put I into its generated code)."""
    from pwsdyn.model import iteration, maps

    flow = {"name": "cf", "states": ["x", "v"], "modes": {"m": {"x": "v", "v": "(-0.5)**x"}}}
    with pytest.raises(ModelError, match="complex"):
        codegen.generate_source(pwsdyn.load_model(flow))
    pieces = {"name": "cm", "kind": "map", "states": ["a", "b"],
              "pieces": [{"name": "P", "condition": "b > 0",
                          "map": {"a": "(-0.01)**(b + 10.0)", "b": "b"}},
                         {"name": "N", "condition": "b <= 0", "map": {"a": "a", "b": "-b"}}]}
    with pytest.raises(ModelError, match=r"pieces\[0\]\.map\.a.*Jacobian of piece 'P'"):
        maps.generate_map_source(pwsdyn.load_model(pieces))
    single = {"name": "cs", "kind": "map", "states": ["a"], "map": {"a": "(-2)**a"}}
    with pytest.raises(ModelError, match=r"map\.a.*complex"):
        iteration.iterate(single, [1.0], 3)


def test_non_finite_numbers_in_toml_and_guards_are_refused(tmp_path):
    f = tmp_path / "nan.toml"
    f.write_text("name = 'n'\nstates = ['x']\n[modes.m]\nx = nan\n")
    with pytest.raises(ExpressionError) as exc:
        pwsdyn.load_model(f)
    assert f"{f}:4" in str(exc.value) and "modes.m.x" in str(exc.value)
    spec = {"name": "g", "states": ["x"], "modes": {"m": {"x": "1"}},
            "events": [{"name": "e", "surface": "x", "guard": "x > 0/0"}]}
    with pytest.raises(ExpressionError, match=r"events\[0\].guard"):
        pwsdyn.load_model(spec)
    with pytest.raises(ExpressionError, match="forcing_period"):
        pwsdyn.load_model({"name": "f", "states": ["x"], "parameters": {"w": 1.0},
                           "forcing_period": "2*pi/0", "modes": {"m": {"x": "cos(w*t)"}}})


def test_large_but_finite_numbers_compile_as_doubles(private_cache):
    """numba types integer literals as int64: 10**20 must reach it as a double."""
    spec = {"name": "big", "states": ["x"], "modes": {"m": {"x": "10**20*x + 3**40/7**30"}}}
    cm = pwsdyn.compile_model(pwsdyn.load_model(spec))
    out = np.zeros(1)
    cm.evaluate(codegen.W_F, 0, 0.0, np.array([2.0]), np.zeros(1), out)
    assert out[0] == pytest.approx(2e20 + 3**40 / 7**30, rel=1e-15)


def test_sympy_input_may_only_use_the_allowed_functions():
    import sympy as sp

    x = sp.Symbol("x", real=True)
    evil = sp.Function("__import__('os').system")(x)
    with pytest.raises(ExpressionError, match="not allowed"):
        pwsdyn.load_model({"name": "s", "states": ["x"], "modes": {"m": {"x": evil}}})
    m = pwsdyn.load_model({"name": "s", "states": ["x"], "modes": {"m": {"x": -sp.sin(x)}}})
    assert m.modes[0].rhs == (-sp.sin(x),)


def test_long_sums_and_products_are_built_in_linear_time_and_big_ones_refused():
    """A sum of many terms parses (its spine is walked iteratively and built as one Add); a
    product of 300 distinct factors, whose derivative has 90,000 factors, is refused."""
    names = {"x": __import__("sympy").Symbol("x", real=True)}
    from pwsdyn.model.expressions import parse_expression

    long_sum = " + ".join(f"{k}*x - {k}/2*x" for k in range(1, 501))
    assert parse_expression(long_sum, names) == 62625 * names["x"]
    product = "*".join(f"(x + {k})" for k in range(1, 301))
    with pytest.raises(ExpressionError, match="too large"):
        parse_expression(product, names, field="modes.m.x")


def test_splitting_into_too_many_modes_is_refused_with_the_count():
    # a sign family (one field of its sides) may have 1024 variants, one per side of each of
    # the ten surfaces a mode may have; an eleventh surface is refused with the names
    terms = " + ".join(f"sign(x - {i})" for i in range(11))
    with pytest.raises(ModelError, match=r"field `modes.m`: mode 'm' has more than 10 "
                                         r"distinct switching surfaces \(x, -1\+x, .*, -2\+x\); "
                                         "write it as explicit"):
        pwsdyn.load_model({"name": "many", "states": ["x"], "modes": {"m": {"x": terms}}})
    ten = " + ".join(f"sign(x - {i})" for i in range(10))
    assert len(pwsdyn.load_model({"name": "ten", "states": ["x"],
                                  "modes": {"m": {"x": ten}}}).modes) == 1024
    # nested terms are no family: each variant is its own field, 16 at most
    nested = " + ".join(f"Max({i}*y, Min({i + 1}*y, x))" for i in range(1, 4))
    with pytest.raises(ModelError, match="at least 32 modes; at most 16"):
        pwsdyn.load_model({"name": "nested", "states": ["x", "y"],
                           "modes": {"m": {"x": nested, "y": "1"}}})


_HANG_SCRIPT = textwrap.dedent("""
    import json, sys
    import pwsdyn
    for spec in json.loads(sys.argv[1]):
        try:
            m = pwsdyn.load_model(spec)
            pwsdyn.compile_model(m)
            print("accepted")
        except pwsdyn.ModelError as exc:
            print("refused", str(exc)[:80].replace(chr(10), " "))
""")


def test_inputs_that_took_minutes_are_answered_at_once(tmp_path):
    """These took minutes or never finished (power towers, a 2,000-factor product, sign
    terms past the bound: seven took minutes when each variant was compiled on its own;
    since they are one sign family, eleven, 2048 variants, are over its bound of 1024). The
    subprocess's timeout only guards the test run against a hang; the inputs are refused
    before any symbolic work."""
    fields = ["((9**999)**999)**999", "*".join(f"(x + {k})" for k in range(2000)),
              " + ".join(f"sign(x - {k})" for k in range(11)), "sin(" * 198 + "x" + ")" * 198]
    specs = [{"name": "h", "states": ["x"], "modes": {"m": {"x": f}}} for f in fields]
    env = dict(os.environ, PWSDYN_CACHE_DIR=str(tmp_path))
    res = subprocess.run([sys.executable, "-c", _HANG_SCRIPT, json.dumps(specs)], env=env,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.strip().splitlines()
    assert len(lines) == 4 and all(ln.startswith("refused") for ln in lines), lines
