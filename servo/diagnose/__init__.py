"""``servo diagnose``: find the physics a model left out, model it, prove the fit improves.

Modules, bottom up: :mod:`~servo.diagnose.signals` (the inverse-dynamics path at full
rate and its rows), :mod:`~servo.diagnose.terms` (the vocabulary of physics, whose
terms live in the effect modules of :mod:`servo.physics`),
:mod:`~servo.diagnose.model` (a model's terms and its rows), :mod:`~servo.diagnose.select`
(blocked cross-validation, the tests, greedy selection), :mod:`~servo.diagnose.partial`
(terms present from some time on), :mod:`~servo.diagnose.concealed`
(recordings with a concealed effect on the simulated drive).  ``docs/diagnosis.md``
explains the method.
"""

# terms beside the diagnosis's signal path register themselves into the vocabulary of
# servo.physics on import; importing any module of the package imports them first
import servo.diagnose.sensor_lag  # noqa: E402,F401

from servo._callable import make_callable  # noqa: E402

make_callable(__name__, "servo.diagnose.job:diagnose")  # servo.diagnose(...): the notebook entry point
