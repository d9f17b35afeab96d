"""porefsi.integrators."""
