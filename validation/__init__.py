"""flexcal.validation."""
