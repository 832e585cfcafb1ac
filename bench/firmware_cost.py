"""The firmware on a Cortex-M7: code size and instructions per tick, against the budget
of a 50 kHz loop on a 200 MHz core (4000 cycles per tick).

* Code size: each portable source of ``firmware/`` cross-compiled for the MPS2 AN500
  (Cortex-M7, FPv5-D16, ``-O2``, :data:`hil.firmware.MPS2_FLAGS`), ``.text`` + ``.data``
  bytes from ``arm-none-eabi-size``; and the linked host-in-the-loop image.
* Instructions per tick (``firmware/bench_mps2.c`` under QEMU with ``-icount shift=0``):
  each controller kind's tick on its stage (compensator on), the simulated drive's step
  and sensor read (what a real board does not run), and one tick's frames at b = 1 (a
  SAMPLES frame out, a COMMANDS frame in: CRC and COBS).  QEMU counts instructions, not
  cycles: a Cortex-M7 retires up to two simple instructions a cycle, but a
  double-precision division or square root takes 16 or more, so cycles may be above or
  below these counts; the margin to the budget is what they show.

    python -m bench.firmware_cost        # prints the table of docs/firmware.md
"""
from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

from hil.firmware import ARM_CC, CFLAGS, MPS2_FLAGS, PORTABLE, ROOT, build_mps2, comparable, instructions_per_tick
from servo.config import Config

BUDGET = 200e6 / 50e3
"""Cycles per tick of a 50 kHz loop on a 200 MHz core."""


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
    print("| source | bytes (.text + .data) |\n|---|---|")
    for src, n in sizes.items():
        print(f"| `{src}` | {n} |")
    print(f"| linked image (both modes, newlib's libm and string functions) | {image} (+ {bss} RAM) |")
    print("\n| kind | controller | frames (b = 1) | board total | simulated drive | of the budget (4000) |")
    print("|---|---|---|---|---|---|")
    for kind, r in ipt.items():
        total = r["controller"] + r["frames"]
        print(f"| `{kind}` | {r['controller']} | {r['frames']} | {total} | {r['plant']} | {total / BUDGET:.0%} |")


if __name__ == "__main__":
    main()
