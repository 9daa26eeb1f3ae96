"""Fluid: the moving particle semi-implicit (MPS) method of Koshizuka & Oka (1996), 2-D and 3-D."""
