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
        try:
            rows = journal_rows(path)
        except (ValueError, KeyError, UnicodeDecodeError) as exc:
            raise RecordingError(f"{path}: not a run-log journal ({exc})") from None
        written = finalise_journal(path, formats)
        print(f"servo recover: {path}: {rows} rows -> " + ", ".join(str(p) for p in written))
    return 0
