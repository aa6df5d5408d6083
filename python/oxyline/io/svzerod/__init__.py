"""svZeroDSolver files: :mod:`~oxyline.io.svzerod.reader` converts an svZeroDSolver
configuration to a native model dict (with the element translations of
:mod:`~oxyline.io.svzerod.heart`, :mod:`~oxyline.io.svzerod.closed_loop`,
:mod:`~oxyline.io.svzerod.coupling` and :mod:`~oxyline.io.svzerod.initial`, which read the
file's values with :mod:`~oxyline.io.svzerod.values`),
:mod:`~oxyline.io.svzerod.writer` exports a model, :mod:`~oxyline.io.svzerod.dropin` runs a
configuration and returns ``svzerod.simulate``'s DataFrame (the core runs its cycle-to-cycle
rule and picks its output rows), :mod:`~oxyline.io.svzerod.calibrator` is
``svzerod.calibrate``. The public drop-in is :mod:`oxyline.svzerod`.
"""
