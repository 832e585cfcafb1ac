"""``servo recover``: finalise the journal a killed run left into its NPZ and CSV."""
from __future__ import annotations

import argparse

from servo.errors import RecordingError


def register(sub) -> None:
    p = sub.add_parser(
        "recover",
        help="turn the journal of a killed run into its log files",
        description="A run killed hard (power, SIGKILL) leaves its log as NAME.journal in OUT.incomplete/: every "
        "row synced before the kill. This writes NAME.npz and/or NAME.csv beside it from its complete rows and "
        "removes the journal.",
    )
    p.add_argument("journals", nargs="+", metavar="JOURNAL", help="journal file(s) (*.journal)")
    p.add_argument("--log-format", choices=("npz", "csv", "both"), default="both", help="files to write (default both)")
    p.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from servo.io.runlog import finalise_journal, journal_rows

    formats = ("npz", "csv") if args.log_format == "both" else (args.log_format,)
    for path in args.journals:
        if not str(path).endswith(".journal"):  # its outputs are named after it: never an input's name
            raise RecordingError(f"{path}: a journal's name ends in .journal (the NPZ and CSV are written beside it)")
        rows = journal_rows(path)  # the header checked: one line naming what is wrong
        written = finalise_journal(path, formats)
        print(f"servo recover: {path}: {rows} rows -> " + ", ".join(str(p) for p in written))
    return 0
