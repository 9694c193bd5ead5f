"""Benchmarks of the augmentation library: transforms, events, binning, peers, readers."""
