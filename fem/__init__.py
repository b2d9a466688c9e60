"""flexcal.fem."""
