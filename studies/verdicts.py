"""Verdicts of two sets of diagnoses of the same recordings, tabulated before/after.

    python -m studies.verdicts BEFORE/diagnoses AFTER/diagnoses [--changed]

The folders hold one ``report.json`` per recording, named ``FAMILY-SIZE-SEED.json``
(what ``python -m studies.identity dump`` writes).  Per family: the verdicts before and
after and how many moved; the recordings whose verdict or named physics changed; and
the changes that count as worse, by the proving ground's rules
(:mod:`studies.proving.cases`): a finding that appears on a ``null``, a right name
(:func:`~studies.proving.cases.accepted`) that is lost, a wrong name that appears, a
verdict that leaves the family's right verdicts.  Exit status 1 when any change is worse.
"""
from __future__ import annotations

import argparse
import json
import sys
from collections import Counter, defaultdict
from pathlib import Path

from studies.proving.cases import FAMILIES, accepted


def _read(path: Path) -> dict:
    d = json.loads(path.read_text())
    if "error" in d:
        return {"verdict": "error: " + d["error"].split(":")[0], "names": (), "decimate": None}
    names = tuple(sorted(f["physics"] for f in d.get("findings", [])))
    dec = (d.get("settings") or {}).get("decimate")
    return {"verdict": d.get("verdict"), "names": names, "decimate": dec}


def _family(stem: str) -> tuple[str, float]:
    fam, size, _seed = stem.rsplit("-", 2) if stem.count("-") >= 2 else (stem, "0", "0")
    return fam, float(size)


def worse(family: str, size: float, a: dict, b: dict) -> list[str]:
    """Why the change from ``a`` to ``b`` (``_read`` records) is worse, if it is."""
    why = []
    if family not in FAMILIES:
        return why
    right = set(accepted(family, size, b["decimate"] or a["decimate"]))
    if family == "null" and b["names"] and not a["names"]:
        why.append(f"a finding on a null: {', '.join(b['names'])}")
    lost = right & (set(a["names"]) - set(b["names"]))
    if lost:
        why.append(f"lost the right name {', '.join(sorted(lost))}")
    wrong = (set(b["names"]) - set(a["names"])) - right
    if wrong and family != "null":
        why.append(f"a wrong name appears: {', '.join(sorted(wrong))}")
    ok = set(FAMILIES[family].verdict)
    if a["verdict"] in ok and b["verdict"] not in ok:
        why.append(f"verdict {a['verdict']} -> {b['verdict']} leaves the right ones ({', '.join(sorted(ok))})")
    return why


def tabulate(before: Path, after: Path, changed_only: bool = False) -> tuple[str, int]:
    rows, per_fam, bad = [], defaultdict(lambda: [Counter(), Counter(), 0, 0]), 0
    for fa in sorted(before.glob("*.json")):
        fb = after / fa.name
        if not fb.exists():
            rows.append(f"  {fa.stem}: missing after")
            continue
        a, b = _read(fa), _read(fb)
        fam, size = _family(fa.stem)
        t = per_fam[fam]
        t[0][a["verdict"]] += 1
        t[1][b["verdict"]] += 1
        t[2] += 1
        moved = a["verdict"] != b["verdict"] or a["names"] != b["names"]
        t[3] += moved
        why = worse(fam, size, a, b)
        bad += bool(why)
        if moved or not changed_only and why:
            rows.append(f"  {fa.stem}: {a['verdict']} [{', '.join(a['names']) or '-'}] -> {b['verdict']} "
                        f"[{', '.join(b['names']) or '-'}]" + (f"  WORSE: {'; '.join(why)}" if why else ""))  # fmt: skip
    fmt = lambda c: ", ".join(f"{k} {v}" for k, v in sorted(c.items()))  # noqa: E731
    out = [f"{'family':<18} {'n':>4} {'moved':>5}  verdicts before | after"]
    for fam in sorted(per_fam):
        c0, c1, n, m = per_fam[fam]
        out.append(f"{fam:<18} {n:>4} {m:>5}  {fmt(c0)} | {fmt(c1)}")
    tot = sum(t[2] for t in per_fam.values())
    mv = sum(t[3] for t in per_fam.values())
    out.append(f"{'all':<18} {tot:>4} {mv:>5}  recordings whose verdict or named physics changed; worse: {bad}")
    out.append("changes:" if rows else "changes: none")
    return "\n".join(out + rows), bad


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m studies.verdicts", description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--changed", action="store_true", help="list only the recordings that changed")
    a = ap.parse_args(argv)
    text, bad = tabulate(a.before, a.after, a.changed)
    print(text)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
