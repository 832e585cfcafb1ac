"""The red-team round's kinds that need processes of their own: ``python -m studies.hostile_processes DIR``.

* **Ctrl-C mid-run**: each long command started as ``python -m servo ...`` and sent
  SIGINT after a drawn delay; it must end with exit 130 and ``servo: interrupted`` (or
  have finished, exit 0), leaving no ``OUT`` and no ``OUT.incomplete/`` unless that
  holds recorded data (a run's ``log_*`` files);
* **two writers to one output**: two processes given the same ``--out`` at once; one
  result, complete, and the other refused in one line (or both refused);
* **fleets**: identical bytes under several names, one name in two folders, a file given
  twice, a file renamed or changed in place between a run and its ``--resume``,
  ``--resume`` with each option that shapes a row changed, a resume folder that is not
  a fleet's, a manifest naming missing, duplicate and foreign files; each row checked
  against a fresh run's (nothing lost, nothing stale);
* **the board**: the emulator (and the firmware's host build, with a C compiler)
  started with hostile configs, and ``servo run --port`` against it with a config that
  differs, a port that is not a board, a board that never answers.

Prints a count per kind and outcome and each finding (see :mod:`studies.hostile_round`).
"""
from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from studies.hostile_round import FINDINGS, TRIED, _good, _write, check, run_steps

ENV = {**os.environ, "PYTHONPATH": os.getcwd(), "MPLBACKEND": "Agg"}


def servo(*argv, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "servo", *map(str, argv)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=ENV, **kw)  # fmt: skip


def _left(out: Path) -> str:
    """What a stopped command left in the place of ``out``: '' when nothing unrecorded."""
    inc = out.with_name(out.name + ".incomplete")
    done = ("summary.json", "fleet.parquet", "report.json", "truth.json")  # (a synthetic fleet's last file: truth.json)
    if out.exists() and not any((out / f).exists() for f in done):
        return f"{out.name}/ without its summary: {sorted(p.name for p in out.iterdir())[:6]}"
    if inc.exists() and not any(p.name.startswith("log_") for p in inc.iterdir()):
        return f"{inc.name}/ holding {sorted(p.name for p in inc.iterdir())[:6]}"
    return ""


def interrupts(root: Path, rec: Path, journal: Path, fleet: Path):
    """SIGINT at 3, 8 and 15 s after the start of each long command."""
    commands = {
        "run (tick)": ["run", "--duration", "3", "--quiet"],
        "run (fast)": ["run", "--duration", "30", "--fast", "--quiet"],
        "identify": ["identify", rec, "--quiet"],
        "diagnose": ["diagnose", rec, "--quiet"],
        "frf": ["frf", rec, "--quiet"],
        "bode": ["bode", "--quiet"],
        "loop": ["loop", "--quiet"],
        "hysteresis": ["hysteresis", "--simulate", "--quiet"],
        "recover": ["recover", journal],
        "fleet synthetic": ["fleet", "synthetic", "--drives", "30", "--quiet"],
        "fleet identify": ["fleet", "identify", str(fleet / "*.npz"), "--workers", "0", "--quiet"],
    }
    n = 0
    for name, argv in commands.items():
        for delay in (3.0, 8.0, 15.0):
            n += 1
            out = root / f"sigint{n}"
            args = list(argv) + ([] if name == "recover" else ["--out", out])
            before = {p.name for p in journal.parent.iterdir()} if name == "recover" else None
            p = servo(*args)
            time.sleep(delay)
            p.send_signal(signal.SIGINT)
            try:
                _, err = p.communicate(timeout=120)
            except subprocess.TimeoutExpired:
                p.kill()
                _, err = p.communicate()
                err += "\n(no exit within 120 s of SIGINT)"
            lines = err.strip().split("\n") if err.strip() else []
            problems = []
            if p.returncode == 130:
                if len(lines) != 1 or not lines[0].startswith("servo: interrupted"):
                    problems.append(f"{len(lines)} lines: {err.strip()[-300:]}")
                outcome = "interrupted (exit 130)"
            elif p.returncode == 0:
                outcome = "finished before the signal"
            else:
                problems.append(f"exit {p.returncode}: {err.strip()[-300:]}")
                outcome = "BUG"
            if name == "recover":
                after = {q.name for q in journal.parent.iterdir()}
                new = sorted(after - before)
                if p.returncode == 130 and new:
                    problems.append(f"left {new}")
                if journal.name not in after:
                    problems.append("the journal is gone")
                for q in new:  # a finished recover: start again from the journal alone
                    (journal.parent / q).unlink()
            else:
                left = _left(out)
                if left:
                    problems.append(left)
            if problems:
                outcome = "BUG"
                FINDINGS.append(f"Ctrl-C after {delay:g} s: {name}: {'; '.join(problems)}")
            TRIED["Ctrl-C mid-run", outcome] += 1


def two_writers(root: Path, rec: Path):
    commands = {
        "run": ["run", "--duration", "0.5", "--fast", "--quiet"],
        "identify": ["identify", rec, "--quiet"],
        "diagnose": ["diagnose", rec, "--quiet", "--no-plots"],
        "fleet synthetic": ["fleet", "synthetic", "--drives", "4", "--duration", "0.2", "--quiet"],
    }
    for name, argv in commands.items():
        out = root / f"two-{name.replace(' ', '-')}"
        a, b = servo(*argv, "--out", out), servo(*argv, "--out", out)
        ra, rb = a.communicate(timeout=600), b.communicate(timeout=600)
        codes = sorted([a.returncode, b.returncode])
        errs = [r[1].strip() for r, p in ((ra, a), (rb, b)) if p.returncode != 0]
        problems = []
        if codes not in ([0, 2], [2, 2]):
            problems.append(f"exits {codes}: {errs}")
        if any(e.count("\n") for e in errs):
            problems.append(f"an error of several lines: {errs}")
        if codes == [0, 2] and _left(out):
            problems.append(_left(out))
        if out.with_name(out.name + ".incomplete").exists():
            problems.append(".incomplete left")
        outcome = "BUG" if problems else ("one result, one refused" if codes == [0, 2] else "both refused")
        if problems:
            FINDINGS.append(f"two writers: {name}: {'; '.join(problems)}")
        TRIED["two writers to one --out", outcome] += 1


# -- fleets ----------------------------------------------------------------------------


def _rows(out: Path) -> list[dict]:
    import pyarrow.parquet as pq

    return pq.read_table(out / "fleet.parquet").to_pylist()


def _fleet(kind: str, argv: list, out: Path, expect: str = "result", label: str = ""):
    full = ["fleet", kind, *argv, "--workers", "0", "--no-plots", "--quiet", "--out", out]
    outcome = check(f"fleet {kind}", full, out, label=label)
    if expect == "error" and outcome == "result":
        TRIED[f"fleet {kind}", "ACCEPTED?"] += 1
        FINDINGS.append(f"fleet {kind} [{label}]: accepted")
    return outcome


def fleets(root: Path):
    from servo.fleet.synthetic import synthetic_drives, write_fleet

    src = root / "fleet-src"
    write_fleet(src, synthetic_drives(4, 0, seed=3), duration_s=0.3)
    files = sorted(src.glob("*.npz"))
    n = [0]

    def out():
        n[0] += 1
        return root / f"fleet{n[0]}"

    def same_rows(a: list[dict], b: list[dict], what: str):
        keys = ("J", "B", "Fc", "K", "h0")
        if len(a) != len(b):
            FINDINGS.append(f"fleet [{what}]: {len(a)} rows against a fresh run's {len(b)}")
            TRIED["fleet rows", "BUG: lost or extra"] += 1
            return
        for ra, rb in zip(a, b):
            if ra.get("drive") != rb.get("drive") or any(
                    not (ra.get(k) == rb.get(k) or (ra.get(k) is not None and rb.get(k) is not None
                                                    and np.isclose(ra[k], rb[k], rtol=1e-9))) for k in keys):  # fmt: skip
                FINDINGS.append(f"fleet [{what}]: row {ra.get('drive')} differs from a fresh run's {rb.get('drive')}")
                TRIED["fleet rows", "BUG: stale"] += 1
                return
        TRIED["fleet rows", "equal to a fresh run's"] += 1

    # identical bytes, one name in two folders, a file twice
    dup = root / "fleet-dup"
    (dup / "a").mkdir(parents=True)
    (dup / "b").mkdir()
    for name in ("alpha", "bravo"):
        (dup / f"{name}.npz").write_bytes(files[0].read_bytes())
    (dup / "a" / "drive.npz").write_bytes(files[1].read_bytes())
    (dup / "b" / "drive.npz").write_bytes(files[2].read_bytes())
    o = out()
    if _fleet("identify", [dup / "*.npz", dup / "a" / "drive.npz", dup / "b" / "drive.npz"], o, label="same bytes, same names") == "result":
        rows = _rows(o)
        names = [r["drive"] for r in rows]
        sources = [r.get("source") for r in rows]
        if len(set(sources)) != len(sources) or len(rows) != 4:
            FINDINGS.append(f"fleet [same names]: rows {names} from {sources}")
            TRIED["fleet rows", "BUG: lost or extra"] += 1
        elif len(set(names)) != len(names):
            FINDINGS.append(f"fleet [same names]: two rows named alike: {names} (read it)")
            TRIED["fleet rows", "two drives of one name"] += 1
        else:
            TRIED["fleet rows", "one row per path"] += 1
    o = out()
    if _fleet("identify", [files[0], files[0], files[1]], o, label="a file given twice") == "result":
        rows = _rows(o)
        FINDINGS.append(f"fleet [a file given twice]: {len(rows)} rows: {[r['drive'] for r in rows]} (read it)")

    # resume: a base run, then each change
    work = root / "fleet-work"
    work.mkdir()
    for f in files:
        (work / f.name).write_bytes(f.read_bytes())
    base = out()
    _fleet("identify", [work / "*.npz"], base, label="base")
    for label, extra in [("--off K", ["--off", "K"]), ("--terms J,B,Fc", ["--terms", "J,B,Fc"]), ("--decimate 5", ["--decimate", "5"]),
                         ("--cutoff-hz 500", ["--cutoff-hz", "500"]), ("--path paper", ["--path", "paper"]),
                         ("--force-lag 1e-4", ["--force-lag", "1e-4"]), ("--scale u=2", ["--scale", "u=2"]),
                         ("--columns t=t,u=u,x=x", ["--columns", "t=t,u=u,x=x"])]:  # fmt: skip
        o, fresh = out(), out()
        _fleet("identify", [work / "*.npz", *extra, "--resume", base], o, label=f"resume {label}")
        _fleet("identify", [work / "*.npz", *extra], fresh, label=f"fresh {label}")
        if o.exists() and fresh.exists():
            same_rows(_rows(o), _rows(fresh), f"resume with {label}")
    # a file renamed, one changed in place, one removed, one added
    (work / files[1].name).rename(work / "renamed.npz")
    from servo.fleet.synthetic import synthetic_drives as sd

    write_fleet(root / "fleet-other", sd(2, 0, seed=11), duration_s=0.3)
    other = sorted((root / "fleet-other").glob("*.npz"))
    (work / files[2].name).write_bytes(other[0].read_bytes())  # changed in place
    (work / files[3].name).unlink()
    (work / "added.npz").write_bytes(other[1].read_bytes())
    o, fresh = out(), out()
    _fleet("identify", [work / "*.npz", "--resume", base], o, label="resume after rename/change/remove/add")
    _fleet("identify", [work / "*.npz"], fresh, label="fresh after rename/change/remove/add")
    if o.exists() and fresh.exists():
        same_rows(_rows(o), _rows(fresh), "resume after a rename, a change, a removal, an addition")
    # resume folders that are not a fleet's
    (root / "not-a-fleet").mkdir()
    (root / "not-a-fleet" / "fleet.json").write_text("[1, 2")
    for label, resume in [("missing", root / "nope"), ("a file", files[0]), ("an empty folder", root / "fleet-dup" / "a"),
                          ("a corrupt fleet.json", root / "not-a-fleet"), ("its own --out", None)]:  # fmt: skip
        o = out()
        _fleet("identify", [work / "*.npz", "--resume", resume if resume is not None else o], o, expect="error", label=f"resume from {label}")
    # manifests
    for label, text in [("a missing file", f"path\n{root / 'nope.npz'}\n"), ("a folder", f"path\n{work}\n"),
                        ("the same path twice", f"path\n{files[0]}\n{files[0]}\n"), ("no path column", "file\nx.npz\n"),
                        ("a CSV that is not one", "\x00\x01\x02"), ("empty", ""), ("header only", "path\n"),
                        ("bad columns", f"path,columns\n{files[0]},u==x\n"), ("bad scale", f"path,scale\n{files[0]},u=nan\n"),
                        ("a journal", f"path\n{root / 'x.journal'}\n"), ("relative to the manifest", "path\n../fleet-src/" + files[0].name + "\n")]:  # fmt: skip
        m = root / f"manifest{n[0]}" / "m.csv"
        m.parent.mkdir()
        m.write_text(text)
        _fleet("identify", ["--manifest", m], out(), label=f"manifest: {label}")
    # fleet simulate / synthetic / diagnose options
    for argv in (["synthetic", "--drives", "0"], ["synthetic", "--drives", "-1"], ["synthetic", "--drives", "2", "--defects", "5"],
                 ["synthetic", "--drives", "2", "--duration", "0"], ["synthetic", "--drives", "2", "--duration", "nan"],
                 ["synthetic", "--drives", "2", "--duration", "1e-6"], ["synthetic", "--drives", "2", "--seed", "-1"],
                 ["simulate", "--drives", "0"], ["simulate", "--drives", "2", "--duration", "0"],
                 ["simulate", "--drives", "2", "--duration", "nan"]):  # fmt: skip
        o = out()
        extra = [] if argv[0] == "synthetic" else ["--workers", "0", "--no-plots"]
        check(f"fleet {argv[0]}", ["fleet", *argv, "--quiet", "--out", o, *extra], o, label=" ".join(argv[1:]))
    o = out()
    _fleet("diagnose", [work / "*.npz", "--blocks", "4"], o, label="diagnose")
    for label, extra in [("--blocks 3", ["--blocks", "3"]), ("--alpha 0.01", ["--alpha", "0.01"]), ("--baseline J,B,Fc", ["--baseline", "J,B,Fc"])]:
        r, fresh = out(), out()
        _fleet("diagnose", [work / "*.npz", "--blocks", "4", *extra, "--resume", o], r, label=f"diagnose resume {label}")
        _fleet("diagnose", [work / "*.npz", "--blocks", "4", *extra], fresh, label=f"diagnose fresh {label}")
        if r.exists() and fresh.exists():
            a, b = _rows(r), _rows(fresh)
            key = [k for k in a[0] if k.startswith("verdict") or k in ("drive", "found")] if a else []
            if [[x.get(k) for k in key] for x in a] != [[x.get(k) for k in key] for x in b]:
                FINDINGS.append(f"fleet diagnose resume with {label}: rows differ from a fresh run's")
                TRIED["fleet rows", "BUG: stale"] += 1
            else:
                TRIED["fleet rows", "equal to a fresh run's"] += 1


# -- the board -------------------------------------------------------------------------


def _emulator(*sets: str, sessions: int = 1):
    argv = ["emulate", "--tcp", "0", "--sessions", str(sessions)] + [a for s in sets for a in ("--set", s)]
    p = servo(*argv)
    deadline = time.time() + 120
    line = ""
    while time.time() < deadline:
        line = p.stdout.readline()
        if not line or "socket://" in line:
            break
    if "socket://" not in line:
        p.kill()
        out, err = p.communicate()
        return p, None, (line + out + err).strip()
    url = "socket://" + line.split("socket://")[1].split()[0].rstrip(".,;")
    return p, url, ""


def boards(root: Path):
    # the emulator with hostile configs: it must start or refuse in one line
    for sets in (["run.sample_rate_hz=nan"], ["drive.J=-1"], ["link.watchdog_s=1e9"], ["link.ready_timeout_s=0"],
                 ["link.baudrate=0"], ["run.duration_s=1e9"], ["drive.position_quantum=1e-300"]):  # fmt: skip
        p, url, err = _emulator(*sets)
        if url is None:
            lines = err.split("\n")
            ok = p.returncode == 2 and len(lines) == 1 and lines[0].startswith("servo: error:")
            TRIED["emulate, hostile config", "error (one line)" if ok else "BUG"] += 1
            if not ok:
                FINDINGS.append(f"emulate {sets}: exit {p.returncode}: {err[-300:]}")
        else:
            p.kill()
            p.communicate()
            TRIED["emulate, hostile config", "started"] += 1
            FINDINGS.append(f"emulate {sets}: started (read it)")
    # run --port against the emulator with a config that differs, and against a board that is not one
    cases = [("same config", [], []), ("other sample rate", [], ["run.sample_rate_hz=40000"]),
             ("other drive", [], ["drive.J=2e-3"]), ("other controller", [], ["controller.kind='track'"]),
             ("other latency", [], ["link.command_latency_ticks=3"]), ("host watchdog 1 ms", [], ["link.watchdog_s=0.001"]),
             ("host timeout 1 ms", [], ["link.timeout_s=0.001"])]  # fmt: skip
    for label, emu_sets, host_sets in cases:
        p, url, err = _emulator(*emu_sets, sessions=2)  # (a run compares: two sessions)
        if url is None:
            FINDINGS.append(f"emulator did not start: {err[-300:]}")
            continue
        o = root / f"port-{label.replace(' ', '-')}"
        argv = ["run", "--port", url, "--duration", "0.2", "--quiet", "--log-format", "npz", "--out", o]
        argv += [a for s in host_sets for a in ("--set", s)]
        check("run --port (emulator)", argv, o, label=label)
        try:
            p.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            p.kill()
            p.communicate()
            FINDINGS.append(f"emulator after {label}: still running 30 s after its one session")
    # ports that are not a board
    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen()
    banner = socket.socket()
    banner.bind(("127.0.0.1", 0))
    banner.listen()

    def chatter():
        while True:
            try:
                c, _ = banner.accept()
            except OSError:
                return
            try:
                c.sendall(b"SSH-2.0-OpenSSH_9.6\r\n" + bytes(range(256)) * 64)
            except OSError:
                pass

    threading.Thread(target=chatter, daemon=True).start()
    for label, url in [("nothing listening", "socket://127.0.0.1:1"), ("a silent listener", f"socket://127.0.0.1:{silent.getsockname()[1]}"),
                       ("a chattering listener", f"socket://127.0.0.1:{banner.getsockname()[1]}"),
                       ("not a URL", "::::"), ("a file", str(root)), ("/dev/null", "/dev/null"), ("an unknown scheme", "gopher://x")]:  # fmt: skip
        o = root / f"port-{label.replace(' ', '-')}"
        t0 = time.time()
        check("run --port (not a board)", ["run", "--port", url, "--duration", "0.2", "--quiet", "--out", o,
                                           "--set", "link.timeout_s=2"], o, label=label)  # fmt: skip
        if time.time() - t0 > 60:
            FINDINGS.append(f"run --port {label}: {time.time() - t0:.0f} s to answer")
    silent.close()
    banner.close()
    # the firmware's host build
    try:
        from hil.firmware import build_host, find_cc, serve_host
        from servo.config import Config
    except ImportError as exc:
        FINDINGS.append(f"firmware: {exc}")
        return
    if find_cc() is None:
        FINDINGS.append("firmware: no C compiler, not tried")
        return
    from hil.firmware import comparable

    cfg = comparable(Config())
    (root / "fw").mkdir(exist_ok=True)
    exe = build_host(cfg, root / "fw")
    for label, host_sets in [("same config", ["drive.position_noise=0", "drive.velocity_noise=0", "scenario.disturbance_amplitude=0"]),
                             ("other sample rate", ["run.sample_rate_hz=40000"]), ("host watchdog 1 ms", ["link.watchdog_s=0.001"]),
                             ("other drive", ["drive.J=2e-3"])]:  # fmt: skip
        with serve_host(exe) as (proc, port):
            o = root / f"fw-{label.replace(' ', '-')}"
            argv = ["run", "--port", port, "--duration", "0.1", "--quiet", "--log-format", "npz", "--out", o]
            check("run --port (firmware host)", argv + [a for s in host_sets for a in ("--set", s)], o, label=label)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("root", type=Path)
    ap.add_argument("--only", default="fleets,boards,writers,interrupts")
    a = ap.parse_args(argv)
    a.root.mkdir(parents=True, exist_ok=True)
    g = _good(200_000)
    rec = _write(a.root / "long.npz", g)
    journal = a.root / "j" / "log.journal"
    journal.parent.mkdir(exist_ok=True)
    import json

    journal.write_bytes((json.dumps({"columns": ["t", "x", "u"], "units": {}, "meta": {}}) + "\n").encode()
                        + np.random.default_rng(0).standard_normal(3 * 3_000_000).tobytes())  # fmt: skip
    fleet = a.root / "syn"
    from servo.fleet.synthetic import synthetic_drives, write_fleet

    write_fleet(fleet, synthetic_drives(12, 1, seed=2), duration_s=1.0)
    steps = {"fleets": lambda: fleets(a.root), "boards": lambda: boards(a.root), "writers": lambda: two_writers(a.root, rec),
             "interrupts": lambda: interrupts(a.root, rec, journal, fleet)}  # fmt: skip
    run_steps(steps, a.only)
    return 0


if __name__ == "__main__":
    sys.exit(main())
