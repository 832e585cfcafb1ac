"""Track-following controller design: continuous prototypes, discretised to two cascades of
second-order sections (:class:`Design`), and the exact multirate loop they make.

* :func:`track_following`: lead-lag (PID) with an integrator on ``J*s^2``, notches, a
  low-pass, solved for a crossover and phase margin on the discrete loop;
* :func:`nss_reference`: the NSS HDD benchmark's own PID plus notches;
* :mod:`servo.design.loop`: the open loop at the PES rate, margins.
"""
from servo.design.design import Design
from servo.design.reference import nss_reference
from servo.design.track_following import track_following

__all__ = ["Design", "nss_reference", "track_following"]
