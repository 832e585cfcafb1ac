
from servo._callable import make_callable  # noqa: E402

make_callable(__name__, "servo.loop.design:loop_design")  # servo.loop(cfg, f_hz): the designed loop
