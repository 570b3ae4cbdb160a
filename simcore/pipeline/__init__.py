"""The main job: a run (render, check, store) with its crash-safe chunk store, the analytic check's
verdict, the run-file -> estimator-error evaluation and parameter sweeps on Dask."""
