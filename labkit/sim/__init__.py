"""labkit.sim — the bundled hybrid simulator of the Qu-Choi-Oldham 2017 hexapod model.

Public API (``docs/model.md`` is the specification; every "choice" there is a
:class:`RobotParams` field, see :data:`labkit.sim.params.FIELD_DOCS`)::

    from labkit.sim import RobotParams, Shaker, PZT, simulate, SimResult, sweep, SweepResult
    r = simulate(RobotParams(), Shaker(freq_hz=240, amp_um=25), duration_s=2.0)
    r.mean_speed_mm_s, r.contact_fraction, r.patterns, r.summary(), r.to_h5("run.h5")

Modules: :mod:`~labkit.sim.params` (RobotParams, TOML files, validation),
:mod:`~labkit.sim.excitation` (Shaker, PZT), :mod:`~labkit.sim.model` (mass
matrix, static equilibrium, array layouts), :mod:`~labkit.sim.scheme` (the
implicit-midpoint scheme with impacts and releases), :mod:`~labkit.sim.kernel`
(it compiled by numba), :mod:`~labkit.sim.reference` (it as plain Python), :mod:`~labkit.sim.core` (``simulate``),
:mod:`~labkit.sim.result` (SimResult); sweeps, Monte Carlo and named
scenarios are in :mod:`~labkit.sim.sweep`, :mod:`~labkit.sim.uncertainty`,
:mod:`~labkit.sim.scenarios`.

Switches for ablations and checks (all plain RobotParams fields or
``simulate`` options, so they pickle and sweep):

* ``simulate(..., ablation="no_adhesion")`` zeroes ``c_ad_n`` and ``c_ad_t_n_s``;
  ``ablation="no_squeeze_film"`` zeroes ``b_g_body_n_m2_s``,
  ``b_g_foot_n_m2_s`` and ``foot_pad_um`` (:data:`labkit.sim.core.ABLATIONS`; the same as
  ``params.replace(...)`` with those fields at 0);
* ``cy_sign=(s1, s2, s3)``: the sign of each mode's lateral coupling (flip
  to reverse the walk; 0 removes lateral coupling);
* ``mu``: Coulomb friction of a pinned foot (``inf``, the default, = no slip as in
  the paper; the normal load is the compression plus the adhesion force);
* ``body_no_slip`` (default true): a body-ground impact also stops the body's
  lateral velocity, as a foot impact does;
* ``impact_modes=(1, 1, 1)``: which leg modes take part in an impact (0 holds a
  mode rigid during it: the stiff-leg limit, the robot rebounds as a whole);
  ``v_stick_mm_s``: rebounds slower than this stick (ends chattering);
* ``simulate(..., engine="numba" | "reference")``, ``dt_s``, ``record_dt_s``,
  ``seed`` (small random start of the free modes), ``transient_s``,
  ``start_height_um`` (start in the air); :func:`labkit.sim.core.dt_check`
  (default step against a quarter step, with a chaos probe over seeds).
"""
from labkit.sim.core import ABLATIONS, simulate
from labkit.sim.excitation import PZT, Shaker
from labkit.sim.params import RobotParams
from labkit.sim.result import SimResult

__all__ = ["RobotParams", "Shaker", "PZT", "simulate", "SimResult", "ABLATIONS", "sweep", "SweepResult"]

# Last, to avoid an import cycle (sweep imports from this package).
from labkit.sim.sweep import SweepResult, sweep  # noqa: E402
