"""The runtime: the driver lifecycle (:mod:`~servo.runtime.driver`), the simulated drive
(:mod:`~servo.runtime.simdriver`, its plant arrays in :mod:`~servo.runtime.simplant`), the
tick scheduler, the controller, the scenario inputs, wall-clock pacing, and the closed
loop that ties them together (:mod:`~servo.runtime.loop`, both paths)."""
