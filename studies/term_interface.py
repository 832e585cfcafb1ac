"""How large a diagnosis term's interface is, and who uses each part of it.

    python -m studies.term_interface            # the tables; --json for the numbers

For :class:`servo.physics.base.Term` and every term of the vocabulary
(:data:`servo.physics.VOCABULARY`) this counts

* ``required``: the public attributes on ``Term`` itself that are not capabilities (what
  every term is: a feature library's name, doc, units, coefficients and parameters,
  columns, grid and bounds, with the derived ``rows``, ``physical``, ``from_physical``);
* ``capabilities``: the attributes of ``Term`` that hold a capability object
  (:class:`servo.physics.base.Capability`, when the tree has one), with the members each
  has.  In a tree without capability objects every hook is on ``Term`` and counts as
  required;
* per term, its ``overrides``: the required attributes its class sets differently from
  ``Term``, and the capability members it changes (the capability object it carries
  differs from the default in that member), as ``capability.member``;
* per hook, the lines of ``servo/`` outside ``servo/physics/`` that call or read it
  (``.hook`` or ``.capability.hook``; a name that is also a common word of the code,
  ``rows``, ``grid``, ``kind``, ``unit``, ``note``, ``full``, ``held``, is counted only
  on a term: after ``phys``, ``VOCABULARY[...]`` or ``MODE_TERM``);
* the lines of ``servo/diagnose/`` that name a term: a vocabulary name in quotes,
  outside the line that declares the term's own ``name`` (listed with ``--lines``);
  and apart, the lines that reach one term through a role the registry declares
  (``diagnosed_by(stage)``, ``BASELINE_TERMS``, ``MASS``, the frequency stage's
  ``MODE_TERM``): no name, but a stage that is about one term.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: hook names that are also common attribute names of the code: counted only on a term
COMMON = frozenset({"rows", "grid", "kind", "unit", "note", "full", "held", "name", "doc", "units", "state"})
TERM_RECEIVER = r"(?:phys|VOCABULARY\[[^\]]*\]|MODE_TERM|term_of\([^)]*\))"


def _public(cls) -> list[str]:
    return [n for n in vars(cls) if not n.startswith("_")]


def interface() -> dict:
    """``required`` names, ``capabilities`` name -> members, per term its ``overrides``."""
    import servo.diagnose.job  # noqa: F401  (registers the terms that live with the diagnosis)
    from servo import physics
    from servo.physics import base

    Term = base.Term
    Capability = getattr(base, "Capability", None)
    names: list[str] = []
    for c in reversed(Term.__mro__[:-1]):
        for n in _public(c):
            if n not in names:
                names.append(n)
    caps = {n: getattr(Term, n) for n in names if Capability is not None and isinstance(getattr(Term, n), Capability)}
    members = {n: [m for c in reversed(type(cap).__mro__[:-1]) for m in _public(c) if m != "term"]
               for n, cap in caps.items()}  # fmt: skip
    required = [n for n in names if n not in caps]
    over = {}
    for name, t in physics.VOCABULARY.items():
        cls, mine = type(t), []
        for n in required:
            if getattr(cls, n) is not getattr(Term, n) and n not in ("name", "doc", "units"):
                mine.append(n)
        for n, default in caps.items():
            cap = getattr(t, n)
            for m in members[n]:
                a, b = getattr(type(cap), m, None), getattr(type(default), m, None)
                if a is not b or vars(cap).get(m, b) is not vars(default).get(m, b):
                    mine.append(f"{n}.{m}")
        over[name] = mine
    return {"required": required, "capabilities": members, "overrides": over}


def _lines(paths) -> list[tuple[str, int, str]]:
    out = []
    for p in paths:
        for i, line in enumerate(p.read_text().splitlines(), 1):
            if line.lstrip().startswith("#"):
                continue
            out.append((str(p.relative_to(ROOT)), i, line))
    return out


def call_sites(hooks) -> dict[str, list[str]]:
    """Hook -> the lines of ``servo/`` outside ``servo/physics/`` that use it."""
    files = [p for p in sorted((ROOT / "servo").rglob("*.py")) if "physics" not in p.parts]
    lines = _lines(files)
    out = {}
    for h in hooks:
        cap, _, member = h.rpartition(".")
        if cap:
            pat = re.compile(r"\.%s\.%s\b" % (cap, member))
        elif h in COMMON:
            pat = re.compile(r"%s\.%s\b" % (TERM_RECEIVER, h))
        else:
            pat = re.compile(r"\.%s\b" % h)
        out[h] = [f"{f}:{i}" for f, i, line in lines if pat.search(line) and '"""' not in line
                  and not line.strip().startswith((":", "(:", "``"))]  # fmt: skip
    return out


def naming_lines() -> list[str]:
    """The lines of ``servo/diagnose/`` that name a term by its vocabulary name in quotes,
    outside the line that declares a term's ``name``."""
    from servo import physics

    pat = re.compile(r"""["'](%s)["']""" % "|".join(map(re.escape, physics.VOCABULARY)))
    out = []
    for f, i, line in _lines(sorted((ROOT / "servo" / "diagnose").rglob("*.py"))):
        code = line.split("#")[0]
        if pat.search(code) and not re.match(r"\s*name\b.*=", code):
            out.append(f"{f}:{i}: {line.strip()}")
    return out


ROLES = re.compile(r"diagnosed_by\(|BASELINE_TERMS\[|\bMASS\b|MODE_TERM\.")


def role_lines() -> list[str]:
    """The lines of ``servo/diagnose/`` that reach a term through a registry role."""
    return [f"{f}:{i}: {line.strip()}" for f, i, line in _lines(sorted((ROOT / "servo" / "diagnose").rglob("*.py")))
            if ROLES.search(line.split("#")[0]) and '"""' not in line and not line.lstrip().startswith((":", "("))]


def measure() -> dict:
    it = interface()
    hooks = it["required"] + [f"{c}.{m}" for c, ms in it["capabilities"].items() for m in ms]
    sites = call_sites(hooks)
    flat = {h: sites[h] for h in hooks}
    over = it["overrides"]
    counts = sorted(len(v) for v in over.values())
    return {"required": it["required"], "capabilities": it["capabilities"], "overrides": over,
            "median_overrides": counts[len(counts) // 2], "call_sites": flat, "naming_lines": naming_lines(),
            "role_lines": role_lines()}  # fmt: skip


def tables(m: dict, show_lines: bool = False) -> str:
    out = [f"required interface: {len(m['required'])} attributes: {', '.join(m['required'])}",
           f"capabilities: {len(m['capabilities'])}" + "".join(f"\n  {c} ({len(ms)}): {', '.join(ms)}"
                                                            for c, ms in m["capabilities"].items()),
           f"overrides per term beyond name, doc, units: median {m['median_overrides']}", "",
           "| term | overrides | which |", "|---|---:|---|"]  # fmt: skip
    for name, o in m["overrides"].items():
        out.append(f"| `{name}` | {len(o)} | {', '.join(o)} |")
    users: dict[str, list[str]] = {}
    for name, o in m["overrides"].items():
        for h in o:
            users.setdefault(h, []).append(name)
    out += ["", "| hook | terms that override it | lines that use it (servo/ outside physics/) |", "|---|---|---|"]
    for h, sites in m["call_sites"].items():
        who = users.get(h, [])
        out.append(f"| `{h}` | {len(who)}: {', '.join(who)} | {len(sites)}: {', '.join(sites)} |")
    out += ["", f"lines of servo/diagnose/ naming a term: {len(m['naming_lines'])}"]
    if show_lines:
        out += [f"  {line}" for line in m["naming_lines"]]
    out += [f"lines of servo/diagnose/ reaching a term through a registry role: {len(m['role_lines'])}"]
    if show_lines:
        out += [f"  {line}" for line in m["role_lines"]]
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m studies.term_interface", description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--lines", action="store_true", help="list the lines that name a term")
    a = ap.parse_args(argv)
    m = measure()
    print(json.dumps(m, indent=1) if a.json else tables(m, a.lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
