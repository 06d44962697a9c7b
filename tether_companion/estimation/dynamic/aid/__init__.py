"""One module per measurement of the dynamic filter: each decides when to fuse, forms the
innovation through :func:`~tether_companion.estimation.dynamic.aiding.fuse` (gate, status)."""
