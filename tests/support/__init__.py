"""Helpers the tests share: checkers, event data, rig files, slow references, op-count cases."""
