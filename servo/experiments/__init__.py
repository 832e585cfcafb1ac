"""The paper's experiments (Gong et al. 2002, section IV) on the simulated drive.

* :mod:`~servo.experiments.square_wave` -- friction identification (Fig. 5);
* :mod:`~servo.experiments.hysteresis` -- hysteresis loops and the Dahl fit (Fig. 2-4);
* :mod:`~servo.experiments.bode` -- swept-sine Bode at several levels (Fig. 7-10).

Each runs the closed loop (PI holding loop, compensator on or off) through
:func:`servo.runtime.closedloop.simulate` and returns plain arrays and dataclasses; the
commands in :mod:`servo.cli` write them to disk.
"""
