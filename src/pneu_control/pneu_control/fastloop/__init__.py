"""The closed loop compiled: plant, controllers and supervisor in one numba function.

Why: a parameter sweep needs thousands of 20 s runs; the in-process runner
(:mod:`pneu_control.experiment.runner`) spends its time in Python around a
compiled plant. Here one ``@njit(cache=True)`` call (:func:`.loop.closed_loop`)
runs all n cycles; :func:`pneu_control.experiment.compiled.run_compiled` turns
its records into the runner's :class:`~pneu_control.experiment.runner.RunResult`.

Design (bit-for-bit equal to the runner, tested there against it):

- **The plant is not mirrored**: the loop calls
  :func:`pneu_sim.physics.kernel.step_period` itself, with the noise rows the
  :class:`~pneu_sim.physics.plant.Plant` would draw (:meth:`Plant.noise_rows`).
- **Controllers and supervisor are not mirrored either**: every algorithm's, reference's
  and axis's step is a kernel on named-field records (DESIGN §12), written once beside
  its Python class and called here as it is there (:mod:`.axis` only dispatches by
  algorithm code); the supervisor's decisions are :mod:`pneu_driver.safety.rules`, which
  :mod:`.supervisor` calls with its thresholds and state as records. Bit-for-bit
  equality then rests on compiling the same expressions the same way: the same libm
  calls (numba calls glibc's sin, cos, exp, tanh, cosh, sqrt, pow as CPython's
  ``math`` does), no fastmath (no FMA contraction, no reassociation). Python's
  ``x ** 2`` is ``pow(x, 2.0)``; LLVM folds a constant ``pow(x, 2.0)`` into ``x * x``,
  which differs in the last bit, so the exponent is read from the parameter array.
- **Constants are not derived twice**: :mod:`.pack` copies the records of the objects
  the runner builds (axis, algorithm, reference, TD) field by field, by name, and the
  supervisor's thresholds and sensor scaling into two flat arrays (:mod:`.layout`). One compiled signature serves every spec.
- **Events are not re-implemented**: the loop reports the last cycle where the
  Python supervisor emits an event or counts; ``run_compiled`` replays the Python
  supervisor up to there (messages, order, counters exact by construction) and
  checks the compiled outputs against it.
- **What is not compiled falls back** to the Python runner, with one line saying why
  (injected faults; an algorithm that is not a ``KernelAlgorithm`` or not in
  :data:`.layout.COMPILED`; a non-finite sample or NaN command met while running): see
  :func:`pneu_control.experiment.compiled.compiled_support`.
- Runs are cold starts: no parameter change or algorithm switch during a run
  (the runner makes none), so no bumpless blending is mirrored.
- Speed: the kernels are compiled without numba's reference counting (``_nrt=False``:
  an atomic incref/decref per array argument was ~17 % of the loop) and the loop
  releases the GIL; what is left is the plant kernel (≈ 85 % of a run: libm's pow,
  cos, exp ≈ a quarter of it) and ≈ 6 ms of Python per run (plant set-up, noise
  draws, metrics).
"""
