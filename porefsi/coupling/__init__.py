"""porefsi.coupling."""
