"""Ray tracing: the only layer that imports ``sionna.rt``, ``mitsuba`` or ``drjit``.

:mod:`.llvm` finds a libLLVM for Dr.Jit (a leaf, no Sionna); :mod:`.settings` holds the RT settings;
:mod:`.tracer` owns the Sionna scene and its solvers; :mod:`.batch_independent_solver` is the patched PathSolver it
traces with by default, for the sionna-rt releases :mod:`.sionna_version` checks; :mod:`.features` reduces paths to
per-cell features.
"""
