"""Input and output: the result store, checkpoints and plots."""
