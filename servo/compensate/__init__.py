"""``servo compensate``: cancel what was found (issue 14).

:mod:`~servo.compensate.model` reads a model (a diagnosis, an identification, a drive
config) as the drive's physics; :mod:`~servo.compensate.propose` mirrors each
cancellable term by its compensator term and bounds its authority;
:mod:`~servo.compensate.job` writes the section.  ``docs/compensate.md`` explains it.
"""

from servo._callable import make_callable  # noqa: E402

make_callable(__name__, "servo.compensate.job:compensate")  # servo.compensate(...): the notebook entry point
