"""Seeded fuzzing of the surfaces issue 48's hardening covers (tests/fuzz_surfaces.py,
in a child process so that a crash names its case): batches locally and on Dask,
continuation, States, order-k runs, declarations and the command line.

Zero raw exceptions (every refusal a ValueError, TypeError or MemoryError with a message,
or the command line's exit 2 with one line before any compile) and zero false successes:
every SUCCESS is checked against an independent solution of the same discrete equations
(a recurrence or a linear solve in NumPy, or the exact cubic).
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

CASES = 240
CHILD = Path(__file__).with_name("fuzz_surfaces.py")


@pytest.mark.parametrize("seed", [20261128])
def test_fuzzed_surfaces_never_crash_or_succeed_falsely(compiled, build_dir, tmp_path, seed):
    for name in ("harmonic_oscillator", "minimum_jerk", "cubic_spline"):
        compiled(name)
    proc = subprocess.run([sys.executable, str(CHILD), str(build_dir), str(CASES), str(seed),
                           str(tmp_path)], capture_output=True, text=True, timeout=600,
                          cwd=tmp_path)
    lines = proc.stdout.strip().splitlines()
    last = lines[-1] if lines else ""
    assert proc.returncode == 0, f"last case: {last}\n{proc.stderr[-4000:]}"
    summary = json.loads(last.removeprefix("SUMMARY "))
    print(f"\nfuzz: {summary}")
    # the mix reaches every outcome, and the successes were verified, not just counted
    assert min(summary["failure"], summary["refused"], summary["verified"]) >= 10, summary
    assert sum(summary[k] for k in ("success", "failure", "refused")) == CASES
