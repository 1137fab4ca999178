"""fwref/period.hpp: Stream::push's timestamp step decided against bounds formed once, no division,
held to the division it replaced by fwref_period on every edge (docs/firmware.md "Streaming")."""

from __future__ import annotations

import math
import subprocess

import pytest

from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)

USUAL = ["0.04", "0.01", "0.02", "0.1", "0.3333333333333333", "0.5", "1", "0x1p-10", "0.03999999910593033",
         "1e-300", "1e-310", "1e300"]  # the suite's period, its float32 value, binade edges, tiny, subnormal, huge
NO_FAST_PATH = ["1.7e308", "inf"]  # 1.5 * dt is not finite: every step takes the division


def _lines(exe, periods: list[str]) -> tuple[int, list[dict]]:
    res = subprocess.run([str(exe / "fwref_period"), *periods], capture_output=True, text=True, timeout=60)
    rows = [dict(kv.split("=", 1) for kv in line.split()) for line in res.stdout.splitlines()]
    return res.returncode, rows


def test_gate_equals_the_division_at_every_edge(host_build):  # noqa: F811
    rc, rows = _lines(host_build, USUAL + NO_FAST_PATH)
    assert rc == 0 and len(rows) == len(USUAL) + len(NO_FAST_PATH)
    for text, r in zip(USUAL + NO_FAST_PATH, rows):
        assert int(r["mismatches"]) == 0 and int(r["checked"]) > 60000, (text, r)
    for text, r in zip(USUAL, rows):
        # one period is [lo, hi), exactly the division's edges, around dt itself
        lo, hi, dt = float.fromhex(r["lo"]), float.fromhex(r["hi"]), float.fromhex(r["dt"])
        assert r["fast"] == "1" and r["tight"] == "1", (text, r)
        assert lo < dt < hi, (text, r)
        for bound, c in ((lo, 0.5), (hi, 1.5)):  # within 2 ulps of c * dt: the search starts there
            assert abs(bound - c * dt) <= 2 * math.ulp(c * dt), (text, r)
    for r in rows[len(USUAL):]:
        assert r["fast"] == "0" and r["lo"] == "nan"


def test_the_bounds_of_the_suite_period_by_hand(host_build):  # noqa: F811
    """dt = 0.04 s: lo = 0.02 (0.5 * dt is exact); hi is the first double whose quotient reaches 1.5."""
    rc, (r,) = _lines(host_build, ["0.04"])
    lo, hi = float.fromhex(r["lo"]), float.fromhex(r["hi"])
    assert rc == 0 and lo == 0.5 * 0.04
    down = lambda x: math.nextafter(x, -1.0)  # noqa: E731  one ulp below
    assert lo / 0.04 >= 0.5 and not down(lo) / 0.04 >= 0.5
    assert hi / 0.04 >= 1.5 and down(hi) / 0.04 < 1.5
    assert round(down(hi) / 0.04) == 1 and round(hi / 0.04) == 2  # 1 period just below hi, 2 (a gap) at hi


@pytest.mark.parametrize("arg", ["0", "-0.04", "nan", "x"])
def test_a_bad_period_is_one_line(host_build, arg):  # noqa: F811
    res = subprocess.run([str(host_build / "fwref_period"), arg], capture_output=True, text=True, timeout=10)
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and res.stdout == ""
