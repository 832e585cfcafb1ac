"""The serial link to a DSP/VCM board: wire protocol, pyserial driver, device emulator.

* :mod:`hil.framing`: COBS + CRC-32 frames; a total decoder.
* :mod:`hil.protocol`: the messages of protocol version 1 (``docs/protocol.md``).
* :mod:`hil.serialdriver`: :class:`~hil.serialdriver.SerialDriver`, the driver interface
  over any pyserial URL (:mod:`hil.port` opens it).
* :mod:`hil.board`: the board's protocol state machine around the simulated drive.
* :mod:`hil.emulator`: the board served on a pseudo-terminal or TCP port, in lockstep or
  real time (``servo emulate``).
* :mod:`hil.faults`: the ``faulty://`` URL handler that injects link faults.

Imports ``servo`` (the driver interface) and ``kernels`` (the emulated plant); nothing
below imports ``hil``.
"""
