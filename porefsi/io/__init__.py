"""porefsi.io."""
