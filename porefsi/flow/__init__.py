"""porefsi.flow."""
