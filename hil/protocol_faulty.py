"""pyserial URL handler module for ``faulty://`` (pyserial looks for ``<package>.protocol_<scheme>``
with a ``Serial`` class); the implementation is :mod:`hil.faults`."""
from hil.faults import FaultySerial as Serial

__all__ = ["Serial"]
