"""Helpers every layer may use: errors, argument checks, atomic files, provenance, signals.

Nothing here knows about robots, patients or RL; it imports only the standard library and
NumPy.
"""
