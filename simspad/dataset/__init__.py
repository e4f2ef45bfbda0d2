"""Dataset generation: the spec, the plan of renders and recordings, executors, and the job that runs them."""
