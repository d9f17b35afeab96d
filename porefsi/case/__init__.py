"""porefsi.case."""
