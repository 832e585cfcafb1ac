"""Provenance: ``servo --version``, and what every job's summary records (package and
library versions, command line, config hash, input hashes, CPU)."""
from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import numba
import numpy as np
import scipy

import servo
from servo.cli import main
from servo.config import Config, load_config
from servo.io.provenance import config_hash, cpu_model, provenance
from servo.io.recording import Recording, save_recording_csv


def test_version_option():
    r = subprocess.run([sys.executable, "-m", "servo", "--version"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == f"servo {servo.__version__}"


def test_provenance_records_versions_config_inputs_and_cpu(tmp_path):
    data = tmp_path / "in.bin"
    data.write_bytes(b"abc" * 1000)
    p = provenance(Config(), [data], ["servo", "x", "--y"])
    assert p["servo_version"] == servo.__version__ and p["command"] == ["servo", "x", "--y"]
    assert p["inputs"] == {str(data): hashlib.sha256(b"abc" * 1000).hexdigest()}
    libs = p["libraries"]
    assert libs["numpy"] == np.__version__ and libs["numba"] == numba.__version__ and libs["scipy"] == scipy.__version__
    assert libs["control"] is not None and p["python"].endswith(sys.version.split()[0])
    assert p["cpu"] and p["created_utc"].endswith("Z")
    json.dumps(p, allow_nan=False)  # strict JSON as it is


def test_config_hash_is_of_the_config_not_of_how_it_was_given(tmp_path):
    f = tmp_path / "c.toml"
    f.write_text("[drive]\nJ = 0.001\n")  # the default value, given explicitly
    assert config_hash(load_config(f)) == config_hash(Config())
    f.write_text("[drive]\nJ = 0.002\n")
    assert config_hash(load_config(f)) != config_hash(Config())


def test_cpu_model_from_cpuinfo(tmp_path):
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nvendor_id\t: X\nmodel name\t: Example CPU 9000 @ 3.0GHz\n\nprocessor\t: 1\n")
    assert cpu_model(info) == "Example CPU 9000 @ 3.0GHz"
    assert cpu_model(tmp_path / "missing")  # falls back to platform, never empty


def test_identify_frf_and_diagnose_summaries_carry_it(tmp_path, capsys):
    rng = np.random.default_rng(0)
    t = np.arange(6000) * 1e-3
    x = 1e-3 * np.sin(2 * np.pi * 1.3 * t) + 3e-4 * np.sin(2 * np.pi * 4.1 * t)
    v, a = np.gradient(x, t), np.gradient(np.gradient(x, t), t)
    u = 0.5 * a + 2.0 * v + 0.3 * np.sign(v) + 1e-3 * rng.standard_normal(t.size)
    rec = tmp_path / "rec.csv"
    save_recording_csv(rec, Recording(t, u, x))
    digest = hashlib.sha256(rec.read_bytes()).hexdigest()
    for argv, name in ((["identify", str(rec), "--terms", "J,B,Fc"], "summary.json"),
                       (["frf", str(rec)], "summary.json"),
                       (["diagnose", str(rec), "--baseline", "J,B", "--no-plots"], "report.json")):  # fmt: skip
        out = tmp_path / argv[0]
        assert main(argv + ["--out", str(out)]) == 0
        prov = json.loads((out / name).read_text())["provenance"]
        assert prov["command"] == ["servo", *argv, "--out", str(out)]
        assert prov["inputs"] == {str(rec): digest}
        assert prov["libraries"]["numpy"] == np.__version__
    capsys.readouterr()


def test_the_version_and_commit_come_from_git_in_a_checkout():
    """The version was a static 0.1.0 and no output named the commit."""
    from servo._version import source_revision

    root = Path(servo.__file__).resolve().parents[1]
    head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
    rev = source_revision()
    assert rev["from"] == "checkout" and rev["commit"] == head and isinstance(rev["dirty"], bool)
    assert f"+g{head[:12]}" in servo.__version__
    p = provenance()
    assert p["source"]["commit"] == head and p["servo_version"] == servo.__version__
    for lib in ("dask", "distributed", "pyarrow", "pyserial", "numba", "scipy", "control"):
        assert p["libraries"][lib] == metadata.version(lib)


def test_without_git_the_version_is_the_fallback(monkeypatch):
    from servo import _version as prov

    monkeypatch.setattr(prov, "_git", lambda *a: None)
    monkeypatch.setattr(prov, "_installed", lambda: None)
    assert prov.package_version() == prov.FALLBACK_VERSION
    assert prov.source_revision() == {"commit": None, "dirty": None, "from": "unknown"}


def test_a_run_started_from_python_records_its_provenance(tmp_path):
    """run_job called from Python wrote "provenance": null."""
    from servo.run.job import run_job

    s = run_job(Config().replace(run={"duration_s": 0.01}), tmp_path / "r", compensation="on", fast=True,
                log_formats=("npz",))  # fmt: skip
    on_disk = json.loads((tmp_path / "r" / "summary.json").read_text())["provenance"]
    assert s["provenance"] == on_disk and on_disk["source"]["commit"] and on_disk["config_sha256"] == config_hash(
        Config().replace(run={"duration_s": 0.01}))
    assert on_disk["libraries"]["pyarrow"] == metadata.version("pyarrow")


def test_schema_metadata_carries_provenance_and_units_into_parquet(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    from servo.io.provenance import schema_metadata

    p = provenance(Config())
    t = pa.table({"J": [1e-3]}, schema=pa.schema([("J", pa.float64())], metadata=schema_metadata(p, {"J": "A*s^2/m"})))
    pq.write_table(t, tmp_path / "t.parquet")
    md = pq.read_schema(tmp_path / "t.parquet").metadata
    assert json.loads(md[b"servo.provenance"]) == json.loads(json.dumps(p))
    assert json.loads(md[b"servo.units"]) == {"J": "A*s^2/m"}
