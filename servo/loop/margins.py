"""The margins of a loop: :func:`servo.design.margins.margins` (one rule for designs,
measurements and the HDD evaluation), here under its former name for existing callers."""
from servo.design.margins import margins, resample

__all__ = ["margins", "resample"]
