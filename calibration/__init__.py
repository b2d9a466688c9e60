"""flexcal.calibration."""
