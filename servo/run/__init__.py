"""The ``servo run`` job (:mod:`~servo.run.job`): its plots, figures of merit, real-time
options and report, and the process's startup time."""
