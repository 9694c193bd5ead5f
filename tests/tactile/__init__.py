"""Tests of the tactile application."""
