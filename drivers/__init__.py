"""Instrument drivers: function generators, oscilloscopes, vibrometer controllers,
shaker amplifier and shaker envelope, camera.

Every driver derives from :class:`labkit.drivers.base.Instrument`; open one by model
name with :func:`labkit.drivers.registry.open_instrument`. Drivers never import the
CLI, :mod:`labkit.analysis`, :mod:`labkit.sim` or :mod:`labkit.lab`.
"""
