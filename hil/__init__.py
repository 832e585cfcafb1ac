"""The serial link to a DSP/VCM board: wire protocol, pyserial driver, device emulator.

Imports ``servo`` (the driver interface) and ``kernels`` (the emulated plant); nothing
below imports ``hil``.
"""
