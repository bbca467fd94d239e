"""chronogym's benchmark scripts, one sub-package per subject (index: ``benchmarks/README.md``).

Not part of the installed package. Run a script from the repository root as a module, e.g.
``python -m benchmarks.vector.peers``; the scripts import what they share from
:mod:`benchmarks.common`.
"""
