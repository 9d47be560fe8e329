"""Subcommands of the ``labkit`` CLI.

Every module here is discovered by :mod:`labkit.cli`. A command module defines

* ``NAME``: the subcommand's name (``"simulate"``),
* ``HELP``: one line of help,
* ``add_arguments(parser, common)``: fill the subparser; ``common`` is a parent
  parser holding ``--json`` and ``--quiet``, to be passed as ``parents=[common]``
  to any nested subparser,
* ``run(args) -> dict``: do the work and return the JSON summary.

Heavy imports (numba, h5py, cv2) belong inside ``run`` so ``labkit --help``
stays fast.
"""
