"""Instrument drivers: function generators, oscilloscopes, vibrometer controllers,
shaker amplifier and shaker envelope, camera.

Every driver derives from :class:`drivers.base.Instrument`; open one by model
name with :func:`drivers.registry.open_instrument`. Drivers never import the
CLI, :mod:`analysis`, :mod:`labkit.sim` or :mod:`labkit.lab`.
"""
