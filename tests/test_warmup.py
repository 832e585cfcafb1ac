"""The first run after an install says it is compiling the kernels (what, how long) and
where it caches them; ``servo warmup`` compiles them all ahead, so the next command
compiles nothing.  Fresh caches in a temporary folder, real subprocesses."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def servo(*args, cache: Path):
    env = {**os.environ, "SERVO_NUMBA_CACHE": str(cache), "PYTHONPATH": str(ROOT)}
    env.pop("NUMBA_CACHE_DIR", None)
    return subprocess.run([sys.executable, "-m", "servo", *args], capture_output=True, text=True, env=env,
                          timeout=1200, cwd=ROOT)  # fmt: skip


@pytest.mark.slow
def test_a_cold_run_says_it_compiles_and_warmup_compiles_everything_ahead(tmp_path):
    cache = tmp_path / "cache"
    cold = servo("run", "--fast", "--duration", "0.01", "--compensation", "on", "--out", str(tmp_path / "r0"), cache=cache)
    assert cold.returncode == 0, cold.stderr
    lines = [x for x in cold.stderr.splitlines() if "kernels" in x]
    assert any(re.search(r"compiling the kernels .* s, now [\w.]+$", x) for x in lines), cold.stderr  # names the kernel
    assert f"cached in {cache}" in lines[-1]
    assert any(p.is_dir() for p in cache.iterdir())  # keyed folders where the user said

    warm = servo("warmup", cache=cache)
    assert warm.returncode == 0, warm.stderr
    first = warm.stdout.strip().splitlines()[-1]
    assert "compiled" in first and "loaded" in first and str(cache) in first
    again = servo("warmup", cache=cache)
    assert again.stdout.startswith("servo warmup: 0 kernels compiled, "), again.stdout
    assert int(again.stdout.split(", ")[1].split()[0]) >= 50  # every kernel loaded

    fresh = tmp_path / "fresh"  # warmup ahead, then a run compiles nothing
    assert servo("warmup", "--quiet", cache=fresh).returncode == 0
    run = servo("run", "--duration", "0.01", "--compensation", "on", "--out", str(tmp_path / "r1"), cache=fresh)
    assert run.returncode == 0 and "compiling" not in run.stderr, run.stderr
    assert json.loads((tmp_path / "r1" / "summary.json").read_text())["kernels_compiled"] is False


def test_importing_kernels_compiles_nothing():
    """A command compiles only the kernel modules it imports."""
    code = "import sys, kernels; assert 'numba' not in sys.modules; from kernels import plant_step; print(plant_step)"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
