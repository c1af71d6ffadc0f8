"""Stage 4, code generation: kernels → C source through the templates (:mod:`.emit`)."""
