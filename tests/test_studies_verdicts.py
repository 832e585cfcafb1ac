"""``python -m studies.verdicts``: the before/after table of two sets of diagnoses, and
the changes it calls worse (a finding on a null, a lost right name, a wrong name, a
verdict that leaves the family's right ones)."""
import json

from studies.verdicts import main, tabulate


def _report(path, verdict, names):
    path.write_text(json.dumps({"verdict": verdict, "findings": [{"physics": n} for n in names],
                                "settings": {"decimate": 10}}))  # fmt: skip


def test_the_table_counts_moves_and_flags_worse_changes(tmp_path, capsys):
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    cases = {  # name: (before, after)
        "null-0-1": (("consistent", []), ("consistent", [])),
        "null-0-2": (("consistent", []), ("explained", ["time_delay"])),  # a finding on a null
        "lugre-0.2-1": (("explained", ["hysteresis"]), ("unexplained", [])),  # lost the right name
        "delay-0.5-1": (("unexplained", []), ("explained", ["time_delay"])),  # better
        "bouc_wen-0.1-1": (("explained", ["hysteresis"]), ("explained", ["hysteresis", "resonance"])),  # wrong name
    }
    for name, (before, after) in cases.items():
        _report(a / f"{name}.json", *before)
        _report(b / f"{name}.json", *after)
    text, bad = tabulate(a, b)
    assert bad == 3
    assert "null-0-2: consistent [-] -> explained [time_delay]  WORSE: a finding on a null" in text
    assert "lost the right name hysteresis" in text and "a wrong name appears: resonance" in text
    assert "delay-0.5-1: unexplained [-] -> explained [time_delay]\n" in text + "\n"  # moved, not worse
    assert "null-0-1" not in text.split("changes:")[1]
    assert main([str(a), str(b), "--changed"]) == 1
    assert main([str(a), str(a)]) == 0
    assert "worse: 0" in capsys.readouterr().out
