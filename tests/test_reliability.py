"""docs/reliability.md is the table ``benchmarks/reliability.py`` makes from its cases, and
the harness that makes it can tell a good outcome from a bad one."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))
import reliability  # noqa: E402
import reliability_cases as rc  # noqa: E402

#: A few cases of each group, run through the harness in the default test run.
SAMPLE = ("npz header claims 10^12 entries", "scene.json preset with an unknown key",
          "--set render.n_coarse=0", "mesh --out an existing folder", "render --split nosuch",
          "evt3: empty file", "OUT already holds other files", "turntable camera not 4x4",
          "resume beside a killed save's temporary files")


def test_the_table_lists_every_case_and_no_failure():
    text = reliability.DOC.read_text()
    cases = rc.all_cases()
    assert len(cases) >= 150
    assert len({c.what for c in cases}) == len(cases)
    for case in cases:
        assert f"| {case.what.replace('|', chr(92) + '|')} |" in text, \
            f"{case.what!r} is not in docs/reliability.md: rerun benchmarks/reliability.py"
    summary = re.search(r"\*\*(\d+) cases: (\d+) ok, 0 tracebacks, 0 silent accepts, 0 unclear, "
                        r"0 leftovers, 0 wrong\.\*\*", text)
    assert summary and int(summary[1]) == int(summary[2]) == len(cases)
    groups = {c.group for c in cases}
    assert {"dataset", "config", "run", "recording", "fault"} <= groups


def _case(expect: str = "error", sees: str = "") -> rc.Case:
    return rc.Case("test", "a case", lambda ws, d: [], expect, sees)


@pytest.mark.parametrize("code, err, new, expect, verdict", [
    (2, "error: data/x.npz: bad\n", set(), "error", "ok"),
    (1, "Traceback (most recent call last):\n  File ...\nValueError: x\n", set(), "error",
     "traceback"),
    (0, "", set(), "error", "silent"),
    (0, "all fine\n", set(), "warn", "silent"),
    (0, "warning: odd input\n", set(), "warn", "ok"),
    (2, "error: data/x.npz: bad\n", {"runs"}, "error", "leftover"),
    (0, "", {".m.123-ab.tmp.ply"}, "recover", "leftover"),
    (1, "error: data/x.npz: bad\n", set(), "error", "unclear"),
    (2, "error: something else\n", set(), "error", "unclear"),
])
def test_the_harness_judges_each_outcome(tmp_path, code, err, new, expect, verdict):
    sees = "odd" if expect == "warn" else "x.npz" if expect == "error" else ""
    assert reliability.judge(_case(expect, sees), code, "", err, new, tmp_path) == verdict


def test_a_sample_of_cases_passes_through_the_harness(tmp_path):
    ws = reliability.build_workspace(tmp_path / "good")
    cases = [c for c in rc.all_cases() if c.what in SAMPLE]
    assert len(cases) == len(SAMPLE)
    rows = [reliability.run_case(c, ws, tmp_path / "cases" / str(i))
            for i, c in enumerate(cases)]
    bad = [f"{r.what}: {r.verdict} ({r.message})" for r in rows if r.verdict != "ok"]
    assert not bad


@pytest.mark.slow
def test_every_case(tmp_path):
    done = subprocess.run([sys.executable, str(BENCH / "reliability.py"), "--allow-dirty",
                           "--doc", str(tmp_path / "reliability.md"), "--out",
                           str(tmp_path / "r.jsonl")], capture_output=True, text=True,
                          timeout=3600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "0 tracebacks, 0 silent accepts, 0 unclear, 0 leftovers, 0 wrong" in \
        (tmp_path / "reliability.md").read_text()
