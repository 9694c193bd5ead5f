"""Benchmarks of the tactile application: simulator, model, training, protocol runs."""
