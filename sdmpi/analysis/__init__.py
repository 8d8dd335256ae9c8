"""Reduction of run files to moduli and viscosities, and the analytic models."""
