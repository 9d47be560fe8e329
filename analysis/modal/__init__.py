"""Resonance fitting: FRFs -> modes with standard uncertainties.

:func:`fit_modes` (in :mod:`~labkit.analysis.modal.fit`) fits FRFs given as arrays;
:func:`fit_robot` (in :mod:`~labkit.analysis.modal.robot`) fits files (run files,
UFF 58, CSV, Touchstone) into robot parameters, as ``labkit fit`` does.
The sub-modules hold its parts: :mod:`~labkit.analysis.modal.lscf` (poles
and the stabilisation diagram), :mod:`~labkit.analysis.modal.refine`
(nonlinear least squares on the pole-residue model),
:mod:`~labkit.analysis.modal.sdof` (peak picking and circle fits),
:mod:`~labkit.analysis.modal.assign` (fitted modes -> simulator modes),
:mod:`~labkit.analysis.modal.io` (reading run files, writing fits),
:mod:`~labkit.analysis.modal.formats` (UFF, CSV, Touchstone in; UFF 55/58 out),
:mod:`~labkit.analysis.modal.noise` (noise level from the data, misfit against it),
:mod:`~labkit.analysis.modal.shapes` (mode shapes, MAC, which mode dominates where),
:mod:`~labkit.analysis.modal.plots` (figures) and
:mod:`~labkit.analysis.modal.synth` (synthetic FRFs with known modes).
"""
from __future__ import annotations

from labkit.analysis.modal.fit import ModalFit, Mode, fit_modes
from labkit.analysis.modal.robot import RobotFit, fit_robot

__all__ = ["Mode", "ModalFit", "fit_modes", "RobotFit", "fit_robot"]
