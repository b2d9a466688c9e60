"""flexcal.geometry."""
