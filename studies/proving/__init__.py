"""The proving ground: recordings made independently of the project's simulated drive.

A diagnosis tuned on :mod:`servo.diagnose.concealed` (the project's own drive,
``kernels/plant.py``, its own excitations) cannot show how it does on data it was not
built on.  This package makes recordings with its own integrator
(:mod:`~studies.proving.integrate`: RK4 with Karnopp sticking, hysteresis
families advanced in position), other friction and hysteresis families (LuGre,
Bouc-Wen, Maxwell-slip, Stribeck curves of other shapes, Karnopp breakaway), other
controllers (PD plus integral, lead-lag, open loop), other excitations (long seeks,
multisine, chirp, PRBS, pulse trains), rates from 500 Hz to 50 kHz, effects present in
part of a recording, modes inside and above the rows' band, a sensor low-pass and
quantisation (:mod:`~studies.proving.cases`).

It lives inside ``servo.diagnose`` so that the tests and the study
(``python -m studies.proving.study``) run from an installed wheel, beside the
concealed-effect generator; nothing the command runs imports it (a test checks that
``servo diagnose`` does not load it, and that it imports nothing of ``kernels``).
"""
