"""The firmware on a Cortex-M7: code size and instructions per tick, against the budget
of a 50 kHz loop on a 200 MHz core (4000 cycles per tick).

* Code size: each portable source of ``firmware/`` cross-compiled for the MPS2 AN500
  (Cortex-M7, FPv5-D16, ``-O2``, :data:`hil.firmware.MPS2_FLAGS`), ``.text`` + ``.data``
  bytes from ``arm-none-eabi-size``; and the linked host-in-the-loop image.
* Instructions per tick (``firmware/bench_mps2.c`` under QEMU with ``-icount shift=0``):
  each controller kind's tick on its stage (compensator on), the simulated drive's step
  and sensor read (what a real board does not run), and the frames: with the host in the
  loop a SAMPLES frame out and a COMMANDS frame in per tick (b = 1); with the loop on the
  board the REFS frames in (32 ticks a frame, per tick) and a LOG frame of one 13-column
  row out (CRC and COBS each way), sent every ``n``-th tick (``run.log_every``;
  :func:`hil.onboard.link_log_every`): the parts of a tick, ``controller + refs + log / n``.
* The whole board with the loop on it (``firmware/bench_board_mps2.c``,
  :func:`hil.firmware.board_instructions_per_tick`): ``board.c`` fed a recorded host
  session from memory (REFS frames of 32 ticks, LOG rows every ``n``-th tick, b = 1),
  behind a drive stand-in that costs next to nothing; instructions per tick from START to
  the last tick.  It is the parts above plus the session's own bookkeeping (the frame
  decoder, the reference ring, the row's assembly), so the budget is checked on it.
* Cycles: QEMU counts instructions, not cycles (it does not model the pipeline).  The
  cycles are bounded with a stated cycles-per-instruction range (:data:`CPI_TYPICAL`,
  :data:`CPI_BOUND`): a Cortex-M7 issues up to two instructions a cycle (CPI 0.5 at
  best); with code and data in its tightly coupled memories (no wait states, no cache
  misses) the integer code of the frames runs near 1 cycle an instruction, and the
  double-precision code of the kernels stalls on its results and on VDIV.F64 and
  VSQRT.F64 (about 30 cycles each, a few per tick), which the bound of 2 covers.  Code in
  flash behind wait states, or a cache miss per tick, is not covered: measure on the
  board (the DWT cycle counter, docs/firmware.md).

    python -m bench.firmware_cost        # prints the table of docs/firmware.md"""
from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

from hil.firmware import (ARM_CC, CFLAGS, MPS2_FLAGS, PORTABLE, ROOT, board_instructions_per_tick, build_mps2, comparable,
                          instructions_per_tick)
from servo.config import Config

BUDGET = 200e6 / 50e3
"""Cycles per tick of a 50 kHz loop on a 200 MHz core."""
CPI_TYPICAL = 1.0
"""Cycles per instruction expected of this code on a Cortex-M7 running from its TCM."""
CPI_BOUND = 2.0
"""Cycles per instruction this code stays under on a Cortex-M7 running from its TCM (the
module doc says why); the budget is checked at this bound."""


ONBOARD_LOG_EVERY = 10
"""The logging period the docs recommend with the loop on the board at 50 kHz
(``run.log_every = 10`` with the default ``run.estimator_every = 10``: the board sends
every 10th row); every kind fits the budget at :data:`CPI_BOUND` with it, with a margin,
and with any period from :data:`ONBOARD_FITS_FROM` on."""
ONBOARD_FITS_FROM = 5
"""The smallest logging period with which the whole board, every kind, the loop on it,
fits the budget at :data:`CPI_BOUND` (docs/firmware.md); at full rate (1) none does."""
PERIODS = (1, 2, 3, 4, 5, 10)
"""The logging periods of the printed table."""


def onboard_tick(r: dict[str, int], every: int) -> float:
    """Instructions per tick with the loop on the board, a log row every ``every`` ticks:
    the kind, its share of a 32-tick REFS frame, its share of a one-row LOG frame (``r``:
    one kind's :func:`hil.firmware.instructions_per_tick`)."""
    return r["controller"] + r["refs"] + r["log"] / every


def cycles(instructions: float) -> tuple[float, float]:
    """``(typical, bound)`` cycles of ``instructions`` on a Cortex-M7 from its TCM."""
    return instructions * CPI_TYPICAL, instructions * CPI_BOUND


def code_size(workdir: Path) -> dict[str, int]:
    """``.text + .data`` bytes of each portable source, compiled for the Cortex-M7."""
    flags = [f for f in MPS2_FLAGS if f.startswith(("-mcpu", "-mfpu", "-mfloat", "-mthumb"))]
    out = {}
    for src in PORTABLE:
        obj = Path(workdir) / (src + ".o")
        subprocess.run([ARM_CC, *CFLAGS, *flags, "-I", str(ROOT), "-c", str(ROOT / src), "-o", str(obj)], check=True)
        text, data = subprocess.run([f"{ARM_CC[:-3]}size", str(obj)], capture_output=True, text=True,
                                    check=True).stdout.splitlines()[1].split()[:2]  # fmt: skip
        out[src] = int(text) + int(data)
    return out


def image_size(workdir: Path) -> tuple[int, int]:
    """``(text + data, bss)`` bytes of the linked board image, both modes (newlib included)."""
    elf = build_mps2(comparable(Config()), workdir)
    f = subprocess.run([f"{ARM_CC[:-3]}size", str(elf)], capture_output=True, text=True, check=True).stdout
    text, data, bss = map(int, f.splitlines()[1].split()[:3])
    return text + data, bss


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        sizes = code_size(Path(tmp))
        image, bss = image_size(Path(tmp))
        ipt = instructions_per_tick(comparable(Config()), Path(tmp))
        whole = board_instructions_per_tick(comparable(Config()), Path(tmp), PERIODS)
    print("| source | bytes (.text + .data) |\n|---|---|")
    for src, n in sizes.items():
        print(f"| `{src}` | {n} |")
    print(f"| linked image (both modes, newlib's libm and string functions) | {image} (+ {bss} RAM) |")
    print("\nInstructions per tick (QEMU), and cycles at 1 and 2 cycles per instruction, of the 4000 of a "
          "50 kHz tick on a 200 MHz core:\n")
    print("| kind | controller | host in the loop: + frames = total | cycles (% of 4000) | simulated drive |")
    print("|---|---|---|---|---|")
    for kind, r in ipt.items():
        total = r["controller"] + r["frames"]
        lo, hi = cycles(total)
        print(f"| `{kind}` | {r['controller']} | {r['frames']} = {total} | {lo:.0f}-{hi:.0f} "
              f"({lo / BUDGET:.0%}-{hi / BUDGET:.0%}) | {r['plant']} |")
    print("\nThe loop on the board: + REFS per tick (32 ticks a frame), + a one-row LOG frame; per tick with a "
          "row every n ticks, cycles at 1-2 per instruction (% of 4000):\n")
    print("| kind | controller + refs | LOG row | " + " | ".join(f"n = {n}" for n in PERIODS) + " |")
    print("|---|---|---|" + "---|" * len(PERIODS))
    for kind, r in ipt.items():
        cells = []
        for n in PERIODS:
            lo, hi = cycles(onboard_tick(r, n))
            cells.append(f"{lo:.0f}-{hi:.0f} ({lo / BUDGET:.0%}-{hi / BUDGET:.0%})")
        print(f"| `{kind}` | {r['controller']} + {r['refs']} | {r['log']} | " + " | ".join(cells) + " |")
    print("\nThe whole board with the loop on it (board.c, a recorded session): instructions per tick with a row "
          "every n ticks, cycles at 1-2 per instruction (% of 4000):\n")
    print("| kind | " + " | ".join(f"n = {n}" for n in PERIODS) + " |")
    print("|---|" + "---|" * len(PERIODS))
    for kind, r in whole.items():
        cells = []
        for n in PERIODS:
            lo, hi = cycles(r[n])
            cells.append(f"{r[n]}: {lo / BUDGET:.0%}-{hi / BUDGET:.0%}")
        print(f"| `{kind}` | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
