"""flexcal.model."""
