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
quantisation (:mod:`~studies.proving.cases`).  A second set (issue 24): an open-loop
force drive with no controller, step excitations, pink and low-pass sensor noise,
four modes up to the Nyquist frequency, a wandering force offset, an input dead zone,
backlash, cubic springs, a Gaussian Stribeck shape and LuGre with a Stribeck level,
scored on a loop x excitation x noise grid (``python -m studies.proving.study --grid
kinds``); an outside generator's recordings go through the same tables
(:mod:`~studies.proving.independent`).

It lives in ``studies`` (it imports the package, never the reverse); nothing the
command runs imports it (a test checks that ``servo diagnose`` does not load it, and
that it imports nothing of ``kernels``).
"""
