
from servo._callable import make_callable  # noqa: E402

make_callable(__name__, "servo.lti:loop")  # servo.loop(...): the notebook entry point
