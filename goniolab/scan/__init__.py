"""Measurement plans, the scan runner (a state machine) and the events it publishes."""
