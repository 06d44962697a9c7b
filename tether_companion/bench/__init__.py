"""Benchmarks of ``tether-companion bench``: one module per benchmark (HELP, add_arguments, run)."""
