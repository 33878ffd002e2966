"""The ``zbuf-occlude`` command: argparse only — parse, call the library, print.

:mod:`.main` (the parser, ``generate``, ``verify``, ``validate`` ...) and one module per command
group: :mod:`.farm`, :mod:`.compare`, :mod:`.learn` (``experiment``), :mod:`.sim2real`,
:mod:`.sensors` (``scan``, ``realism``), :mod:`.protocols`.  Nothing outside this package imports it.
"""
