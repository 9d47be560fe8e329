"""Experiments: in-chip swept-sine tests and out-of-chip shaker runs, into HDF5 run files, safely.

config (TOML, validated) -> plans (plain steps) -> the runner (the only code that
drives outputs; safe shutdown) -> run files (appended and flushed per point).

* :mod:`labkit.experiments.config`   ``load_inchip``, ``load_shaker``
* :mod:`labkit.experiments.plans`    ``inchip_plan``, ``shaker_plan``
* :mod:`labkit.experiments.runner`   ``Runner``
* :mod:`labkit.experiments.safety`   drive guard, interlocks, signal handling
* :mod:`labkit.experiments.rig`      the open instruments, limits handed to the drivers
* :mod:`labkit.experiments.measure`  acquisition and demodulation (via :mod:`labkit.analysis.frf`)
* :mod:`labkit.experiments.runfile`  the run-file layout (documented there), writer, readers
* :mod:`labkit.experiments.session`  ``run_session``: what the CLI commands call
"""
