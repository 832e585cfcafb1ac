"""The kernels' on-disk cache is keyed by their source, so an edit recompiles them all."""
import pytest
import shutil
from pathlib import Path

from kernels import _cache
from servo.controllers.pi import pi_tick


def test_any_kernel_edit_changes_the_cache_directory(tmp_path):
    folders = (_cache.HERE, Path(pi_tick.py_func.__code__.co_filename).parent)  # kernels/, a controller kind's
    copies = []
    for i, folder in enumerate(folders):
        (tmp_path / str(i)).mkdir()
        for f in folder.glob("*.py"):
            shutil.copy(f, tmp_path / str(i) / f.name)
        copies.append(tmp_path / str(i))
    before = _cache.source_hash(copies)
    assert before == _cache.source_hash(folders)
    dahl = copies[0] / "dahl.py"
    dahl.write_text(dahl.read_text().replace("math.exp(-sigma * xi / Ha)", "math.exp(-sigma * xi / Ha) * 1.0"))
    edited = _cache.source_hash(copies)
    assert edited != before
    pi = copies[1] / "pi.py"
    pi.write_text(pi.read_text().replace("e_p = (r_base + p.b * r) - x", "e_p = (r_base + p.b * r) - x + 0.0"))
    assert _cache.source_hash(copies) != edited


def test_numba_caches_into_the_keyed_directory_and_its_configuration_is_left_alone():
    import subprocess
    import sys

    from kernels.dahl import dahl_update

    # each kernel under the hash of kernels/ and of the folder that declares it
    assert dahl_update.stats.cache_path.startswith(str(_cache.cache_dir()))
    controllers = Path(pi_tick.py_func.__code__.co_filename).parent
    assert pi_tick.stats.cache_path.startswith(str(_cache.cache_dir(controllers)))
    assert _cache.cache_dir(controllers) != _cache.cache_dir()
    code = ("from numba.core import config; before = config.CACHE_DIR; import kernels, servo.run.job, "
            "servo.runtime.controller as c, servo.config as s; c.Controller(s.Config()); "
            "assert config.CACHE_DIR == before, config.CACHE_DIR")  # fmt: skip
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


@pytest.mark.slow
def test_the_first_run_says_it_compiled_the_kernels_and_the_second_that_it_loaded_them(tmp_path):
    """Issue 12.6: the first run after an install said "cached kernels" while it compiled."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "SERVO_NUMBA_CACHE": str(tmp_path / "cache")}
    env.pop("NUMBA_CACHE_DIR", None)
    said = []
    for i in range(2):
        r = subprocess.run([sys.executable, "-m", "servo", "run", "--duration", "0.01", "--fast", "--compensation", "on",
                            "--out", str(tmp_path / f"r{i}")], capture_output=True, text=True, env=env)  # fmt: skip
        assert r.returncode == 0, r.stderr
        said.append(next(line for line in r.stdout.splitlines() if "startup:" in line))
    assert "compiling the kernels" in said[0] and "cached kernels" in said[1]
