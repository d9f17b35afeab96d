"""porefsi.solid."""
