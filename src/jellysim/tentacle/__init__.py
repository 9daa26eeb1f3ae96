"""Tentacles: particle chains with bending after Young's modulus and sphere drag (paper §4.1)."""
