"""Model structures of the paper's section 5.3, each ``fit(experiments, context)``."""
