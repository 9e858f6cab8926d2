"""Parameter sweeps: the paper's experiments (or any run) over plant samples drawn from
plant.yaml's ranges, run in local processes or on a Dask cluster, one tidy table.

sampling (factors, seeded design) -> engine (plan: every run's spec; run) ->
executors (serial / local processes / Dask) -> tasks (one run, the one closed-loop
call) -> table (CSV), summary (bands, ranking odds, sensitivities), figures, report.
"""
