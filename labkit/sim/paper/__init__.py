"""The paper (Qu, Choi, Oldham 2017) as data: its observations and its shaker.

* :mod:`~labkit.sim.paper.observations`: the bundled table ``observations.toml``
  (source, value, tolerance and regime of every behaviour the paper reports)
  and the met / not met / not applicable test of each;
* :mod:`~labkit.sim.paper.shaker`: the 4809-on-2718 amplitude law the paper
  scenarios drive the tray with;
* :mod:`~labkit.sim.paper.ensemble`: the observations scored over a Monte Carlo
  ensemble of drawn robots x seeds (:func:`~labkit.sim.paper.ensemble.score_ensemble`);
* :mod:`~labkit.sim.paper.fit`: the calibration of the unmeasured parameters to
  the observations (writes the bundled ``paper`` preset).
"""
from labkit.sim.paper.observations import Observation, ObservationCheck, check, observations
from labkit.sim.paper.shaker import PAPER_SHAKER, ShakerLaw

__all__ = ["Observation", "ObservationCheck", "check", "observations", "PAPER_SHAKER", "ShakerLaw"]
