"""The ``servo`` command line: the top layer, the only one that may import everything.

Each subcommand lives in its own module here with ``register(subparsers)``; the module
names are listed in :data:`COMMANDS`.  Every user-facing failure is one line on stderr
and a non-zero exit: ``servo: error: ...`` (exit 2; 3 for drive/link failures; an
operating-system error such as an output path under a file, a read-only or full disk is
``servo: error: PATH: CAUSE``, exit 2), Ctrl-C or SIGTERM ``servo: interrupted; WHAT WAS KEPT`` (exit
130), and a bug ``servo: internal error: ...`` (exit 70; ``SERVO_DEBUG=1`` shows the
traceback).
"""
from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import tomllib

from servo.errors import ConfigError, Interrupted, ServoError

COMMANDS = ("run", "config", "identify", "hysteresis", "bode", "frf", "paper", "emulate", "diagnose", "compensate", "recover",
            "fleet", "loop", "demo", "warmup")


class UsageError(ServoError):
    """Bad command-line usage."""


class Parser(argparse.ArgumentParser):
    """argparse that raises one-line errors instead of printing usage and exiting."""

    def error(self, message: str):
        where = "" if self.prog == "servo" else f"{self.prog}: "  # the top level is already "servo: error:"
        raise UsageError(f"{where}{message} (see {self.prog} --help)")


def parse_set(items: list[str] | None) -> dict:
    """``--set section.key=value`` options (TOML values) as nested dicts; a controller
    kind's field is ``controller.<kind>.key``."""
    out: dict = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        section, dot, name = key.strip().partition(".")
        if not sep or not dot or not name:
            raise ConfigError(f"--set {item!r}: expected section.key=value")
        try:
            parsed = tomllib.loads(f"v = {value.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            parsed = value.strip()  # a bare word: a string
        except ValueError:  # an integer of more digits than Python reads
            raise ConfigError(f"--set {key.strip()}: {len(value.strip())} characters, not a value") from None
        into = out.setdefault(section, {})
        sub, dot, leaf = name.partition(".")
        if dot:
            into.setdefault(sub, {})[leaf] = parsed
        else:
            into[name] = parsed
    return out


def build_parser() -> Parser:
    parser = Parser(prog="servo", description="Servo runtime and modeling tool for voice-coil actuators.")
    parser.add_argument("--version", action="store_true", help="print the version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for name in COMMANDS:
        importlib.import_module(f"servo.cli.{name}").register(sub)
    return parser


def os_error_line(exc: OSError) -> str:
    """One line naming the path and the cause of an operating-system error."""
    cause = exc.strerror or str(exc) or type(exc).__name__
    if exc.filename is None:
        return cause
    path = f"{exc.filename} -> {exc.filename2}" if exc.filename2 else f"{exc.filename}"
    return f"{path}: {cause}"


def _sigterm(signum, frame):
    raise KeyboardInterrupt


def use_agg() -> None:
    """Select matplotlib's Agg backend (files, no display): the command line's choice,
    made here and nowhere in the library (whose figures need no backend at all).
    Without importing matplotlib when nothing has yet (``servo config`` needs none)."""
    if "matplotlib" in sys.modules:
        sys.modules["matplotlib"].use("Agg")
    else:
        os.environ["MPLBACKEND"] = "Agg"


def _interrupted(exc: BaseException) -> bool:
    """Whether ``exc`` was caused by a Ctrl-C or SIGTERM: an extension module whose
    initialisation a KeyboardInterrupt cut short raises ImportError from it (pybind11's
    "initialization failed"), which is the user's interruption, not a bug."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def main(argv: list[str] | None = None) -> int:
    # every command stops the same way on SIGTERM and SIGINT (the actuator to its safe
    # state, what it recorded kept): also when started in a script's background, whose
    # shell hands it an ignored SIGINT
    signal.signal(signal.SIGTERM, _sigterm)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    use_agg()
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        args.argv = ["servo", *(sys.argv[1:] if argv is None else argv)]  # the command line, for provenance
        if args.version:
            from servo.io.provenance import package_version

            print(f"servo {package_version()}")
            return 0
        if args.command is None:
            parser.print_help()
            return 2
        from servo.runtime.warmup import announce

        with announce(f"servo {args.command}", quiet=bool(getattr(args, "quiet", False))):  # kernels compiling
            return int(args.handler(args) or 0)
    except Interrupted as exc:  # a command that says what it kept
        print(f"servo: interrupted; {exc}", file=sys.stderr)
        return exc.exit_code
    except ServoError as exc:
        print(f"servo: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("servo: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0
    except OSError as exc:  # the user's environment (a path, a full or read-only disk), not a bug
        print(f"servo: error: {os_error_line(exc)}", file=sys.stderr)
        return 2
    except Exception as exc:  # a bug: still one line unless asked for more
        if _interrupted(exc):  # Ctrl-C while a compiled module initialised: "ImportError: initialization failed"
            print("servo: interrupted", file=sys.stderr)
            return 130
        if os.environ.get("SERVO_DEBUG"):
            raise
        print(f"servo: internal error: {type(exc).__name__}: {exc} (SERVO_DEBUG=1 shows the traceback)", file=sys.stderr)
        return 70


if __name__ == "__main__":
    sys.exit(main())
