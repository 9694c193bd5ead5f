"""Tests of the augmentation library."""
