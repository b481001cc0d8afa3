"""Verification on an independent multibody car (MuJoCo)."""
