"""``servo compensate``: cancel what was found (issue 14).

:mod:`~servo.compensate.model` reads a model (a diagnosis, an identification, a drive
config) as the drive's physics, checked; :mod:`~servo.compensate.significance` leaves out
the terms not distinguishable from zero; :mod:`~servo.compensate.plausible` refuses a
model no drive of the config can have; :mod:`~servo.compensate.propose` mirrors each
cancellable term by its compensator term and bounds its authority;
:mod:`~servo.compensate.check` checks the proposal in closed loop on the model;
:mod:`~servo.compensate.job` writes the folder.  ``docs/compensate.md`` explains it.
"""

from servo._callable import make_callable  # noqa: E402

make_callable(__name__, "servo.compensate.job:compensate")  # servo.compensate(...): the notebook entry point
