"""Ray tracing: the only layer that imports ``sionna.rt``, ``mitsuba`` or ``drjit``.

:mod:`.llvm` finds a libLLVM for Dr.Jit (a leaf, no Sionna); :mod:`.settings` holds the RT settings;
:mod:`.tracer` owns the Sionna scene and its solvers; :mod:`.features` reduces paths to per-cell features.
"""
