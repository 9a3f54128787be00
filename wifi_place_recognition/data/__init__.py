"""Fingerprint data in and out: CSV files, the recorder's log, WiFi tool output."""
