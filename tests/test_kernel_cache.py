"""The kernels' on-disk cache is keyed by their source, so an edit recompiles them all."""
import shutil

from numba.core import config

from kernels import _cache


def test_any_kernel_edit_changes_the_cache_directory(tmp_path):
    for f in _cache.HERE.glob("*.py"):
        shutil.copy(f, tmp_path / f.name)
    before = _cache.source_hash(tmp_path)
    assert before == _cache.source_hash()
    dahl = tmp_path / "dahl.py"
    dahl.write_text(dahl.read_text().replace("math.exp(-sigma * xi / Ha)", "math.exp(-sigma * xi / Ha) * 1.0"))
    assert _cache.source_hash(tmp_path) != before


def test_numba_caches_into_the_keyed_directory():
    assert config.CACHE_DIR == str(_cache.cache_dir())
    assert config.CACHE_DIR.endswith(_cache.source_hash())
