"""``servo frf``: a frequency response from a recording (H1 over Welch segments, or the
reference as instrument in closed loop), with coherence and random-error bounds."""

from servo._callable import make_callable  # noqa: E402

make_callable(__name__, "servo.frf.job:estimate_frf")  # servo.frf(...): the notebook entry point
