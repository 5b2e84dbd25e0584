"""Training a pose network: the run (`train`), its losses, mixed precision, the optimizer and the
wall-time budget."""
