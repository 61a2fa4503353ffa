"""Monitor keys: the named type of a monitor of a discontinuity-induced bifurcation and its
string form (the name a branch's column and a special point carry) read back to the same
key."""

from __future__ import annotations

import pytest

from pwsdyn.orbits import MonitorKey
from pwsdyn.orbits.monitors import DIB_KINDS


@pytest.mark.parametrize("text, key", [
    ("GR/impact/0", MonitorKey("GR", "impact", 0)),
    ("GR/impact@0", MonitorKey("GR", "impact", 0, "boundary")),
    ("GR/x/2/arc", MonitorKey("GR", "x", 2, "arc")),
    ("AS/vrel:above/2", MonitorKey("AS", "vrel", 2, side="above")),
    ("AS/vrel@3", MonitorKey("AS", "vrel", 3, "boundary")),
    ("CC/wall@1", MonitorKey("CC", "wall", 1, "boundary")),
    ("GS/switch/4", MonitorKey("GS", "switch", 4)),
])
def test_a_key_and_its_string_form_are_one(text, key):
    assert str(key) == text
    assert MonitorKey.parse(text) == key
    assert key.kind in DIB_KINDS


@pytest.mark.parametrize("text", ["LP", "BEB/above", "GR/impact", "GR/impact@x", "XX/a/0"])
def test_a_text_that_names_no_monitor_is_refused(text):
    with pytest.raises(ValueError, match="monitor key"):
        MonitorKey.parse(text)


def test_the_monitors_of_an_orbit_carry_their_keys():
    from _orbit_cases import io_orbit

    prob, u, p = io_orbit("stable").problem()
    monitors = prob.dib_monitors(u, p)
    assert "GR/impact@0" in monitors
    for text, mon in monitors.items():
        assert str(mon.key) == text and MonitorKey.parse(text) == mon.key
        assert (mon.segment, mon.surface) == (mon.key.segment, mon.key.name)
