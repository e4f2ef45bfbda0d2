"""Dataset generation: a spec (TOML) in, a folder of renders, recordings and a manifest out.

``spec`` (the model) · ``spec_validation`` (loading and checking a spec file) · ``spec_hashing`` (what decides
whether work must be redone) · ``plan`` (every render and recording, with seeds and hashes) · ``directory`` (the
folder's layout, lock and clean-up) · ``manifest_state`` (the manifest of a run in progress) · ``jobs`` (typed
jobs and results) · ``render_job`` (one render's phases) · ``executors`` (local processes or Dask, one
``submit(job)``) · ``task_queue`` · ``generate`` (the driver).
"""
