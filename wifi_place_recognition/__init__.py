"""Building and floor recognition from one WiFi scan (SAE + classifier)."""
