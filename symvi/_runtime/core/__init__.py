"""The run time's infrastructure: arguments, options, results, memory, paths — no solver."""
