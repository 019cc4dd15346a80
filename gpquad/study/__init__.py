"""Studies: configs, the run loop, run folders and checkpoints, sweeps, full models."""
